"""The Franka Emika Panda's description, read by the simulated and the real arm alike.

Pure NumPy: kinematic constants, joint limits, the hand's TCP and dimensions, and the named
joint configurations.  The MJCF builder (:mod:`cablesim.panda.model`) and the arm-only IK and
collision model (:mod:`cablesim.panda.ik`) are built from these numbers; ``SimPanda`` and
``FrankyPanda`` both use them, so the two arms agree on every pose.

Named configurations (radians, joints 1..7):

- ``HOME_QPOS``: franka's ready pose (hand down in front of the base);
- ``RETRACT_QPOS``: the hand down and pulled back (TCP about (0.37, 0, 0.46) from the base),
  the collision-free way point between home and poses that face the board;
- ``FORWARD_QPOS``: the hand pointing along +x (towards the board), elbow up; an IK seed;
- ``PARK_QPOS``: where the arm waits, turned away about joint 1 out of the default camera's
  view (a scene or a real set-up may choose its own).
"""

from __future__ import annotations

import math

import numpy as np

from cablesim.errors import ConfigError

ARM_JOINTS: tuple[str, ...] = tuple(f"joint{i}" for i in range(1, 8))
FINGER_JOINTS: tuple[str, str] = ("finger_joint1", "finger_joint2")

JOINT_LIMITS: np.ndarray = np.array(
    [
        [-2.8973, 2.8973],
        [-1.7628, 1.7628],
        [-2.8973, 2.8973],
        [-3.0718, -0.0698],
        [-2.8973, 2.8973],
        [-0.0175, 3.7525],
        [-2.8973, 2.8973],
    ]
)
#: Franka's nominal joint velocity limits (rad/s).
JOINT_VELOCITY_LIMITS: np.ndarray = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])

FINGER_RANGE = (0.0, 0.04)  # per finger, metres
MAX_OPENING = 2 * FINGER_RANGE[1]
#: MuJoCo's ``solimp`` dmax of the finger pads' and finger bodies' contacts (they have priority
#: over the cables' own contact parameters): a contact gives way under force in proportion to
#: 1 - dmax over the mass it presses, so a light cable vertex sinks deep into a pad at 0.99
#: (docs/cables.md, "Table, rope").  A cable kind asks for its own (``CableKind.grip_dmax``, the
#: rope 0.999; ``hoses.grip_dmax`` overrides it), which the scene's build sets
#: (:func:`cablesim.panda.model.set_finger_contact_dmax`).
FINGER_CONTACT_DMAX = 0.99
TCP_OFFSET = 0.1034  # the TCP (between the finger pads) below the hand flange along hand z
HAND_OFFSET = 0.107  # hand flange below link7 along z
DEFAULT_GRASP_FORCE = 70.0  # N per finger

HOME_QPOS: np.ndarray = np.array([0.0, 0.0, 0.0, -1.5708, 0.0, 1.5708, 0.7854])
RETRACT_QPOS: np.ndarray = np.array([0.0, -0.6, 0.0, -2.3, 0.0, 1.7, np.pi / 4])
#: Planar, so joint6 = pi/2 + joint2 - joint4; TCP at about (0.49, 0, 0.76) from the base.
FORWARD_QPOS: np.ndarray = np.array([0.0, -0.6, 0.0, -2.3, 0.0, np.pi / 2 + 1.7, np.pi / 4])
PARK_QPOS: tuple[float, ...] = (-2.0, -0.5, 0.0, -2.8, 0.0, 2.3, 0.78)

NAMED_QPOS: dict[str, np.ndarray] = {
    "home": HOME_QPOS,
    "retract": RETRACT_QPOS,
    "forward": FORWARD_QPOS,
    "park": np.asarray(PARK_QPOS),
}


def _flange_t_tcp() -> np.ndarray:
    c, s = math.cos(-math.pi / 4), math.sin(-math.pi / 4)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[2, 3] = TCP_OFFSET
    return T


#: The Franka Hand's TCP (between the finger pads) in the flange frame: what Desk sets as
#: ``F_T_NE`` when the hand is configured, and the simulated model's ``grasp_site``.
FLANGE_T_TCP: np.ndarray = _flange_t_tcp()


# the arm's looks: the vendored meshes or MuJoCo primitives (cablesim.panda.visuals adds them)
VISUALS = ("mesh", "primitive")


def check_visual(visual: str, field: str = "robot.visual") -> str:
    """``visual`` if it names one of :data:`VISUALS`, else ``ConfigError``."""
    if visual not in VISUALS:
        raise ConfigError(field, f"unknown visual {visual!r}; choose one of {VISUALS}")
    return visual
