"""One interaction of a robot with a hose (SPEC section 3), for the simulated and the real robot.

    from cablesim.episode import InteractionConfig, run_interaction
    result = run_interaction(robot, camera, clock, segment, InteractionConfig(), truth=None)

Modules: ``config`` (InteractionConfig), ``primitives`` (grasp/actions/push/release/retreat on
the Robot interface), ``clock`` (the Clock protocol, ticks, the real-device StreamClock and
stillness from images), ``truth`` (the optional ground-truth provider protocol), ``capture``
(ticks -> kept frames), ``runner`` (run_interaction).  Nothing here imports the simulator: the
simulated clock, truth and session live in :mod:`cablesim.sim`
(``cablesim.sim.session.simulate_episode`` runs all of it from a seed).
"""

from cablesim.episode.config import (
    ActionConfig,
    CaptureConfig,
    GraspConfig,
    InteractionConfig,
    RetreatConfig,
)
from cablesim.episode.runner import run_interaction

__all__ = [
    "ActionConfig",
    "CaptureConfig",
    "GraspConfig",
    "InteractionConfig",
    "RetreatConfig",
    "run_interaction",
]
