"""A primitive-geometry model of the Franka Emika Panda, built with ``mujoco.MjSpec``.

The kinematics, joint limits, masses and inertias are those of MuJoCo Menagerie's
``franka_emika_panda/panda.xml``; the robot collides through capsules, cylinders and boxes that
follow each link's outline, and is drawn either with those or with franka_ros's visual meshes
(``visual="mesh"``, :mod:`cablesim.panda.visuals`).  The hand has two real slide
joints coupled by a tendon and an equality, driven by one force-limited position actuator whose
control is the opening width in metres (0 = closed, 0.08 = open) and whose force range is the
grasp force per finger (70 N by default, like the real hand; change it at run time with
:func:`set_grasp_force`).  Finger pads are high-friction boxes (mu 1.5, condim 4).

Every robot body is a descendant of ``{prefix}link0``; every robot geom name starts with the
prefix.  Robot geoms have ``contype=2, conaffinity=1``: they touch everything in the scene that
has the default ``contype=conaffinity=1`` (table, board, hoses) but not each other.

Public API: :func:`panda_spec`, :func:`attach_panda`, :class:`PandaNames`,
:func:`robot_body_ids`, :func:`set_home`, :func:`set_grasp_force`, :func:`reach_pads`; the
numbers come from :mod:`cablesim.panda.description`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from cablesim.panda.description import (
    ARM_JOINTS,
    DEFAULT_GRASP_FORCE,
    FINGER_CONTACT_DMAX,
    FINGER_JOINTS,
    FINGER_RANGE,
    HAND_OFFSET,
    HOME_QPOS,
    JOINT_LIMITS,
    MAX_OPENING,
    TCP_OFFSET,
)
from cablesim.panda.visuals import HIDDEN_COLLISION_GROUP, add_mesh_visuals, check_visual

_KP = (4500.0, 4500.0, 3500.0, 3500.0, 2000.0, 2000.0, 2000.0)
_TORQUE = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
_GRIPPER_KP = 5000.0
_GRIPPER_KV = 100.0
#: the fingers' hard contacts (their pads and bodies, and the pads against each other)
_FINGER_SOLREF = (0.004, 1.0)
_FINGER_SOLIMP = (0.95, FINGER_CONTACT_DMAX, 0.001, 0.5, 2.0)

WHITE = (0.95, 0.95, 0.95, 1.0)
OFF_WHITE = (0.90, 0.92, 0.93, 1.0)
DARK = (0.25, 0.25, 0.25, 1.0)
PAD = (0.12, 0.12, 0.12, 1.0)

ROBOT_CONTYPE = 2
ROBOT_CONAFFINITY = 1
#: ``contype`` of the finger pads.  A geom meets a pad where its ``contype`` has bit 1 (the
#: pads' ``conaffinity``) or its ``conaffinity`` bit 8, and meets the other robot geoms where
#: its ``contype`` has bit 1 or its ``conaffinity`` bit 2.  Cables, the board and the sockets
#: (1, 1) meet both; the table scene's mat and table top (16, 3:
#: ``cablesim.sim.world.YIELDING_BITS``) meet the arm and the finger bodies but let the pads in.
PAD_CONTYPE = 8
ROBOT_GEOM_GROUP = 1

# Body kinematics (pos, quat wxyz) from menagerie, and inertials (mass, com, fullinertia).
_LINKS: tuple[tuple[str, tuple, tuple], ...] = (
    ("link1", (0, 0, 0.333), (1, 0, 0, 0)),
    ("link2", (0, 0, 0), (1, -1, 0, 0)),
    ("link3", (0, -0.316, 0), (1, 1, 0, 0)),
    ("link4", (0.0825, 0, 0), (1, 1, 0, 0)),
    ("link5", (-0.0825, 0.384, 0), (1, -1, 0, 0)),
    ("link6", (0, 0, 0), (1, 1, 0, 0)),
    ("link7", (0.088, 0, 0), (1, 1, 0, 0)),
)
_INERTIALS: dict[str, tuple[float, tuple, tuple]] = {
    "link0": (
        0.629769,
        (-0.041018, -0.00014, 0.049974),
        (0.00315, 0.00388, 0.004285, 8.2904e-7, 0.00015, 8.2299e-6),
    ),
    "link1": (
        4.970684,
        (0.003875, 0.002081, -0.04762),
        (0.70337, 0.70661, 0.009117, -0.000139, 0.006772, 0.019169),
    ),
    "link2": (
        0.646926,
        (-0.003141, -0.02872, 0.003495),
        (0.007962, 2.811e-2, 2.5995e-2, -3.925e-3, 1.0254e-2, 7.04e-4),
    ),
    "link3": (
        3.228604,
        (2.7518e-2, 3.9252e-2, -6.6502e-2),
        (3.7242e-2, 3.6155e-2, 1.083e-2, -4.761e-3, -1.1396e-2, -1.2805e-2),
    ),
    "link4": (
        3.587895,
        (-5.317e-2, 1.04419e-1, 2.7454e-2),
        (2.5853e-2, 1.9552e-2, 2.8323e-2, 7.796e-3, -1.332e-3, 8.641e-3),
    ),
    "link5": (
        1.225946,
        (-1.1953e-2, 4.1065e-2, -3.8437e-2),
        (3.5549e-2, 2.9474e-2, 8.627e-3, -2.117e-3, -4.037e-3, 2.29e-4),
    ),
    "link6": (
        1.666555,
        (6.0149e-2, -1.4117e-2, -1.0517e-2),
        (1.964e-3, 4.354e-3, 5.433e-3, 1.09e-4, -1.158e-3, 3.41e-4),
    ),
    "link7": (
        7.35522e-1,
        (1.0517e-2, -4.252e-3, 6.1597e-2),
        (1.2516e-2, 1.0027e-2, 4.815e-3, -4.28e-4, -1.196e-3, -7.41e-4),
    ),
}

# Collision + visual primitives per link, in the link frame: (kind, fromto or pos, size, rgba).
# "cap"/"cyl" use fromto (x0 y0 z0 x1 y1 z1) and a radius; "box" uses pos and half sizes.
_SHAPES: dict[str, tuple[tuple[str, tuple, tuple, tuple], ...]] = {
    "link0": (
        ("cyl", (0, 0, 0.0, 0, 0, 0.16), (0.065,), WHITE),
        ("box", (-0.06, 0, 0.03), (0.085, 0.075, 0.03), OFF_WHITE),
        ("cyl", (-0.13, -0.04, 0.06, -0.13, 0.04, 0.06), (0.025,), DARK),
    ),
    "link1": (
        ("cyl", (0, 0, -0.175, 0, 0, -0.06), (0.062,), WHITE),
        ("cyl", (0, -0.065, 0, 0, 0.065, 0), (0.062,), WHITE),
    ),
    "link2": (
        ("cap", (0, -0.03, 0, 0, -0.20, 0), (0.058,), WHITE),
        ("cyl", (0, 0, -0.065, 0, 0, 0.065), (0.063,), DARK),
    ),
    "link3": (
        ("cap", (0, 0, -0.12, 0, 0, -0.02), (0.056,), WHITE),
        ("cap", (0, 0, 0, 0.0825, 0, 0), (0.055,), WHITE),
    ),
    "link4": (
        ("cyl", (0, 0, -0.06, 0, 0, 0.06), (0.058,), DARK),
        ("cap", (0, 0, 0, -0.0825, 0.10, 0), (0.055,), WHITE),
    ),
    "link5": (
        ("cap", (0, 0, -0.27, 0, 0, -0.17), (0.055,), WHITE),
        ("box", (0, 0.045, -0.17), (0.03, 0.03, 0.07), WHITE),
        ("cap", (0, 0, -0.17, 0, 0, -0.08), (0.035,), WHITE),
    ),
    "link6": (
        ("cyl", (0, 0, -0.06, 0, 0, 0.025), (0.05,), DARK),
        ("cap", (0, 0, 0, 0.088, 0, 0), (0.042,), WHITE),
    ),
    "link7": (
        ("cyl", (0, 0, -0.015, 0, 0, 0.075), (0.045,), WHITE),
        ("cyl", (0, 0, 0.075, 0, 0, HAND_OFFSET), (0.032,), DARK),
    ),
}


@dataclass(frozen=True)
class PandaNames:
    """Fully prefixed names of the Panda's elements in a compiled model."""

    prefix: str
    joints: tuple[str, ...]
    finger_joints: tuple[str, str]
    actuators: tuple[str, ...]
    gripper_actuator: str
    site: str
    base_body: str
    hand_body: str
    bodies: tuple[str, ...]
    finger_bodies: tuple[str, str]
    finger_geoms: tuple[str, str]
    grasp_equality: str

    @staticmethod
    def with_prefix(prefix: str) -> PandaNames:
        p = prefix
        links = tuple(f"{p}link{i}" for i in range(8))
        fingers = (f"{p}left_finger", f"{p}right_finger")
        return PandaNames(
            prefix=p,
            joints=tuple(p + j for j in ARM_JOINTS),
            finger_joints=(p + FINGER_JOINTS[0], p + FINGER_JOINTS[1]),
            actuators=tuple(f"{p}actuator{i}" for i in range(1, 8)),
            gripper_actuator=f"{p}gripper",
            site=f"{p}grasp_site",
            base_body=links[0],
            hand_body=f"{p}hand",
            bodies=links + (f"{p}hand",) + fingers,
            finger_bodies=fingers,
            finger_geoms=(f"{p}left_finger_pad", f"{p}right_finger_pad"),
            grasp_equality=f"{p}grasp_connect",
        )


def _add_shape(
    body: mujoco.MjsBody,
    name: str,
    kind: str,
    where: tuple,
    size: tuple,
    rgba: tuple,
    friction: tuple = (1.0, 0.005, 0.0001),
    condim: int = 3,
    stiff: bool = False,
    contype: int = ROBOT_CONTYPE,
) -> None:
    g = body.add_geom(name=name)
    if kind in ("cap", "cyl"):
        g.type = mujoco.mjtGeom.mjGEOM_CAPSULE if kind == "cap" else mujoco.mjtGeom.mjGEOM_CYLINDER
        g.fromto = list(where)
        g.size = [size[0], 0, 0]
    else:
        g.type = mujoco.mjtGeom.mjGEOM_BOX
        g.pos = list(where)
        g.size = list(size)
    g.rgba = list(rgba)
    g.contype = contype
    g.conaffinity = ROBOT_CONAFFINITY
    g.group = ROBOT_GEOM_GROUP
    g.friction = list(friction)
    g.condim = condim
    g.mass = 0.0  # inertia comes from the explicit inertials
    if stiff:  # fingers: their contact parameters win over the hose's, and are hard
        g.priority = 1
        g.solref = list(_FINGER_SOLREF)
        g.solimp = list(_FINGER_SOLIMP)


def reach_pads(spec: mujoco.MjSpec, depth: float, prefix: str = "panda/") -> None:
    """Lengthen both finger pads' collision boxes by ``depth`` (m) past the fingertips, where a
    surface lets the pads in (the table scene's mat and table top, ``PAD_CONTYPE``).  The pads
    look as before: each collision box moves to the hidden group 3 (as under mesh visuals) and
    a visual-only copy of the pad as built (``{side}_finger_pad_visual``, no contacts, no mass)
    takes its place in the picture and the labels.

    Why: MuJoCo pushes a cable vertex whose centre has passed into a box out through the face
    nearest that centre.  A 2 mm wire grasped on the mat lies with its centre 1 mm above the
    pads' lower edge, and squeezed (its soft contacts let the pads 0.7 mm into it from each
    side) each pad's face is about 0.3 mm from that centre; a solver step that carries the
    centre more than 1 mm into a pad turns the contact towards the lower face, and the wire is
    pushed out under the fingertips (traced on table thin-wire seed 10710, docs/cables.md).
    With the pads reaching below the tips that face is ``depth`` further away, and the contact
    pushes the wire back between the pads."""
    if depth <= 0:
        return
    p = prefix
    for side in ("left", "right"):
        pad = spec.geom(f"{p}{side}_finger_pad")
        look = spec.body(f"{p}{side}_finger").add_geom(name=f"{p}{side}_finger_pad_visual")
        look.type = pad.type
        look.pos = pad.pos.copy()
        look.size = pad.size.copy()
        look.rgba = pad.rgba.copy()
        look.group = pad.group
        look.contype = 0
        look.conaffinity = 0
        look.mass = 0.0
        pad.group = HIDDEN_COLLISION_GROUP
        pad.size = [pad.size[0], pad.size[1], pad.size[2] + depth / 2]
        pad.pos = [pad.pos[0], pad.pos[1], pad.pos[2] + depth / 2]


def finger_contact_geoms(model: mujoco.MjModel, prefix: str = "panda/") -> np.ndarray:
    """Ids of the fingers' colliding geoms (each finger's pad and the body behind it)."""
    names = [
        f"{prefix}{side}_finger_{part}" for side in ("left", "right") for part in ("pad", "body")
    ]
    return np.asarray([model.geom(n).id for n in names], dtype=int)


def set_finger_contact_dmax(model: mujoco.MjModel, dmax: float, prefix: str = "panda/") -> None:
    """Set the fingers' contact ``solimp`` dmax in a compiled ``model`` (the default,
    :data:`FINGER_CONTACT_DMAX`, leaves it as built, bit for bit)."""
    model.geom_solimp[finger_contact_geoms(model, prefix), 1] = dmax


def _set_inertial(body: mujoco.MjsBody, link: str) -> None:
    mass, com, full = _INERTIALS[link]
    body.mass = mass
    body.ipos = list(com)
    body.fullinertia = list(full)
    body.explicitinertial = True


def _add_hand(link7: mujoco.MjsBody, p: str) -> None:
    hand = link7.add_body(
        name=f"{p}hand", pos=[0, 0, HAND_OFFSET], quat=[0.9238795, 0, 0, -0.3826834]
    )
    hand.mass = 0.73
    hand.ipos = [-0.01, 0, 0.03]
    hand.inertia = [0.001, 0.0025, 0.0017]
    hand.explicitinertial = True
    hand.gravcomp = 1.0
    _add_shape(hand, f"{p}hand_box", "box", (0, 0, 0.03), (0.03, 0.072, 0.028), OFF_WHITE)
    for side, y in (("l", 0.072), ("r", -0.072)):
        _add_shape(
            hand, f"{p}hand_end_{side}", "cyl", (-0.03, y, 0.03, 0.03, y, 0.03), (0.028,), OFF_WHITE
        )
    _add_shape(hand, f"{p}hand_rail", "box", (0, 0, 0.0545), (0.012, 0.06, 0.004), DARK)
    hand.add_site(
        name=f"{p}grasp_site",
        pos=[0, 0, TCP_OFFSET],
        size=[0.005, 0, 0],
        rgba=[1, 0, 0, 0],
        group=4,
    )
    for side, quat in (("left", (1, 0, 0, 0)), ("right", (0, 0, 0, 1))):
        finger = hand.add_body(name=f"{p}{side}_finger", pos=[0, 0, 0.0584], quat=list(quat))
        finger.mass = 0.015
        finger.inertia = [2.375e-6, 2.375e-6, 7.5e-7]
        finger.explicitinertial = True
        finger.gravcomp = 1.0
        j = finger.add_joint(name=f"{p}finger_joint{1 if side == 'left' else 2}")
        j.type = mujoco.mjtJoint.mjJNT_SLIDE
        j.axis = [0, 1, 0]
        j.range = list(FINGER_RANGE)
        j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        j.armature = 0.05
        j.damping = [2.0, 0.0, 0.0]
        # Finger body behind the pad (y from 7 mm to 19 mm), then the high-friction pad.
        _add_shape(
            finger,
            f"{p}{side}_finger_body",
            "box",
            (0, 0.013, 0.026),
            (0.0105, 0.006, 0.026),
            OFF_WHITE,
            stiff=True,
        )
        _add_shape(
            finger,
            f"{p}{side}_finger_pad",
            "box",
            (0, 0.0035, 0.0393),
            (0.01, 0.0035, 0.0152),
            PAD,
            friction=(1.5, 0.01, 0.0002),
            condim=4,
            stiff=True,
            contype=PAD_CONTYPE,
        )


def panda_spec(prefix: str = "", home_key: bool = True, visual: str = "primitive") -> mujoco.MjSpec:
    """The standalone Panda on the world body, base at the origin, at ``HOME_QPOS``.

    ``home_key`` adds a keyframe ``home`` (only meaningful while the spec holds only the arm).
    ``visual="mesh"`` draws franka_ros's meshes instead of the primitives, which still collide
    (:mod:`cablesim.panda.visuals`; the physics is the same bit for bit).
    """
    check_visual(visual, "visual")
    p = prefix
    spec = mujoco.MjSpec()
    spec.modelname = "panda"
    spec.compiler.degree = False
    parent = spec.worldbody.add_body(name=f"{p}link0")
    _set_inertial(parent, "link0")
    for gi, (kind, where, size, rgba) in enumerate(_SHAPES["link0"]):
        _add_shape(parent, f"{p}link0_g{gi}", kind, where, size, rgba)
    for i, (link, pos, quat) in enumerate(_LINKS):
        body = parent.add_body(name=p + link, pos=list(pos), quat=list(quat))
        _set_inertial(body, link)
        body.gravcomp = 1.0  # the real arm compensates gravity in its controller
        j = body.add_joint(name=p + ARM_JOINTS[i])
        j.axis = [0, 0, 1]
        j.range = list(JOINT_LIMITS[i])
        j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        j.armature = 0.1
        j.damping = [1.0, 0.0, 0.0]
        for gi, (kind, where, size, rgba) in enumerate(_SHAPES[link]):
            _add_shape(body, f"{p}{link}_g{gi}", kind, where, size, rgba)
        parent = body
    _add_hand(parent, p)
    _add_finger_stop(spec, p)
    _add_actuators(spec, p)
    if visual == "mesh":
        add_mesh_visuals(spec, p)
    if home_key:
        key = spec.add_key(name="home")
        key.qpos = list(HOME_QPOS) + [FINGER_RANGE[1]] * 2
        key.ctrl = list(HOME_QPOS) + [MAX_OPENING]
    return spec


def _add_finger_stop(spec: mujoco.MjSpec, p: str) -> None:
    """The two finger pads touch, as on the real hand, where a closing gripper meets nothing.

    The robot's geoms do not collide with each other (``ROBOT_CONTYPE`` & ``ROBOT_CONAFFINITY``
    is 0), and the fingers' joint limit at 0 is soft: against 70 N the fingers of a hand that
    closed past a light cable crossed by 9 mm each, trapped it between the crossed pads and
    could not open again (table rope seed 11194: the rope was dragged along by the retreat and
    torn).  This contact pair is the mechanical stop; it is inactive (no contact, no
    constraint row) while the pads are apart, so a grasp whose pads never meet steps as before,
    bit for bit.  It does not stop fingers that slam shut (a cable leaving the pads mid-stroke
    lets them close from 7.7 mm at 70 N and pass through each other within a step, table rope
    seed 11207): the simulated gripper has no speed limit."""
    pair = spec.add_pair(
        name=f"{p}finger_stop",
        geomname1=f"{p}left_finger_pad",
        geomname2=f"{p}right_finger_pad",
    )
    pair.condim = 1
    pair.solref = list(_FINGER_SOLREF)
    pair.solimp = list(_FINGER_SOLIMP)


def _add_actuators(spec: mujoco.MjSpec, p: str) -> None:
    for i in range(7):
        a = spec.add_actuator(name=f"{p}actuator{i + 1}", target=p + ARM_JOINTS[i])
        a.trntype = mujoco.mjtTrn.mjTRN_JOINT
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        kp = _KP[i]
        a.gainprm[0] = kp
        a.biasprm[0:3] = [0.0, -kp, -kp / 10.0]
        a.ctrlrange = list(JOINT_LIMITS[i])
        a.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        a.forcerange = [-_TORQUE[i], _TORQUE[i]]
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    # Fingers: tendon length = q1 + q2 = opening width; equality keeps them symmetric.
    tendon = spec.add_tendon(name=f"{p}finger_split")
    tendon.wrap_joint(p + FINGER_JOINTS[0], 1.0)
    tendon.wrap_joint(p + FINGER_JOINTS[1], 1.0)
    eq = spec.add_equality(
        name=f"{p}finger_sync",
        type=mujoco.mjtEq.mjEQ_JOINT,
        name1=p + FINGER_JOINTS[0],
        name2=p + FINGER_JOINTS[1],
    )
    eq.solref = [0.005, 1.0]
    eq.solimp = [0.95, 0.99, 0.001, 0.5, 2.0]
    g = spec.add_actuator(name=f"{p}gripper", target=f"{p}finger_split")
    g.trntype = mujoco.mjtTrn.mjTRN_TENDON
    g.gaintype = mujoco.mjtGain.mjGAIN_FIXED
    g.biastype = mujoco.mjtBias.mjBIAS_AFFINE
    g.gainprm[0] = _GRIPPER_KP
    g.biasprm[0:3] = [0.0, -_GRIPPER_KP, -_GRIPPER_KV]
    g.ctrlrange = [0.0, MAX_OPENING]
    g.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    g.forcerange = [-DEFAULT_GRASP_FORCE, DEFAULT_GRASP_FORCE]
    g.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    # Equality used by the explicit ``grasp_mode="equality"`` fallback; its second body and
    # anchors are set at grasp time.  Inactive by default.
    c = spec.add_equality(
        name=f"{p}grasp_connect",
        type=mujoco.mjtEq.mjEQ_CONNECT,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=f"{p}hand",
        name2="world",
    )
    c.active = False
    c.solref = [0.02, 1.0]


def attach_panda(
    scene: mujoco.MjSpec,
    pos: Sequence[float] = (0.0, 0.0, 0.0),
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    prefix: str = "panda/",
    visual: str = "primitive",
) -> PandaNames:
    """Attach a Panda to ``scene``'s world body at ``pos``/``quat`` (wxyz); names get ``prefix``.
    ``visual``: ``"primitive"`` or ``"mesh"`` (see :func:`panda_spec`)."""
    arm = panda_spec(home_key=False, visual=visual)
    frame = scene.worldbody.add_frame(pos=list(pos), quat=list(quat))
    scene.attach(arm, prefix=prefix, frame=frame)
    return PandaNames.with_prefix(prefix)


def robot_body_ids(model: mujoco.MjModel, prefix: str = "panda/") -> np.ndarray:
    """Ids of all bodies in the subtree of ``{prefix}link0`` (the whole robot)."""
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{prefix}link0")
    if root < 0:
        return np.zeros(0, dtype=int)
    ids = [b for b in range(model.nbody) if _is_descendant(model, b, root)]
    return np.asarray(ids, dtype=int)


def robot_geom_ids(model: mujoco.MjModel, prefix: str = "panda/") -> np.ndarray:
    """Ids of all geoms attached to robot bodies."""
    bodies = set(robot_body_ids(model, prefix).tolist())
    return np.asarray([g for g in range(model.ngeom) if model.geom_bodyid[g] in bodies], dtype=int)


def _is_descendant(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return root == 0


def joint_qpos_addresses(model: mujoco.MjModel, names: Sequence[str]) -> np.ndarray:
    """qpos addresses of the named 1-dof joints."""
    return np.asarray([model.jnt_qposadr[model.joint(n).id] for n in names], dtype=int)


def set_home(model: mujoco.MjModel, data: mujoco.MjData, names: PandaNames) -> None:
    """Put the arm at ``HOME_QPOS`` with fingers open and matching controls (no forward call)."""
    set_arm(model, data, names, HOME_QPOS)


def set_arm(
    model: mujoco.MjModel, data: mujoco.MjData, names: PandaNames, q: Sequence[float]
) -> None:
    """Put the arm at joint angles ``q`` (7,) with fingers open and matching controls."""
    q = np.asarray(q, dtype=float)
    data.qpos[joint_qpos_addresses(model, names.joints)] = q
    data.qpos[joint_qpos_addresses(model, names.finger_joints)] = FINGER_RANGE[1]
    for i, a in enumerate(names.actuators):
        data.ctrl[model.actuator(a).id] = q[i]
    data.ctrl[model.actuator(names.gripper_actuator).id] = MAX_OPENING


def set_grasp_force(model: mujoco.MjModel, names: PandaNames, force: float) -> None:
    """Limit the force each finger can exert (N)."""
    a = model.actuator(names.gripper_actuator).id
    model.actuator_forcerange[a] = (-abs(force), abs(force))
