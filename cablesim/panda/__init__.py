"""The Panda's description in one place (kinematic model, limits, TCP and hand dimensions,
named joint configurations), read by the simulated and the real arm.

- :mod:`cablesim.panda.description`: the numbers (pure NumPy; re-exported here);
- :mod:`cablesim.panda.model`: the MJCF builder (``panda_spec``, ``attach_panda``);
- :mod:`cablesim.panda.ik`: the arm-only IK and collision model (mink on MuJoCo kinematics)
  that both arms use to judge reachability.

MuJoCo is used here as a kinematics and geometry library, not as the simulator: nothing in
this package steps physics.  Importing the package imports neither MuJoCo nor mink.
"""

from cablesim.panda.description import (
    ARM_JOINTS,
    DEFAULT_GRASP_FORCE,
    FINGER_JOINTS,
    FINGER_RANGE,
    FLANGE_T_TCP,
    FORWARD_QPOS,
    HAND_OFFSET,
    HOME_QPOS,
    JOINT_LIMITS,
    JOINT_VELOCITY_LIMITS,
    MAX_OPENING,
    NAMED_QPOS,
    PARK_QPOS,
    RETRACT_QPOS,
    TCP_OFFSET,
)

__all__ = [
    "ARM_JOINTS",
    "DEFAULT_GRASP_FORCE",
    "FINGER_JOINTS",
    "FINGER_RANGE",
    "FLANGE_T_TCP",
    "FORWARD_QPOS",
    "HAND_OFFSET",
    "HOME_QPOS",
    "JOINT_LIMITS",
    "JOINT_VELOCITY_LIMITS",
    "MAX_OPENING",
    "NAMED_QPOS",
    "PARK_QPOS",
    "RETRACT_QPOS",
    "TCP_OFFSET",
]
