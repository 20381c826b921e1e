"""The simulated world: a MuJoCo model of the table, the task board, the hoses, the Panda and
the RGB-D camera, built from a ``SceneConfig`` and settled before anything is recorded.

    world = World.build(SceneConfig(seed=3))   # compiled, start shapes set, settled (cached)
    world.step(10)                             # raises PhysicsDivergedError on NaN/instability
    world.hose_vertices(0)                     # (V, 3) world positions of hose 0's rod

Step hooks (as dm_control's composer has ``before_substep``/``after_substep``): callables in
``world.before_step`` run before every physics step, those in ``world.after_step`` after it;
each gets the world.  The camera clock and the neighbour perturbation are such hooks::

    with world.hooks(after=[on_step]):
        robot.move_to(pose)                    # on_step(world) after every physics step

A device's own firmware is a controller instead (``world.controllers``, by name): it runs at
the start of every step however the world is stepped, as the simulated gripper's force limit
(``cablesim.sim.sim_panda``) does.

Each hose is a MuJoCo 4.0 1D ``flexcomp`` (rod elasticity, integrator ``discrete``).  The rod is
built straight (its rest shape), then bent into its start shape through the vertex joints; a
far end attached to a second connector is held by a ``connect`` equality (SPEC section 9).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import mujoco
import numpy as np

from cablesim.cables import CableKind
from cablesim.episode.surface import SURFACES, Surface
from cablesim.errors import PhysicsDivergedError
from cablesim.panda.model import attach_panda, reach_pads, set_arm, set_finger_contact_dmax
from cablesim.panda.visuals import add_mesh_visuals_same_view
from cablesim.seeding import stream
from cablesim.sim import assets
from cablesim.sim.config import SceneConfig
from cablesim.sim.hand_board import add_hand_board
from cablesim.sim.layout import (
    FEMALE_OVERLAP,
    CameraPose,
    HoseSpec,
    sample_camera,
    sample_hoses,
    start_shape,
)
from cablesim.sim.settle import settle_world
from cablesim.sim.table import (
    MAT_DEPTH,
    MAT_TOP,
    PLUG_LENGTH,
    SOCKET_HALF,
    socket_direction,
    socket_point,
)

CAMERA_NAME = "rgbd"
#: Collision bits of the table scene's mat and table top: they touch the cables and the arm
#: (``conaffinity`` 1 | 2) but not the finger pads (``PAD_CONTYPE``, conaffinity 1), so a
#: grasp on the table may reach down to the mat (``TABLE.clearance``) as a compliant real hand
#: does, without the pads' soft contact on a rigid mat jamming the closing fingers.
YIELDING_BITS = ' contype="16" conaffinity="3"'
_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADCTRL,
    mujoco.mjtWarning.mjWARN_CNSTRFULL,
    mujoco.mjtWarning.mjWARN_CONTACTFULL,
)


_WARNING_INDEX = np.array([int(w) for w in _WARNINGS])
_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
_SOLVERS = {"Newton": int(mujoco.mjtSolver.mjSOL_NEWTON), "CG": int(mujoco.mjtSolver.mjSOL_CG)}

StepHook = Callable[["World"], None]

#: The geoms the hoses lie or hang on (the scene XML's names): a hose sunk deep into one of
#: them starts a rescue (``physics.rescue_depth``)
SURFACE_GEOMS = ("table", "mat", "board")
#: m/s: a hose deeper than ``physics.rescue_depth`` in a surface that goes deeper faster than
#: this is sinking through it (0.4 mm per 4 ms step; on seed 11326 the sinking vertices went
#: 0.6-1.5 mm deeper per step, a resting cable's depth changes by microns)
SINK_SPEED = 0.1


@dataclass(frozen=True)
class Hose:
    """A hose in the compiled model."""

    spec: HoseSpec
    flex_id: int
    vert_adr: int  # first vertex in data.flexvert_xpos
    n_vertices: int
    vertex_bodies: np.ndarray  # body id of each vertex (0 = pinned to the world)
    start_equality: int  # id of the connect equality holding the first end
    end_equality: int | None  # id of the connect equality holding the far end


def look_at_frame(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """3x3 rotation whose columns are the OpenCV camera axes (x right, y down, z forward)."""
    fwd = np.asarray(target, float) - np.asarray(position, float)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return np.stack([right, down, fwd], 1)


def _fmt(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.ravel(v))


KEY_LIGHT_DIR = (0.45, 0.2, -0.87)


def _lighting(cfg: SceneConfig) -> dict[str, str]:
    """Headlight and key light of the scene (``LightConfig``; jittered from the seed's
    ``lighting`` stream when ``jitter`` > 0)."""
    li = cfg.light
    gains, direction = np.ones(3), np.array(KEY_LIGHT_DIR)
    if li.jitter > 0:
        rng = stream(cfg.seed, "lighting")
        gains = rng.uniform(1 - li.jitter, 1 + li.jitter, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(-li.jitter, li.jitter)
        # Rodrigues: turn the key light's direction about a random axis
        d = direction
        direction = (
            d * math.cos(angle)
            + np.cross(axis, d) * math.sin(angle)
            + axis * (axis @ d) * (1 - math.cos(angle))
        )
    ambient, diffuse, key = (li.ambient, li.diffuse, li.key) * gains
    return {
        "ambient": _fmt([ambient] * 3),
        "diffuse": _fmt([diffuse] * 3),
        "key": _fmt([key] * 3),
        "dir": _fmt(direction),
    }


def cable_xml(
    name: str,
    cable: CableKind,
    young: float,
    n_vertices: int,
    spacing: float,
    centre: np.ndarray,
    quat: str,
    rgb: Sequence[float],
    mass: float,
    section: str = "",
    inner: str = "",
) -> str:
    """The MJCF ``flexcomp`` of one cable: a straight rod of ``n_vertices`` along its grid x
    axis (turned by ``quat``), centred on ``centre``, with ``cable``'s radius, Poisson ratio
    and friction and the drawn ``young``; ``inner`` goes inside (e.g. a ``pin``)."""
    c = cable
    return f"""
    <flexcomp name="{name}" type="grid" count="{n_vertices} 1 1" spacing="{spacing:.9g} 1 1"
              pos="{_fmt(centre)}" quat="{quat}" dim="1" dof="full"
              radius="{c.radius}" rgba="{_fmt(rgb)} 1" mass="{mass:.6g}">
      <edge equality="true" solimp="0.99 0.999 0.001" solref="0.004 1" damping="0"/>
      <elasticity young="{young:.6g}" poisson="{c.poisson}" damping="0.0005"{section}/>
      <contact condim="3" solref="0.01 1" solimp="0.95 0.99 0.001" friction="{c.friction} 0.005 0.0001"
               selfcollide="none"/>{inner}
    </flexcomp>"""


def _scene_xml(cfg: SceneConfig, hoses: list[HoseSpec], cam: CameraPose) -> str:
    h = cfg.hoses
    R = look_at_frame(cam.position, cam.look_at)
    flexes, equalities = [], []
    table_bits = ""
    if cfg.surface == "table":
        board_mat, board_geoms = _table_xml(cfg, hoses)
        table_bits = YIELDING_BITS
    else:
        board_mat, board_geoms = _board_xml(cfg, hoses)
    light = _lighting(cfg)
    for s in hoses:
        top = start_shape(cfg, s)[0]
        spacing = s.length / (s.n_vertices - 1)
        c = s.cable
        mass = c.mass_per_metre * s.length * c.inertia_scale  # weight: gravity compensation
        section = ""
        if h.section == "box":
            size = h.section_size or (c.radius, c.radius)
            section = f' section="box" sectionsize="{_fmt(size)}"'
        # straight rod hanging from its first end: grid x axis -> world -z
        centre = top - np.array([0, 0, spacing * (s.n_vertices - 1) / 2])
        flexes.append(
            cable_xml(
                s.name,
                c,
                s.young,
                s.n_vertices,
                spacing,
                centre,
                "0.70710678 0 0.70710678 0",
                s.rgb,
                mass,
                section,
            )
        )
        # Ends are held by connect equalities rather than pinned: a pinned vertex cannot give
        # way, and contacts on the edge next to it chatter (measured: 20-100 mm/s forever).
        held = [(f"{s.name}_start", 0)]
        if s.both_ends:
            held.append((f"{s.name}_far_end", s.n_vertices - 1))
        for name, vertex in held:
            equalities.append(
                f'<connect name="{name}" body1="{s.name}_{vertex}" body2="world" anchor="0 0 0" '
                f'solref="0.004 1" solimp="0.99 0.999 0.001"/>'
            )
    cam_xy = np.concatenate([R[:, 0], -R[:, 1]])
    return f"""
<mujoco model="cablesim_task_board">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{cfg.physics.timestep!r}" integrator="discrete" gravity="0 0 {cfg.physics.gravity}"
          cone="elliptic" impratio="{cfg.impratio()!r}" solver="{cfg.physics.solver}"{_sleep_xml(cfg.physics)}
  <size memory="64M"/>
  <visual>
    <global offwidth="{max(1280, cfg.camera.width)}" offheight="{max(720, cfg.camera.height)}"/>
    <quality shadowsize="0"/>
    <map znear="{cfg.camera.near / 5:.6g}" zfar="{cfg.camera.far / 5:.6g}"/>
    <headlight ambient="{light["ambient"]}" diffuse="{light["diffuse"]}" specular="0.05 0.05 0.05"/>
  </visual>
  <default>
    <geom solref="0.01 1"/>
  </default>
  <asset>
    <mesh name="male" file="{assets.mesh_path("male")}"/>
    <mesh name="female" file="{assets.mesh_path("female")}"/>
    <texture name="table_tex" type="2d" builtin="checker" rgb1="0.42 0.40 0.38" rgb2="0.46 0.44 0.42"
             width="256" height="256" mark="random" random="0.05" markrgb="0.3 0.3 0.3"/>
    <material name="table" texture="table_tex" texrepeat="6 6" specular="0.05"/>
    <material name="brass" rgba="0.80 0.66 0.30 1" specular="0.5" shininess="0.6"/>
    <material name="floor" rgba="0.25 0.25 0.27 1"/>
    <texture name="room" type="skybox" builtin="gradient" rgb1="0.62 0.63 0.66" rgb2="0.32 0.33 0.36"
             width="64" height="64"/>
    {board_mat}
  </asset>
  <worldbody>
    <light name="key" pos="-0.6 -0.4 2.2" dir="{light["dir"]}" directional="true" castshadow="false"
           diffuse="{light["key"]}" specular="0.1 0.1 0.1"/>
    <geom name="floor" type="plane" size="3 3 0.1" pos="0 0 -0.75" material="floor" contype="0" conaffinity="0"/>
    <geom name="table" type="box" size="0.75 0.85 0.02" pos="0.15 0 -0.02" material="table" friction="0.8"{table_bits}/>
    {board_geoms}
    <camera name="{CAMERA_NAME}" mode="fixed" pos="{_fmt(cam.position)}" xyaxes="{_fmt(cam_xy)}"
            fovy="{cfg.camera.fovy}"/>
    {"".join(flexes)}
  </worldbody>
  <equality>
    {"".join(equalities)}
  </equality>
</mujoco>"""


def _sleep_xml(physics) -> str:
    """The end of the ``<option>`` element: MuJoCo's sleeping islands when
    ``physics.sleep_tolerance`` > 0 (see :class:`~cablesim.sim.config.PhysicsConfig`)."""
    if physics.sleep_tolerance <= 0:
        return "/>"
    return (
        f' sleep_tolerance="{physics.sleep_tolerance!r}">\n    <flag sleep="enable"/>\n  </option>'
    )


def _background_material(
    name: str, background: str, solid_rgb: Sequence[float], specular: float
) -> str:
    """The MJCF material ``name`` of a board or mat: ``solid_rgb`` for "solid", else the
    background's texture (and its texture element)."""
    if background == "solid":
        return f'<material name="{name}" rgba="{_fmt(solid_rgb)} 1" specular="{specular}"/>'
    return (
        f'<texture name="{name}_tex" type="2d" file="{assets.texture_path(background)}"/>'
        f'<material name="{name}" texture="{name}_tex" texrepeat="1 1" specular="{specular}"/>'
    )


def _board_xml(cfg: SceneConfig, hoses: list[HoseSpec]) -> tuple[str, str]:
    """(assets, world geoms) of the task board: the board, its connectors and the coupling on
    every attached hose end."""
    b = cfg.board
    mat = _background_material("board", b.background, b.solid_rgb, 0.1)
    geoms = [
        f'<geom name="board" type="box" size="{b.thickness / 2:.6g} {b.width / 2:.6g} '
        f'{b.height / 2:.6g}" pos="{b.x + b.thickness / 2:.6g} 0 {b.height / 2:.6g}" '
        'material="board" friction="0.6"/>'
    ]
    x_tip = b.x - b.connector_length
    for i, (y, z) in enumerate(b.connectors):
        geoms.append(
            f'<geom name="connector{i}" type="mesh" mesh="male" pos="{b.x:.6g} {y:.6g} {z:.6g}" '
            f'quat="0 0.70710678 0 0.70710678" material="brass" contype="0" conaffinity="0"/>'
        )
    for s in hoses:
        for k, c in enumerate(s.ends):
            y, z = b.connectors[c]
            x0 = x_tip + FEMALE_OVERLAP
            geoms.append(
                f'<geom name="{s.name}_coupling{k}" type="mesh" mesh="female" '
                f'pos="{x0:.6g} {y:.6g} {z:.6g}" quat="0 0.70710678 0 0.70710678" '
                f'rgba="{_fmt(np.clip(np.array(s.rgb) * 0.7 + 0.15, 0, 1))} 1" '
                f'contype="0" conaffinity="0"/>'
            )
    return mat, "\n    ".join(geoms)


def _table_xml(cfg: SceneConfig, hoses: list) -> tuple[str, str]:
    """(assets, world geoms) of the table scene: the mat under the cable region (with the
    table's ``background``), a socket at every connector and a plug on every plugged end."""
    t = cfg.table
    fmt = _fmt

    x0, x1, y0, y1 = t.region
    m = t.mat_margin
    mat = _background_material("mat", t.background, t.solid_rgb, 0.05)
    mat += '<material name="socket" rgba="0.12 0.12 0.13 1" specular="0.2"/>'
    geoms = [
        f'<geom name="mat" type="box" size="{(x1 - x0) / 2 + m:.6g} {(y1 - y0) / 2 + m:.6g} '
        f'{(MAT_TOP + MAT_DEPTH) / 2:.6g}" pos="{(x0 + x1) / 2:.6g} {(y0 + y1) / 2:.6g} '
        f'{(MAT_TOP - MAT_DEPTH) / 2:.6g}" '
        f'material="mat" friction="0.8"{YIELDING_BITS}/>'
    ]
    hz = (t.socket_height + 0.012) / 2  # the socket box reaches 12 mm above a plug's centre
    for i, (x, y, yaw) in enumerate(t.connectors):
        d = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        centre = np.array([x, y, hz]) - d * SOCKET_HALF[0]  # behind its mouth at (x, y)
        quat = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        geoms.append(
            f'<geom name="socket{i}" type="box" size="{SOCKET_HALF[0]} {SOCKET_HALF[1]} {hz:.6g}" '
            f'pos="{fmt(centre)}" quat="{fmt(quat)}" material="socket"/>'
        )
    for s in hoses:
        for k, c in enumerate(s.ends):
            d = socket_direction(t, c)
            end = socket_point(cfg, c)
            mid = end - d * PLUG_LENGTH / 2
            # a cylinder along the socket's yaw: its z axis turned onto d
            quat = _quat_z_to(d)
            rgb = np.clip(np.array(s.rgb) * 0.7 + 0.15, 0, 1)
            geoms.append(
                f'<geom name="{s.name}_plug{k}" type="cylinder" '
                f'size="{max(1.6 * s.radius, 0.004):.6g} {PLUG_LENGTH / 2:.6g}" pos="{fmt(mid)}" '
                f'quat="{fmt(quat)}" rgba="{fmt(rgb)} 1" contype="0" conaffinity="0"/>'
            )
    return mat, "\n    ".join(geoms)


def _quat_z_to(d: np.ndarray) -> tuple[float, float, float, float]:
    """The rotation (w, x, y, z) taking the z axis onto the horizontal unit vector ``d``."""
    # z -> d: rotate by 90 degrees about the axis z x d
    axis = np.cross([0.0, 0.0, 1.0], d)
    axis /= np.linalg.norm(axis)
    s = math.sin(math.pi / 4)
    return (math.cos(math.pi / 4), axis[0] * s, axis[1] * s, axis[2] * s)


def compensate_weight(spec: mujoco.MjSpec, name: str, cable: CableKind) -> None:
    """The cable ``name``'s vertex bodies carry ``1 - 1/inertia_scale`` of their own weight by
    gravity compensation: built with ``inertia_scale`` times the kind's mass, they weigh what
    the kind weighs and move as if heavier (:attr:`CableKind.inertia_scale`)."""
    if cable.inertia_scale == 1:
        return
    for body in spec.bodies:
        if body.name.startswith(f"{name}_"):
            body.gravcomp = 1.0 - 1.0 / cable.inertia_scale


def damp_cable_dofs(model: mujoco.MjModel, joints: Iterable[int], cable: CableKind) -> None:
    """Velocity damping on a cable's vertex joints ``joints`` (air drag and its internal
    losses): the kind's ``damping`` times its ``inertia_scale`` (the same decay as built) on
    each slide dof, 1e-4 of that on each hinge dof."""
    damping = cable.damping * cable.inertia_scale
    for j in joints:
        adr = model.jnt_dofadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
            model.dof_damping[adr] = damping
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            model.dof_damping[adr] = damping * 1e-4


def _damp_hoses(model: mujoco.MjModel, hoses: list[Hose]) -> None:
    """:func:`damp_cable_dofs` on every hose's vertex joints."""
    prefixes = [h.spec.name + "_" for h in hoses]
    joints: list[list[int]] = [[] for _ in hoses]
    for j in range(model.njnt):
        body = model.body(model.jnt_bodyid[j]).name
        for k, prefix in enumerate(prefixes):
            if body.startswith(prefix):
                joints[k].append(j)
                break
    for hose, js in zip(hoses, joints, strict=True):
        damp_cable_dofs(model, js, hose.spec.cable)


class World:
    """A compiled, settled scene.  Build with ``World.build(cfg)``."""

    def __init__(
        self,
        cfg: SceneConfig,
        spec: mujoco.MjSpec,
        model: mujoco.MjModel,
        hoses: list[Hose],
        camera_pose: CameraPose,
        panda=None,
        panda_base: tuple[np.ndarray, np.ndarray] | None = None,
    ):
        self.cfg = cfg
        self.spec = spec
        self.model = model
        self.data = mujoco.MjData(model)
        self.hoses = hoses
        self.camera_pose = camera_pose
        self.camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA_NAME)
        self.panda = panda
        self.panda_base = panda_base
        R = look_at_frame(camera_pose.position, camera_pose.look_at)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, camera_pose.position
        self.T_world_camera = T
        self._warn_counts = np.zeros(len(_WARNINGS), int)
        # rest length of every hose edge: a stretched edge is a blow-up (check_diverged);
        # an edge of zero rest length (none in a hose) is left out
        length0 = model.flexedge_length0
        self._edge_length0 = np.where(length0 > 0, length0, 1.0)
        self._zero_rest_edges = np.flatnonzero(length0 <= 0)
        self._settled_state: np.ndarray | None = None
        # Newton with CG standing in where Newton stalls (see PhysicsConfig and _advance)
        self._solver = int(model.opt.solver)
        self._fallback_steps = 0
        self._settling = False  # inside settling(): see fallback_time
        self._fallbacks = 0  # how often CG stood in since the last reset
        # accurate steps (Newton, dense Jacobian) while a hose is stretched (see _advance)
        self._jacobian = int(model.opt.jacobian)
        self._rescue_steps = 0
        self._rescues = 0
        self._rescue_release = cfg.rescue_release()  # ends a rescue early (0: never)
        # a hose sunk this deep into the board, the table or its mat (not a socket or a
        # coupling) starts a rescue too (see _advance); 0: never
        self._rescue_depth = cfg.rescue_depth()
        self._surface_geom = np.zeros(model.ngeom, bool)
        for name in SURFACE_GEOMS:
            gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
            if gid >= 0:
                self._surface_geom[gid] = True
        self._last_depth = 0.0  # the deepest a hose lay in a surface after the last step
        # a cable vertex whose equation of motion the solver left this far off (m/s^2) sends
        # the step to CG, and then to a rescue (see _unsolved); 0: never
        self._rescue_residual = cfg.rescue_residual()
        self._vertex_dofs = np.asarray(
            [
                a
                for h in hoses
                for b in h.vertex_bodies  # a pinned vertex (body 0) has none
                for a in range(model.body_dofadr[b], model.body_dofadr[b] + model.body_dofnum[b])
            ],
            dtype=int,
        )
        self._vertex_mass = model.dof_M0[self._vertex_dofs].copy()
        self._Mqacc = np.zeros(model.nv)
        self._step_state = np.empty(mujoco.mj_stateSize(model, _STATE))
        self.before_step: list[StepHook] = []
        self.after_step: list[StepHook] = []
        # a device's own controllers, by name, run at the start of every physics step (inside
        # ``step``'s divergence checks, unlike the hooks): the simulated gripper's force limit
        self.controllers: dict[str, StepHook] = {}

    # ------------------------------------------------------------------ building
    @classmethod
    def build(cls, cfg: SceneConfig | None = None, settle: bool = True) -> World:
        cfg = cfg or SceneConfig()
        hose_specs = sample_hoses(cfg)
        cam = sample_camera(cfg)
        try:
            spec = mujoco.MjSpec.from_string(_scene_xml(cfg, hose_specs, cam))
        except (ValueError, mujoco.FatalError) as e:  # names the failing part for the user
            raise PhysicsDivergedError(f"the scene failed to compile: {e}") from e
        for s in hose_specs:
            compensate_weight(spec, s.name, s.cable)
        panda = panda_base = None
        if cfg.robot.enabled:
            yaw = cfg.robot.base_yaw
            quat = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
            panda = attach_panda(
                spec, pos=tuple(cfg.robot.base_position), quat=quat, prefix="panda/"
            )
            panda_base = (np.array(cfg.robot.base_position, float), np.array(quat))
            if cfg.robot.hand_board:
                add_hand_board(spec, panda)
            if cfg.surface == "table":  # the mat and the table top let the pads in
                reach_pads(spec, cfg.table.pad_reach, prefix="panda/")
        try:
            model = spec.compile()
            if panda is not None and cfg.robot.visual == "mesh":
                model = add_mesh_visuals_same_view(spec, model, prefix="panda/")
            if panda is not None:
                set_finger_contact_dmax(model, cfg.hoses.finger_contact_dmax(), prefix="panda/")
        except Exception as e:  # pragma: no cover - names the failing part for the user
            raise PhysicsDivergedError(f"the scene failed to compile: {e}") from e
        hoses = []
        for s in hose_specs:
            fid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, s.name)
            adr, num = int(model.flex_vertadr[fid]), int(model.flex_vertnum[fid])
            eq = (
                mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, f"{s.name}_far_end")
                if s.both_ends
                else None
            )
            start = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, f"{s.name}_start")
            bodies = model.flex_vertbodyid[adr : adr + num].copy()
            hoses.append(Hose(s, fid, adr, num, bodies, start, eq))
        _damp_hoses(model, hoses)
        world = cls(cfg, spec, model, hoses, cam, panda, panda_base)
        try:
            world._set_start_shapes()
        except mujoco.FatalError as e:
            raise PhysicsDivergedError(f"the scene's start state failed: {e}") from e
        if settle:
            settle_world(world)
        return world

    def _set_start_shapes(self) -> None:
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        if self.panda is not None:
            set_arm(m, d, self.panda, self.cfg.robot.park_qpos)
        mujoco.mj_kinematics(m, d)
        for hose in self.hoses:
            target = start_shape(self.cfg, hose.spec)
            for k, body in enumerate(hose.vertex_bodies):
                if body == 0:
                    continue
                jadr, jnum = m.body_jntadr[body], m.body_jntnum[body]
                axes = np.stack(
                    [d.xmat[body].reshape(3, 3) @ m.jnt_axis[jadr + j] for j in range(jnum)], 1
                )
                delta = target[k] - d.xpos[body]
                sol = np.linalg.lstsq(axes, delta, rcond=None)[0]
                for j in range(jnum):
                    d.qpos[m.jnt_qposadr[jadr + j]] += sol[j]
            # connect: the anchor on the end vertex (body1) meets this world point (body2)
            m.eq_data[hose.start_equality, 3:6] = target[0]
            if hose.end_equality is not None:
                m.eq_data[hose.end_equality, 3:6] = target[-1]
        mujoco.mj_forward(m, d)

    @property
    def surface(self) -> Surface:
        """What holds the cables, as the interaction needs it (approach, action plane, the
        height under a grasp): ``cfg.surface``'s."""
        return SURFACES[self.cfg.surface]

    # ------------------------------------------------------------------ stepping
    @property
    def time(self) -> float:
        return float(self.data.time)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps, running the step hooks around each; raise
        ``PhysicsDivergedError`` if the physics blew up."""
        d = self.data
        try:
            if not (self.before_step or self.after_step):
                strain = None
                for _ in range(n):
                    # a blow-up resets the data and counts a warning: caught below
                    strain = self._advance()
                self.check_diverged(strain)
                return
            for _ in range(n):
                for hook in tuple(self.before_step):
                    hook(self)
                self.check_diverged(self._advance())
                for hook in tuple(self.after_step):
                    hook(self)
        except mujoco.FatalError as e:  # e.g. out of memory for contacts
            raise PhysicsDivergedError(f"MuJoCo stopped at t={d.time:.3f}s: {e}") from e

    def _advance(self) -> np.ndarray | None:
        """One physics step; the hoses' edge strain after it where the step measured it (else
        None).  With ``physics.solver`` Newton: if Newton stops converging (it
        hits its iteration limit, which MuJoCo 4.0's Newton does in some hose-on-hose contact
        states and then leaves the hoses jittering), the step is redone from the same state
        with CG, and CG keeps stepping for :attr:`fallback_time` before Newton resumes.
        Both solve the same convex problem; this only picks the one that converges.

        With ``physics.rescue_strain`` > 0: when a step leaves a hose edge stretched by more
        than that (a taut hose held by the arm, where CG at its iteration cap and the sparse
        Newton both stop short of the solution and the hose can run away), or with
        ``physics.rescue_depth`` > 0 leaves a hose sunk deeper than that into the table, the
        board or the mat (see :meth:`_sinking`), or with ``physics.rescue_residual`` > 0
        leaves a cable vertex's equation of motion unsolved after CG stood in for Newton (see
        :meth:`_unsolved`), the step is redone
        with Newton on a dense Jacobian, which converges in a few iterations there, and the
        dense Newton goes on for ``physics.rescue_time`` (16 ms per step instead of ~2), or
        until a dense step leaves every edge stretched by less than the resolved
        ``physics.rescue_release`` (the table's 0.1; the board runs the whole rescue)."""
        m, d = self.model, self.data
        for controller in self.controllers.values():
            controller(self)
        if self._rescue_steps == 0:
            rescue = self.cfg.physics.rescue_strain > 0 and len(self._edge_length0) > 0
            mujoco.mj_getState(m, d, self._step_state, _STATE)
            solved = self._plain_step()
            if not rescue:
                return None
            strain = self.hose_stretch()
            sinking = self._sinking()
            stretched = strain.max() > self.cfg.physics.rescue_strain
            if not (stretched or sinking or (not solved and self._unsolved())):
                return strain
            # redo the step from the saved state, and go on, with the dense Newton
            mujoco.mj_setState(m, d, self._step_state, _STATE)
            self._fallback_steps = 0
            self._rescues += 1
            m.opt.solver = _SOLVERS["Newton"]
            m.opt.jacobian = int(mujoco.mjtJacobian.mjJAC_DENSE)
            self._rescue_steps = max(1, round(self.cfg.physics.rescue_time / m.opt.timestep))
        mujoco.mj_step(m, d)
        self._rescue_steps -= 1
        release = self._rescue_release
        sinking = self._sinking()  # every step: it keeps the depth for the next one
        if (
            release > 0
            and self._rescue_steps > 0
            and not sinking
            and self.hose_stretch().max() < release
        ):
            self._rescue_steps = 0
        if self._rescue_steps == 0:
            m.opt.solver, m.opt.jacobian = self._solver, self._jacobian
        return None

    def _surface_depth(self) -> float:
        """How deep (m) the deepest hose lies in a surface (the board, the table, its mat)
        now; 0 where none touches one."""
        d = self.data
        if d.ncon == 0:
            return 0.0
        con = d.contact
        flex, geom = con.flex, con.geom
        hose0, hose1 = flex[:, 0] >= 0, flex[:, 1] >= 0
        other = np.where(hose0, geom[:, 1], geom[:, 0])
        on = (hose0 ^ hose1) & (other >= 0) & self._surface_geom[np.maximum(other, 0)]
        return max(0.0, -float(con.dist[on].min())) if on.any() else 0.0

    def _remember_depth(self) -> None:
        """Take the current state's surface depth as the last step's (after a state is set,
        so that a hose lying deep in it is not taken for one sinking)."""
        self._last_depth = self._surface_depth() if self._rescue_depth > 0 else 0.0

    def _sinking(self) -> bool:
        """Whether a hose lies deeper than ``physics.rescue_depth`` in a surface and went
        deeper in the last step, faster than :data:`SINK_SPEED`.  Where the sparse Newton
        fails on a hose lying on the table it reports convergence in one or two iterations
        while a few vertices accelerate through the mat at ~13 m/s^2 (table rope seed 11326:
        24 mm deep in 50 ms; the edge strain shows it only once the hose is torn, the depth 9
        steps earlier).  A hose that lies deep and stays there is not sinking: a plugged rope
        end rests 3.2 mm deep in the mat beside its socket (table rope seed 11420), and a
        rescue there would run the dense Newton for the whole interaction.  Called once per
        step: it keeps the depth for the next call."""
        if self._rescue_depth <= 0:
            return False
        depth = self._surface_depth()
        before, self._last_depth = self._last_depth, depth
        sunk = depth - before > SINK_SPEED * self.model.opt.timestep
        return depth > self._rescue_depth and sunk

    def _unsolved(self) -> bool:
        """Whether the last step left a cable vertex's equation of motion off by more than
        ``physics.rescue_residual``: |M qacc - qfrc_smooth - qfrc_constraint| over the
        vertex's mass, the gradient the constraint solver drives to zero.  MuJoCo 4.0's
        sparse Newton can stop after one to three iterations with it large on a few light
        vertices (a thin-wire vertex weighs 0.2 g; perhaps because its tolerance is scaled by
        the mean inertia of the whole model, arm included: not verified).  Traced on table
        thin-wire seed 14139: a stretch of wire lying on the mat 16 cm from the grasp
        accelerated down through it at about 5 m/s^2 with its contact forces rising to 1.9 N
        unanswered (residual up to 6.8e5 m/s^2), an edge beside it stretched 22 %, and the
        pull took the wire out of the fingers; in normal steps the residual is a median 0.04
        m/s^2.  Such a Newton step is redone with CG (:meth:`_plain_step`); one that CG too
        leaves unsolved starts the dense-Newton rescue (:meth:`_advance`)."""
        if self._rescue_residual <= 0 or len(self._vertex_dofs) == 0:
            return False
        m, d = self.model, self.data
        mujoco.mj_mulM(m, d, self._Mqacc, d.qacc)
        i = self._vertex_dofs
        r = self._Mqacc[i] - d.qfrc_smooth[i] - d.qfrc_constraint[i]
        return bool(np.max(np.abs(r) / self._vertex_mass) > self._rescue_residual)

    def _plain_step(self) -> bool:
        """One step with the configured solver and the CG fallback (state saved by the caller
        in ``_step_state``): a Newton step that hits the iteration limit or leaves a cable
        vertex unsolved (:meth:`_unsolved`) is redone with CG, which goes on for
        :attr:`fallback_time`.  True where the step it leaves was checked and found
        solved (so the caller need not check it again)."""
        m, d = self.model, self.data
        if self._fallback_steps > 0:
            mujoco.mj_step(m, d)
            self._fallback_steps -= 1
            if self._fallback_steps == 0:
                m.opt.solver = self._solver
            return False
        fallback = self.fallback_time
        if m.opt.solver != _SOLVERS["Newton"] or fallback <= 0:
            mujoco.mj_step(m, d)
            return False
        mujoco.mj_step(m, d)
        if self.solver_iterations() < m.opt.iterations and not self._unsolved():
            return True
        mujoco.mj_setState(m, d, self._step_state, _STATE)
        m.opt.solver = _SOLVERS["CG"]
        self._fallbacks += 1
        self._fallback_steps = max(1, round(fallback / m.opt.timestep))
        mujoco.mj_step(m, d)
        self._fallback_steps -= 1
        if self._fallback_steps == 0:
            m.opt.solver = self._solver
        return False

    def solver_iterations(self) -> int:
        """Iterations the constraint solver took in the last step (the most of any island)."""
        d = self.data
        return int(d.solver_niter[: max(1, d.nisland)].max())

    def hose_stretch(self) -> np.ndarray:
        """|length / rest length - 1| of every flex edge now (0 for an edge of zero rest
        length): about 0.01 at rest, past ``physics.max_hose_strain`` a blow-up."""
        strain = np.abs(self.data.flexedge_length / self._edge_length0 - 1.0)
        strain[self._zero_rest_edges] = 0.0
        return strain

    @property
    def solver_rescues(self) -> int:
        """How often a stretched or sunk hose switched the solver to Newton on a dense
        Jacobian since the last reset (see ``_advance``)."""
        return self._rescues

    @property
    def solver_fallbacks(self) -> int:
        """How often CG stood in for a Newton step that did not converge since the last reset
        (see ``_advance``)."""
        return self._fallbacks

    @property
    def fallback_time(self) -> float:
        """How long (simulated s) CG stands in after a Newton step that did not converge:
        ``physics.fallback_time`` while the scene settles (:meth:`settling`),
        ``physics.run_fallback_time`` (where set) in every other step."""
        p = self.cfg.physics
        if self._settling or p.run_fallback_time is None:
            return p.fallback_time
        return p.run_fallback_time

    @contextmanager
    def settling(self) -> Iterator[None]:
        """The steps inside settle the scene (``settle_world``): see :attr:`fallback_time`."""
        self._settling = True
        try:
            yield
        finally:
            self._settling = False

    @contextmanager
    def transit(self) -> Iterator[None]:
        """Steps inside the block run with MuJoCo's sleeping islands on, with
        ``physics.transit_sleep`` as the tolerance (``SimPanda``'s motions in a
        :meth:`~cablesim.robot.base.Robot.transit`, holding nothing): a
        hose whose every vertex stays slower than that for 10 steps rests there and costs no
        collision or constraint solving; the hand, an awake hose or an applied force touching
        it wakes its island (the hose and what touches it).  Leaving the block turns sleep off
        again, and MuJoCo wakes every tree at the next step, each with the velocity it slept
        with (zero).  Nothing changes where ``transit_sleep`` is 0 or sleep is on throughout
        (``physics.sleep_tolerance`` > 0)."""
        m = self.model
        flag = int(mujoco.mjtEnableBit.mjENBL_SLEEP)
        tolerance = self.cfg.physics.transit_sleep
        if tolerance <= 0 or m.opt.enableflags & flag:
            yield
            return
        before = m.opt.sleep_tolerance
        m.opt.sleep_tolerance = tolerance
        m.opt.enableflags |= flag
        try:
            yield
        finally:
            m.opt.enableflags &= ~flag
            m.opt.sleep_tolerance = before

    @contextmanager
    def hooks(
        self, before: Sequence[StepHook] = (), after: Sequence[StepHook] = ()
    ) -> Iterator[World]:
        """Run ``before``/``after`` hooks around every physics step inside the block."""
        self.before_step.extend(before)
        self.after_step.extend(after)
        try:
            yield self
        finally:
            for hook in before:
                self.before_step.remove(hook)
            for hook in after:
                self.after_step.remove(hook)

    def check_diverged(self, strain: np.ndarray | None = None) -> None:
        """Raise ``PhysicsDivergedError`` where the last step blew up.  ``strain``: the hose
        edge strain of the current state where the caller has it (``hose_stretch``)."""
        d = self.data
        counts = d.warning.number[_WARNING_INDEX]
        bad = counts > self._warn_counts
        self._warn_counts = counts
        if bad.any() or not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            names = [w.name for w, b in zip(_WARNINGS, bad, strict=True) if b]
            raise PhysicsDivergedError(
                f"physics diverged at t={d.time:.3f}s "
                f"({', '.join(names) or 'non-finite state'}); try a smaller physics.timestep "
                f"(now {self.model.opt.timestep}) or stiffer hose contacts"
            )
        if len(self._edge_length0):
            strain = self.hose_stretch() if strain is None else strain
            k = int(np.argmax(strain))
            if strain[k] > self.cfg.physics.max_hose_strain:
                m = self.model
                flex = int(np.searchsorted(m.flex_edgeadr, k, side="right") - 1)
                raise PhysicsDivergedError(
                    f"physics diverged at t={d.time:.3f}s: hose {flex} edge "
                    f"{k - int(m.flex_edgeadr[flex])} stretched {strain[k]:.0%} (limit "
                    f"physics.max_hose_strain {self.cfg.physics.max_hose_strain:g}; its "
                    "edges stretch by 1 % at rest, up to ~16 % pulled taut by the gripper)"
                )

    # ------------------------------------------------------------------ state
    def get_state(self) -> np.ndarray:
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.empty(mujoco.mj_stateSize(self.model, spec))
        mujoco.mj_getState(self.model, self.data, state, spec)
        return state

    def set_state(self, state: np.ndarray) -> None:
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        if state.shape != (mujoco.mj_stateSize(self.model, spec),):
            raise ValueError(
                f"state has shape {state.shape}, the model needs "
                f"({mujoco.mj_stateSize(self.model, spec)},)"
            )
        if self.model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP:
            # which trees sleep is not part of MuJoCo's state vector: start every restored
            # state with all of them awake, as in a fresh MjData, so that a state gives the
            # same steps whether it was just settled, loaded from the cache or reset to
            # (writing ``data.tree_asleep`` directly leaves MuJoCo's awake lists stale)
            mujoco.mj_resetData(self.model, self.data)
        mujoco.mj_setState(self.model, self.data, state, spec)
        mujoco.mj_forward(self.model, self.data)
        self._remember_depth()

    def reset(self) -> None:
        """Back to the settled state (bit for bit)."""
        self.model.opt.solver, self.model.opt.jacobian = self._solver, self._jacobian
        self._fallback_steps = self._fallbacks = 0
        self._rescue_steps = self._rescues = 0
        if self._settled_state is None:
            self._set_start_shapes()
            self._remember_depth()
        else:
            self.set_state(self._settled_state)
        self._warn_counts = self.data.warning.number[_WARNING_INDEX]

    # ------------------------------------------------------------------ hoses
    def hose_vertices(self, i: int) -> np.ndarray:
        h = self.hoses[i]
        return self.data.flexvert_xpos[h.vert_adr : h.vert_adr + h.n_vertices].copy()

    def all_hose_vertices(self) -> np.ndarray:
        return np.concatenate([self.hose_vertices(i) for i in range(len(self.hoses))])

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        T = self.T_world_camera
        return (np.asarray(points) - T[:3, 3]) @ T[:3, :3]

    def camera_to_world(self, points: np.ndarray) -> np.ndarray:
        T = self.T_world_camera
        return np.asarray(points) @ T[:3, :3].T + T[:3, 3]
