"""cablesim: simulation-first interactive perception of cables.

Data flows one way: scene config -> simulated world -> robot and camera -> frame stream ->
perception -> votes and next grasp -> evaluation.  ``cablesim.perception`` never imports
MuJoCo; everything under ``cablesim.sim`` does.
"""

from cablesim import gl
from cablesim.errors import (
    CablesimError,
    ConfigError,
    InputError,
    NoGraspableSegmentError,
    PhysicsDivergedError,
    RecordingError,
    SceneError,
    SceneUnsettledError,
    UnreachableError,
)

__version__ = "0.1.0"

gl.configure()

__all__ = [
    "CablesimError",
    "ConfigError",
    "InputError",
    "NoGraspableSegmentError",
    "PhysicsDivergedError",
    "RecordingError",
    "SceneError",
    "SceneUnsettledError",
    "UnreachableError",
    "__version__",
]
