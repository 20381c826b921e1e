"""The simulated Panda: IK on an arm-only model, joint position control in the scene.

A Cartesian move is planned first (IK along the straight line, every waypoint checked for joint
limits and collisions on the arm-only model with the static obstacles) and executed only if the
plan is valid; execution streams interpolated joint targets to the position actuators with a
minimum-jerk time law, watches the scene's contacts between robot and static geoms, and then
waits for the TCP to settle.  Nothing here raises for an unreachable target or a collision: a
plan the arm model refuses is ``MoveResult(False, reason, outcome=Outcome.UNREACHABLE)``, a motion
stopped on a robot/static contact (or ending off its target on one) ``Outcome.COLLISION``.

Grasping: ``grasp_mode="friction"`` (default) closes the real finger joints on the hose and
relies on pad friction.  ``grasp_mode="equality"`` is an explicitly chosen fallback that also
switches on a ``connect`` equality between the hand and the nearest flex vertex body (looser:
a few mm of lag); it is not the default because it is not how the real robot holds a hose.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass
from typing import Literal, Protocol

import mujoco
import numpy as np

from cablesim.errors import ConfigError
from cablesim.outcomes import Outcome
from cablesim.panda.description import JOINT_LIMITS, JOINT_VELOCITY_LIMITS, MAX_OPENING
from cablesim.panda.ik import ArmModel, ArmModelChecks, Obstacle, static_obstacles
from cablesim.panda.model import (
    PandaNames,
    joint_qpos_addresses,
    robot_body_ids,
    set_grasp_force,
)
from cablesim.pose import Pose
from cablesim.robot.base import MoveResult, Robot

#: Velocity feed-forward through the position target: kv / kp of the joint actuators.
_KV_OVER_KP = 0.1
#: The Franka Hand's top speed (m/s of opening; frankx ``Gripper.max_speed``): the gripper's
#: force limit (``SimPanda._limit_gripper_force``) lets the servo make up its damping up to it.
GRIPPER_MAX_SPEED = 0.1
#: The share of the grasp force the force limit keeps below the actuator's clamp.
_FORCE_MARGIN = 1e-3


class SimWorld(Protocol):
    """What :class:`SimPanda` needs from the simulated world.  A world that also has
    ``hoses`` (each with ``spec.radius``) and ``hose_vertices(i)`` (``cablesim.sim.world.World``) gets
    its hoses planned around (``SimPandaConfig.avoid_hoses``)."""

    model: mujoco.MjModel
    data: mujoco.MjData
    T_world_camera: np.ndarray
    panda: PandaNames
    panda_base: tuple[Sequence[float], Sequence[float]]

    def step(self, n: int = 1) -> None: ...


@dataclass
class SimPandaConfig:
    """Tolerances and limits of the simulated controller."""

    position_tolerance: float = 0.002  # m, TCP to target after settling
    rotation_tolerance: float = 0.02  # rad
    waypoint_spacing: float = 0.005  # m between IK waypoints on a line
    waypoint_angle: float = 0.05  # rad between IK waypoints
    max_joint_jump: float = 0.25  # rad between consecutive waypoints (else: IK branch switch)
    settle_time: float = 0.6  # s allowed after the trajectory to reach tolerance
    collision_depth: float = 0.002  # m of robot/static penetration that aborts a motion
    grasp_timeout: float = 1.5  # s
    grasp_vertex_distance: float = 0.03  # m, equality mode: max TCP to vertex distance
    grasp_mode: Literal["friction", "equality"] = "friction"
    # plan the joint motions of links 0-6 around the hoses while approaching a grasp or push,
    # ``hose_clearance`` m from their surface (see SimPanda._update_obstacles); a motion being
    # executed may go ``hose_slack`` m deeper (the hoses moved a little since it was planned;
    # a graze does no harm: the blow-ups came from links 30-50 mm inside a hose)
    avoid_hoses: bool = True
    hose_clearance: float = 0.0
    hose_slack: float = 0.003

    def __post_init__(self) -> None:
        if self.grasp_mode not in ("friction", "equality"):
            raise ConfigError(
                "grasp_mode", f"must be 'friction' or 'equality', got {self.grasp_mode!r}"
            )
        for name in ("position_tolerance", "waypoint_spacing", "settle_time", "grasp_timeout"):
            if getattr(self, name) <= 0:
                raise ConfigError(name, "must be > 0")
        for name in ("hose_clearance", "hose_slack"):
            if not 0 <= getattr(self, name) <= 0.1:
                raise ConfigError(name, f"must be in [0, 0.1] m, got {getattr(self, name)}")


def _interpolate(plan: np.ndarray, s: float, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint target and velocity at normalised time ``s`` along piecewise-linear ``plan``."""
    n_seg = len(plan) - 1
    u = min_jerk(s) * n_seg
    i = min(int(u), n_seg - 1)
    seg = plan[i + 1] - plan[i]
    du_dt = _min_jerk_rate(s) * n_seg / duration
    return plan[i] + (u - i) * seg, seg * du_dt


def _min_jerk_rate(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return 30.0 * s * s * (1.0 - s) * (1.0 - s)


def min_jerk(s: float) -> float:
    """Minimum-jerk time law on [0, 1]; peak rate 1.875."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


class SimPanda(ArmModelChecks, Robot):
    """The :class:`Robot` interface on a Panda attached to a simulated world."""

    def __init__(
        self,
        world: SimWorld,
        config: SimPandaConfig | None = None,
        obstacles: Sequence[Obstacle] | None = None,
    ):
        self.world = world
        self.config = config or SimPandaConfig()
        self.names = world.panda
        m, d = world.model, world.data
        n = self.names
        self.T_world_camera = np.asarray(world.T_world_camera, dtype=float)
        self._qadr = joint_qpos_addresses(m, n.joints)
        self._dofadr = np.asarray([m.jnt_dofadr[m.joint(j).id] for j in n.joints])
        self._finger_qadr = joint_qpos_addresses(m, n.finger_joints)
        self._finger_dofadr = np.asarray([m.jnt_dofadr[m.joint(j).id] for j in n.finger_joints])
        self._act = np.asarray([m.actuator(a).id for a in n.actuators])
        self._gripper = m.actuator(n.gripper_actuator).id
        self._site = m.site(n.site).id
        self._hand = m.body(n.hand_body).id
        self._eq = m.equality(n.grasp_equality).id
        self._pad_geoms = {m.geom(g).id for g in n.finger_geoms}
        robot_bodies = robot_body_ids(m, n.prefix)
        self._robot_geom = np.isin(m.geom_bodyid, robot_bodies)
        mujoco.mj_forward(m, d)
        if obstacles is None:
            obstacles = static_obstacles(m, d, exclude_bodies=robot_bodies)
        self._static_geom = np.zeros(m.ngeom, dtype=bool)
        for g in range(m.ngeom):
            self._static_geom[g] = (not self._robot_geom[g]) and m.body_weldid[
                m.geom_bodyid[g]
            ] == 0
        base_pos, base_quat = world.panda_base
        capsules: list[float] = []  # half rest length of every hose edge
        radii: list[float] = []  # and the radius of its cable, with the clearance
        hoses = getattr(world, "hoses", ()) if self.config.avoid_hoses else ()
        for h in hoses:
            capsules += [0.5 * h.spec.length / (h.n_vertices - 1)] * (h.n_vertices - 1)
            radii += [h.spec.radius + self.config.hose_clearance] * (h.n_vertices - 1)
        self.arm = ArmModel(
            base_pos, base_quat, obstacles, hose_capsules=capsules, hose_radius=radii
        )
        self._closed = False  # the fingers were closed (grasp) and not opened since
        self._transits = 0  # open transit() blocks
        self._grip_kp = float(m.actuator_gainprm[self._gripper, 0])
        self._grip_kv = -float(m.actuator_biasprm[self._gripper, 2])
        self._grip_command = float(d.ctrl[self._gripper])  # what the gripper was told
        self._grip_written = self._grip_command  # what the force limit last left in ctrl
        controllers = getattr(world, "controllers", None)
        if controllers is not None:  # the latest robot on a world drives its gripper
            controllers["gripper"] = self._limit_gripper_force
        self._vertex_bodies = np.unique(m.flex_vertbodyid[m.flex_vertbodyid > 0])
        self.last_plan: list[np.ndarray] = []

    # ---- state -------------------------------------------------------------------------------
    @property
    def joint_positions(self) -> np.ndarray:
        return self.world.data.qpos[self._qadr].copy()

    @property
    def gripper_opening(self) -> float:
        return float(np.sum(self.world.data.qpos[self._finger_qadr]))

    def ee_pose(self) -> Pose:
        d = self.world.data
        return Pose.from_rotation(d.site_xpos[self._site], d.site_xmat[self._site].reshape(3, 3))

    @property
    def dt(self) -> float:
        return float(self.world.model.opt.timestep)

    # ---- planning ----------------------------------------------------------------------------
    def _update_obstacles(self) -> None:
        """The hoses as they are now become obstacles for the arm links in the arm model
        (``config.avoid_hoses``), while the gripper is open: a joint motion planned against the
        board alone swept link6 through a hose and crushed it until the physics tore it apart
        (seeds 6062, 6077).  Holding a hose, the arm drags it wherever it goes: no hose
        obstacles then."""
        if not self.arm.hose_capacity:
            return
        if self._closed:
            self.arm.set_hoses()
            return
        w = self.world
        self.arm.set_hoses([w.hose_vertices(i) for i in range(len(w.hoses))])

    @contextmanager
    def _executing(self) -> Iterator[None]:
        """Checking the joint motion about to be executed: the hoses as they are now, and a
        link may come through the clearance and ``hose_slack`` into a hose, since the hoses
        have moved a little since the motion was planned ahead."""
        self._update_obstacles()
        self.arm.hose_slack = self.config.hose_clearance + self.config.hose_slack
        try:
            yield
        finally:
            self.arm.hose_slack = 0.0

    def plan_line(self, target: Pose) -> tuple[list[np.ndarray], str]:
        """Joint waypoints along the straight TCP line to ``target``; empty list + reason on failure."""
        cfg = self.config
        return self.arm.plan_line(
            self.ee_pose(),
            self.joint_positions,
            target,
            self.gripper_opening,
            cfg.waypoint_spacing,
            cfg.waypoint_angle,
            cfg.max_joint_jump,
        )

    # ---- motion ------------------------------------------------------------------------------
    def move_to(self, pose: Pose, speed: float = 0.1, angular_speed: float = 0.8) -> MoveResult:
        if speed <= 0 or angular_speed <= 0:
            return MoveResult(False, "speed must be > 0")
        plan, reason = self.plan_line(pose)  # straight lines do not see the hoses (ArmModel)
        if not plan:
            return MoveResult(False, reason, self._pos_error(pose), outcome=Outcome.UNREACHABLE)
        dist, angle = self.ee_pose().distance_to(pose)
        duration = max(1.875 * dist / speed, 1.875 * angle / angular_speed, 0.02)
        self.last_plan = plan
        with self._resting():
            return self._execute(np.asarray(plan), duration, pose)

    def move_joints(self, q: np.ndarray, speed_factor: float = 0.3) -> MoveResult:
        q = np.asarray(q, dtype=float).reshape(7)
        if not 0 < speed_factor <= 1:
            return MoveResult(False, f"speed_factor must be in (0, 1], got {speed_factor}")
        q0 = self.joint_positions
        with self._executing():
            problem = self.arm.check_joint_path(q0, q, self.gripper_opening)
        if problem:
            return MoveResult(False, problem, outcome=Outcome.UNREACHABLE)
        n = max(1, math.ceil(np.max(np.abs(q - q0)) / 0.05))
        plan = [q0 + (q - q0) * i / n for i in range(n + 1)]
        duration = max(
            1.875 * float(np.max(np.abs(q - q0) / (JOINT_VELOCITY_LIMITS * speed_factor))), 0.02
        )
        with self._resting():
            return self._execute(np.asarray(plan), duration, self.arm.fk(q))

    @contextmanager
    def transit(self) -> Iterator[None]:
        """See :meth:`Robot.transit`: each motion inside runs in the world's
        :meth:`~cablesim.sim.world.World.transit` (the hoses it does not touch rest,
        ``physics.transit_sleep``) unless the hand is closed on something (after
        :meth:`grasp`, until :meth:`open`)."""
        self._transits += 1
        try:
            yield
        finally:
            self._transits -= 1

    def _resting(self) -> AbstractContextManager[None]:
        """The world's transit for a motion inside :meth:`transit` with nothing grasped;
        everything awake otherwise (and on a world without ``transit``)."""
        transit = getattr(self.world, "transit", None)
        if self._transits == 0 or self._closed or transit is None:
            return nullcontext()
        return transit()

    def _execute(self, plan: np.ndarray, duration: float, target: Pose) -> MoveResult:
        cfg, w = self.config, self.world
        d = w.data
        dt = self.dt
        steps = max(1, math.ceil(duration / dt))
        t = 0.0
        for k in range(1, steps + 1):
            q_des, qd_des = _interpolate(plan, k / steps, duration)
            d.ctrl[self._act] = q_des + _KV_OVER_KP * qd_des
            w.step(1)
            t += dt
            if k % 5 == 0:
                hit = self._static_collision()
                if hit:
                    d.ctrl[self._act] = self.joint_positions  # stop where we are
                    return MoveResult(
                        False,
                        f"collision in scene: {hit}",
                        self._pos_error(target),
                        t,
                        Outcome.COLLISION,
                    )
        d.ctrl[self._act] = plan[-1]
        for _ in range(max(1, math.ceil(cfg.settle_time / dt))):
            if np.abs(d.qvel[self._dofadr]).max() < 2e-3:
                break
            w.step(1)
            t += dt
        pos_err, rot_err = self.ee_pose().distance_to(target)
        if pos_err < cfg.position_tolerance and rot_err < cfg.rotation_tolerance:
            return MoveResult(True, "", pos_err, t)
        hit = self._static_collision()
        return MoveResult(
            False,
            f"target not reached within tolerance (error "
            f"{pos_err * 1000:.1f} mm, {math.degrees(rot_err):.1f} deg)"
            + (f"; contact: {hit}" if hit else ""),
            pos_err,
            t,
            Outcome.COLLISION if hit else None,
        )

    def _static_collision(self) -> str:
        """Name pair of a robot/static-geom contact deeper than the configured depth, or ''."""
        m, d = self.world.model, self.world.data
        if d.ncon == 0:
            return ""
        contacts = d.contact
        geom, dist = contacts.geom, contacts.dist
        g1, g2 = geom[:, 0], geom[:, 1]
        deep = (g1 >= 0) & (g2 >= 0) & (dist <= -self.config.collision_depth)
        if not deep.any():
            return ""
        a, b = np.maximum(g1, 0), np.maximum(g2, 0)
        hit = deep & (
            (self._robot_geom[a] & self._static_geom[b])
            | (self._robot_geom[b] & self._static_geom[a])
        )
        if not hit.any():
            return ""
        i = int(np.argmax(hit))
        return f"{m.geom(int(g1[i])).name} with {m.geom(int(g2[i])).name}"

    def _pos_error(self, target: Pose) -> float:
        return float(np.linalg.norm(self.ee_pose().position - target.position))

    # ---- gripper -----------------------------------------------------------------------------
    def open(self, width: float = MAX_OPENING, speed: float = 0.1) -> bool:
        self._closed = False
        self._set_equality(False)
        width = float(np.clip(width, 0.0, MAX_OPENING))
        self._drive_gripper(width, speed)
        return abs(self.gripper_opening - width) < 0.005

    def grasp(
        self,
        width: float = 0.015,
        force: float = 70.0,
        speed: float = 0.05,
        epsilon_inner: float = 0.01,
        epsilon_outer: float = 0.01,
    ) -> bool:
        set_grasp_force(self.world.model, self.names, force)
        self._closed = True
        self._drive_gripper(0.0, speed)
        opening = self.gripper_opening
        # fingers closed to under 2 mm hold nothing, unless both pads press on a cable: a
        # 2 mm wire is squeezed to about 0.5 mm by the soft contacts of its light vertices
        # (0.2 g each, against 70 N), where the width window alone would accept an empty hand
        held = width - epsilon_inner <= opening <= width + epsilon_outer and (
            opening > 0.002 or self._pads_on_cable()
        )
        if held and self.config.grasp_mode == "equality":
            held = self._attach_nearest_vertex()
        return bool(held)

    def _pads_on_cable(self) -> bool:
        """Whether both finger pads touch a cable (a flex) now."""
        d = self.world.data
        touched = set()
        for i in range(d.ncon):
            c = d.contact[i]
            if c.flex[0] >= 0 or c.flex[1] >= 0:
                touched.update(int(g) for g in c.geom if g in self._pad_geoms)
        return len(touched) == 2

    def _gripper_command(self) -> float:
        """The gripper's command (m): ``ctrl`` as last set, not as the force limit left it."""
        c = float(self.world.data.ctrl[self._gripper])
        return self._grip_command if c == self._grip_written else c

    def _limit_gripper_force(self, world: SimWorld) -> None:
        """The gripper's firmware, run at the start of every physics step: the command never
        asks for more than the grasp force, i.e. it stays within ``force / kp`` (14 mm at 70 N)
        of the opening, plus what the damping takes at the closing speed up to
        :data:`GRIPPER_MAX_SPEED`.  The position servo's force then does not reach its clamp
        (``forcerange``) while the fingers close, MuJoCo keeps integrating the gripper's
        damping implicitly, and fingers that close faster than the hand can are braked.  A
        clamped force has no velocity derivative: fingers held 15 mm apart by a cable that then
        leaves them were driven at 70 N with no damping for a step, 7.7 m/s in 4 ms, and passed
        through each other (-13.9 mm, table garden hose seed 14216; docs/cables.md).  A command
        within that reach of the opening is left as it is, bit for bit."""
        d = world.data
        g = self._gripper
        self._grip_command = self._gripper_command()
        closing = -float(d.qvel[self._finger_dofadr[0]] + d.qvel[self._finger_dofadr[1]])
        # the force (a hair inside the clamp, where MuJoCo would drop the damping's derivative
        # again), plus what the damping takes at the closing speed up to the hand's top speed:
        # a weak grasp still closes as fast as commanded, faster fingers are braked
        force = -float(world.model.actuator_forcerange[g, 0]) * (1.0 - _FORCE_MARGIN)
        push = max(0.0, force + self._grip_kv * min(closing, GRIPPER_MAX_SPEED))
        ctrl = max(self._grip_command, self.gripper_opening - push / self._grip_kp)
        d.ctrl[g] = ctrl
        self._grip_written = ctrl

    def _drive_gripper(self, target: float, speed: float) -> None:
        """Ramp the gripper command at ``speed`` (m/s), then wait until the fingers stop."""
        w, d = self.world, self.world.data
        dt = self.dt
        start = self._gripper_command()
        ramp = max(1, math.ceil(abs(target - start) / max(speed, 1e-3) / dt))
        for k in range(1, ramp + 1):
            d.ctrl[self._gripper] = start + (target - start) * k / ramp
            w.step(1)
        still = 0
        for _ in range(math.ceil(self.config.grasp_timeout / dt)):
            w.step(1)
            v = np.abs(d.qvel[self._finger_dofadr]).max()
            still = still + 1 if v < 1e-3 else 0
            if still >= 20:
                break

    def _set_equality(self, active: bool) -> None:
        self.world.data.eq_active[self._eq] = int(active)

    def _attach_nearest_vertex(self) -> bool:
        m, d = self.world.model, self.world.data
        if len(self._vertex_bodies) == 0:
            return False
        tcp = d.site_xpos[self._site]
        dists = np.linalg.norm(d.xpos[self._vertex_bodies] - tcp, axis=1)
        j = int(np.argmin(dists))
        if dists[j] > self.config.grasp_vertex_distance:
            return False
        body = int(self._vertex_bodies[j])
        hand_R = d.xmat[self._hand].reshape(3, 3)
        anchor_in_hand = hand_R.T @ (d.xpos[body] - d.xpos[self._hand])
        m.eq_obj2id[self._eq] = body
        m.eq_data[self._eq, 0:3] = anchor_in_hand
        m.eq_data[self._eq, 3:6] = 0.0
        self._set_equality(True)
        return True

    # ---- limits for callers ------------------------------------------------------------------
    @staticmethod
    def joint_limits() -> np.ndarray:
        return JOINT_LIMITS.copy()
