"""Inverse kinematics and collision checks on an arm-only model (mink differential IK).

The full scene (hoses with hundreds of dofs) is ~100x slower per IK iteration, so IK runs on a
small model: the Panda at the scene's base pose plus the static obstacles (table, board,
connectors) copied in as primitive geoms.  Checking a configuration never touches the scene.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, replace

import mink
import mujoco
import numpy as np

from cablesim.panda.description import FORWARD_QPOS, HOME_QPOS, JOINT_LIMITS, MAX_OPENING
from cablesim.panda.model import PandaNames, attach_panda, joint_qpos_addresses, robot_body_ids
from cablesim.pose import Pose

_Q_LO, _Q_HI = np.asarray(JOINT_LIMITS, dtype=float).T  # arm joint limits, for clipping
_HOSE_BIT = 4  # contype of the hose capsules; only the arm links have it in their conaffinity
_PARKED = (0.0, 0.0, -10.0)  # where unused hose capsules wait, far below the table

_PRIMITIVES = (
    mujoco.mjtGeom.mjGEOM_PLANE,
    mujoco.mjtGeom.mjGEOM_SPHERE,
    mujoco.mjtGeom.mjGEOM_CAPSULE,
    mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    mujoco.mjtGeom.mjGEOM_CYLINDER,
    mujoco.mjtGeom.mjGEOM_BOX,
)


@dataclass(frozen=True)
class Obstacle:
    """A static primitive geom in world coordinates (MuJoCo type, size, pos, quat wxyz)."""

    name: str
    geom_type: int
    size: tuple[float, float, float]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    # the source geom's collision bits (the table scene's mat and table top let the finger
    # pads in: cablesim.panda.model.PAD_CONTYPE)
    contype: int = 1
    conaffinity: int = 1

    @staticmethod
    def box(
        name: str,
        pos: Sequence[float],
        half_size: Sequence[float],
        quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    ) -> Obstacle:
        return Obstacle(
            name, int(mujoco.mjtGeom.mjGEOM_BOX), tuple(half_size), tuple(pos), tuple(quat)
        )


def static_obstacles(
    model: mujoco.MjModel, data: mujoco.MjData, exclude_bodies: Sequence[int] = ()
) -> list[Obstacle]:
    """Geoms fixed to the world: the colliding primitives (table, board) and the meshes
    (connectors and hose couplings, which are visual in the scene but solid on a real board).

    Planes become thin boxes, meshes their bounding boxes.  ``data`` must have current
    kinematics (after mj_forward).
    """
    excluded = set(int(b) for b in exclude_bodies)
    out: list[Obstacle] = []
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        if body in excluded or model.body_weldid[body] != 0:
            continue
        gtype = int(model.geom_type[g])
        if gtype == mujoco.mjtGeom.mjGEOM_MESH:
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, data.geom_xmat[g])
            aabb = model.geom_aabb[g]
            centre = data.geom_xpos[g] + data.geom_xmat[g].reshape(3, 3) @ aabb[:3]
            name = model.geom(g).name or f"geom{g}"
            out.append(Obstacle.box(name, tuple(centre), tuple(aabb[3:]), tuple(quat)))
            continue
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        if gtype not in _PRIMITIVES:
            continue
        size = tuple(float(s) for s in model.geom_size[g])
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, data.geom_xmat[g])
        pos = data.geom_xpos[g].copy()
        if gtype == mujoco.mjtGeom.mjGEOM_PLANE:
            half = 0.01
            sx = size[0] if size[0] > 0 else 5.0
            sy = size[1] if size[1] > 0 else 5.0
            normal = data.geom_xmat[g].reshape(3, 3)[:, 2]
            pos = pos - half * normal
            gtype, size = int(mujoco.mjtGeom.mjGEOM_BOX), (sx, sy, half)
        name = model.geom(g).name or f"geom{g}"
        bits = int(model.geom_contype[g]), int(model.geom_conaffinity[g])
        out.append(Obstacle(name, gtype, size, tuple(pos), tuple(quat), *bits))
    return out


#: how many distinct IK problems an :class:`ArmModel` remembers the answers to
IK_MEMO_SIZE = 4096


@dataclass(frozen=True)
class IKResult:
    q: np.ndarray  # (7,) arm joints
    converged: bool
    position_error: float
    rotation_error: float
    iterations: int


class ArmModel:
    """The arm alone (at the scene's base pose) with static obstacles, for IK and checks."""

    def __init__(
        self,
        base_pos: Sequence[float] = (0.0, 0.0, 0.0),
        base_quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
        obstacles: Sequence[Obstacle] = (),
        position_tolerance: float = 5e-4,
        rotation_tolerance: float = 5e-3,
        max_iterations: int = 60,
        hose_capsules: Sequence[float] = (),
        hose_radius: float | Sequence[float] = 0.01,
    ):
        spec = mujoco.MjSpec()
        self.base = Pose(np.asarray(base_pos, dtype=float), np.asarray(base_quat, dtype=float))
        self.names: PandaNames = attach_panda(spec, base_pos, base_quat, prefix="arm/")
        for ob in obstacles:
            g = spec.worldbody.add_geom(
                name=f"obstacle/{ob.name}",
                type=ob.geom_type,
                size=list(ob.size),
                pos=list(ob.pos),
                quat=list(ob.quat),
            )
            g.contype, g.conaffinity, g.group = ob.contype, ob.conaffinity, 3
        self.obstacle_names = tuple(ob.name for ob in obstacles)
        # movable capsules for the hoses (set_hoses), each on a mocap body (the world body's
        # bounding volumes are computed once, at compile time): only the arm links collide
        radii = np.broadcast_to(np.asarray(hose_radius, dtype=float), (len(hose_capsules),))
        for k, half in enumerate(hose_capsules):
            body = spec.worldbody.add_body(name=f"hose/{k}", mocap=True, pos=list(_PARKED))
            g = body.add_geom(
                name=f"hose/{k}",
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                size=[float(radii[k]), float(half), 0],
            )
            g.contype, g.conaffinity, g.group = _HOSE_BIT, 0, 3
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.position_tolerance = position_tolerance
        self.rotation_tolerance = rotation_tolerance
        self.max_iterations = max_iterations

        m = self.model
        self._arm_qadr = joint_qpos_addresses(m, self.names.joints)
        self._finger_qadr = joint_qpos_addresses(m, self.names.finger_joints)
        robot = robot_body_ids(m, prefix="arm/")
        self._robot_geoms = np.isin(m.geom_bodyid, robot)
        # Self-collision between robot links at least 3 apart in the chain (neighbours overlap
        # where primitives meet at the joints; the real arm's limits keep them apart anyway).
        chain = {m.body(n).id: i for i, n in enumerate(self.names.bodies)}
        for f in self.names.finger_bodies:
            chain[m.body(f).id] = len(self.names.bodies) - 2
        self._chain = chain
        self._base_body = m.body(self.names.base_body).id
        # Robot-robot pairs generate contacts here (the broadphase filters on body masks too).
        m.geom_conaffinity[self._robot_geoms] = 3
        m.body_conaffinity[robot] |= 2
        # links 0-6 see the hose capsules; link7 (the flange), the hand and the fingers do not:
        # they reach in among the hoses to grasp, and brush the hoses that hang out in front
        # on the way (measured: link7 within 6 mm of a hose on the approach line of seed 2);
        # link6 is the one that swept through hoses and tore them (seeds 6062, 6077)
        links = [m.body(n).id for n in self.names.bodies[:7]]
        self._link_geoms = np.isin(m.geom_bodyid, links)
        m.geom_conaffinity[self._link_geoms] |= _HOSE_BIT
        m.body_conaffinity[links] |= _HOSE_BIT
        self._hose_geoms = np.array([m.geom(f"hose/{k}").id for k in range(len(hose_capsules))])
        self._hose_mocap = np.array(
            [m.body_mocapid[m.body(f"hose/{k}").id] for k in range(len(hose_capsules))], int
        )
        self._hose_of_geom = np.full(m.ngeom, -1)
        # the hose capsules count only while this is set (cablesim.robot.grasping.avoiding_hoses:
        # the approach to a grasp or push; retreats and parking may brush a hose)
        self.avoid_hoses = False
        # m of a hose capsule's radius a link may enter without it counting: 0 when planning
        # ahead; the simulated arm executing a motion sets its clearance and slack (the hoses
        # move a little between the plan and the motion)
        self.hose_slack = 0.0

        self.configuration = mink.Configuration(m)
        self.frame_task = mink.FrameTask(
            self.names.site, "site", position_cost=1.0, orientation_cost=0.5, lm_damping=1e-4
        )
        self.posture_task = mink.PostureTask(m, cost=1e-3)
        self.limits = [mink.ConfigurationLimit(m, gain=0.5)]
        # solve() is a pure function of its inputs (the hose capsules and obstacles only enter
        # the checks), and planning asks the same question often (the start-segment picker's
        # dry runs: 1131 solves of 805 distinct problems for seed 2), so answers are kept
        self._solved: OrderedDict[bytes, IKResult] = OrderedDict()
        self.solve_calls = 0  # solve() calls, and how many were answered from the memo
        self.solve_hits = 0

    # ---- hoses ---------------------------------------------------------------------------
    @property
    def hose_capacity(self) -> int:
        """How many hose segments :meth:`set_hoses` can take."""
        return len(self._hose_mocap)

    def set_hoses(self, polylines: Sequence[np.ndarray] = ()) -> None:
        """Make the hoses obstacles for arm links 0-6: the segments of the polylines (V, 3), in
        world coordinates and in order, take the capsules given at construction (their radius
        and half-lengths: the hoses' rest geometry), each centred on its segment and along it.
        Link7, the hand and the fingers do not see them (they reach in among the hoses).  No
        polylines: no hose obstacles.  They count only in joint paths
        (:meth:`check_joint_path`: the fast free motions, where a link sweeping through a hose
        crushes it) and only while ``avoid_hoses`` is set; a straight TCP line (the slow
        approach into the hoses) and a single configuration do not see them.

        A joint path that starts with a link already touching a hose is not failed for that
        link and hose (it may be moving away); any other link-hose contact fails it."""
        d = self.data
        starts = [np.asarray(p, dtype=float)[:-1] for p in polylines]
        ends = [np.asarray(p, dtype=float)[1:] for p in polylines]
        n = sum(len(a) for a in starts)
        if n > len(self._hose_mocap):
            raise ValueError(f"{n} hose segments, the arm model holds {len(self._hose_mocap)}")
        d.mocap_pos[self._hose_mocap] = _PARKED
        d.mocap_quat[self._hose_mocap] = (1.0, 0.0, 0.0, 0.0)
        self._hose_of_geom[:] = -1
        if n:
            a, b = np.concatenate(starts), np.concatenate(ends)
            seg = b - a
            u = seg / np.maximum(np.linalg.norm(seg, axis=1), 1e-12)[:, None]
            # the rotation taking z to u: axis z x u, w = 1 + z.u (z -> -z: about x)
            quat = np.stack([1.0 + u[:, 2], -u[:, 1], u[:, 0], np.zeros(n)], axis=1)
            quat[quat[:, 0] < 1e-9] = (0.0, 1.0, 0.0, 0.0)
            quat /= np.linalg.norm(quat, axis=1)[:, None]
            d.mocap_pos[self._hose_mocap[:n]] = 0.5 * (a + b)
            d.mocap_quat[self._hose_mocap[:n]] = quat
            owner = [np.full(len(x), h) for h, x in enumerate(starts)]
            self._hose_of_geom[self._hose_geoms[:n]] = np.concatenate(owner)

    def _contacts(
        self, q: np.ndarray, opening: float, min_distance: float
    ) -> list[tuple[int, int, float]]:
        """(geom, geom, distance) of the geom-geom contacts at ``q`` closer than
        ``min_distance``."""
        m, d = self.model, self.data
        self.set_q(q, opening)
        mujoco.mj_collision(m, d)
        out = []
        for c in d.contact[: d.ncon]:
            g1, g2 = int(c.geom[0]), int(c.geom[1])
            if g1 >= 0 and g2 >= 0 and c.dist < min_distance:
                out.append((g1, g2, float(c.dist)))
        return out

    def _hose_contacts(self, q: np.ndarray, opening: float) -> set[tuple[int, int]]:
        """(link geom, hose) pairs in contact at ``q``."""
        if not self.avoid_hoses or not (self._hose_of_geom >= 0).any():
            return set()
        out = set()
        for g1, g2, _ in self._contacts(q, opening, 0.0):
            if self._hose_of_geom[g2] >= 0:
                out.add((g1, int(self._hose_of_geom[g2])))
            elif self._hose_of_geom[g1] >= 0:
                out.add((g2, int(self._hose_of_geom[g1])))
        return out

    # ---- kinematics --------------------------------------------------------------------------
    def set_q(self, q: np.ndarray, opening: float | None = None) -> None:
        self.data.qpos[self._arm_qadr] = q
        if opening is not None:
            self.data.qpos[self._finger_qadr] = opening / 2.0
        mujoco.mj_kinematics(self.model, self.data)

    def fk(self, q: np.ndarray) -> Pose:
        """TCP pose for arm joints ``q``."""
        self.set_q(q)
        sid = self.model.site(self.names.site).id
        return Pose.from_rotation(self.data.site_xpos[sid], self.data.site_xmat[sid].reshape(3, 3))

    def solve(
        self,
        target: Pose,
        q_init: np.ndarray,
        q_posture: np.ndarray | None = None,
        opening: float = 0.08,
    ) -> IKResult:
        """Differential IK from ``q_init`` to ``target``; joint limits are respected (a
        ``q_init`` measured a hair outside them, as a real arm's can be, starts clipped).

        The same problem (bit for bit: target, start, posture, opening, tolerances) gets the
        same answer from a memo of the last :data:`IK_MEMO_SIZE` problems, without iterating."""
        self.solve_calls += 1
        q_start = np.clip(np.asarray(q_init, dtype=float).reshape(7), _Q_LO, _Q_HI)
        key = b"".join(
            np.ascontiguousarray(a, dtype=float).tobytes()
            for a in (
                target.position,
                target.quaternion,
                q_start,
                np.full(7, np.nan) if q_posture is None else np.reshape(q_posture, 7),
                (opening, self.position_tolerance, self.rotation_tolerance, self.max_iterations),
            )
        )
        known = self._solved.get(key)
        if known is not None:
            self.solve_hits += 1
            self._solved.move_to_end(key)
            return replace(known, q=known.q.copy())
        result = self._solve(target, q_start, q_posture, opening)
        self._solved[key] = replace(result, q=result.q.copy())
        if len(self._solved) > IK_MEMO_SIZE:
            self._solved.popitem(last=False)
        return result

    def _solve(
        self, target: Pose, q_start: np.ndarray, q_posture: np.ndarray | None, opening: float
    ) -> IKResult:
        qpos = self.data.qpos.copy()
        qpos[self._arm_qadr] = q_start
        qpos[self._finger_qadr] = opening / 2.0
        self.configuration.update(qpos)
        posture = qpos.copy()
        if q_posture is not None:
            posture[self._arm_qadr] = q_posture
        self.posture_task.set_target(posture)
        self.frame_task.set_target(
            mink.SE3.from_rotation_and_translation(
                mink.SO3(np.asarray(target.quaternion)), np.asarray(target.position)
            )
        )
        pos_err = rot_err = np.inf
        it = 0
        for it in range(1, self.max_iterations + 1):
            err = self.frame_task.compute_error(self.configuration)
            pos_err, rot_err = float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))
            if pos_err < self.position_tolerance and rot_err < self.rotation_tolerance:
                it -= 1
                break
            vel = mink.solve_ik(
                self.configuration,
                [self.frame_task, self.posture_task],
                dt=1.0,
                solver="daqp",
                damping=1e-6,
                limits=self.limits,
            )
            self.configuration.integrate_inplace(vel, 1.0)
        else:
            err = self.frame_task.compute_error(self.configuration)
            pos_err, rot_err = float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))
        q = np.clip(self.configuration.q[self._arm_qadr], _Q_LO, _Q_HI)
        converged = pos_err < self.position_tolerance and rot_err < self.rotation_tolerance
        return IKResult(q, converged, pos_err, rot_err, it)

    # ---- checks ------------------------------------------------------------------------------
    def limit_violation(self, q: np.ndarray, margin: float = 1e-4) -> str:
        """Empty if ``q`` is within the joint limits, else which joint is out."""
        for i, (lo, hi) in enumerate(JOINT_LIMITS):
            if not (lo - margin <= q[i] <= hi + margin):
                return f"joint{i + 1} = {q[i]:.3f} outside [{lo:.3f}, {hi:.3f}]"
        return ""

    def collisions(
        self,
        q: np.ndarray,
        opening: float = 0.08,
        min_distance: float = 0.0,
        ignore: set[tuple[int, int]] = frozenset(),  # type: ignore[assignment]
        hoses: bool = False,
    ) -> list[tuple[str, str, float]]:
        """Robot-obstacle and robot self-collision pairs (names, distance) at ``q``; the hose
        capsules count with ``hoses`` (and ``avoid_hoses``), but for the (link geom, hose)
        pairs in ``ignore`` (see :meth:`set_hoses`)."""
        m = self.model
        out = []
        for g1, g2, dist in self._contacts(q, opening, min_distance):
            r1, r2 = self._robot_geoms[g1], self._robot_geoms[g2]
            if r1 and r2:
                b1, b2 = self._chain.get(m.geom_bodyid[g1]), self._chain.get(m.geom_bodyid[g2])
                if b1 is None or b2 is None or abs(b1 - b2) < 3:
                    continue
            elif r1 or r2:
                robot_geom = g1 if r1 else g2
                if m.geom_bodyid[robot_geom] == self._base_body:
                    continue  # the base stands on the table
                hose = int(self._hose_of_geom[g2 if r1 else g1])
                if hose >= 0 and (
                    not (hoses and self.avoid_hoses)
                    or (robot_geom, hose) in ignore
                    or dist > -self.hose_slack
                ):
                    continue
            else:
                continue
            out.append((m.geom(g1).name, m.geom(g2).name, dist))
        return out

    def seeds(self, pose: Pose, current: np.ndarray) -> list[np.ndarray]:
        """IK starts for ``pose``: the forward posture turned (joint 1) towards it, the
        current joints, and home turned towards it."""
        local = self.base.inverse() @ pose
        yaw = float(np.clip(math.atan2(local.position[1], local.position[0]), *JOINT_LIMITS[0]))
        forward, home = FORWARD_QPOS.copy(), HOME_QPOS.copy()
        forward[0] = home[0] = yaw
        return [forward, np.asarray(current, dtype=float), home]

    def reach(
        self, pose: Pose, seeds: Sequence[np.ndarray], opening: float
    ) -> tuple[bool, str, IKResult | None]:
        """The first seed's IK solution within limits and free of collisions, or the reason
        none was found (the closest miss when IK did not converge)."""
        reason = "IK did not converge"
        best: IKResult | None = None
        for seed in seeds:
            seed = np.asarray(seed, dtype=float)
            r = self.solve(pose, seed, seed, opening)
            if not r.converged:
                if best is None or r.position_error < best.position_error:
                    best = r
                    reason = (
                        f"IK did not converge (position error {r.position_error * 1000:.1f}"
                        f" mm, rotation error {math.degrees(r.rotation_error):.1f} deg)"
                    )
                continue
            problem = self.check(r.q, opening)
            if not problem:
                return True, "", r
            reason = problem
        return False, reason, None

    def plan_line(
        self,
        start: Pose,
        q_start: np.ndarray,
        target: Pose,
        opening: float,
        spacing: float = 0.005,
        angle_step: float = 0.05,
        max_joint_jump: float = 0.25,
    ) -> tuple[list[np.ndarray], str]:
        """Joint waypoints of the straight TCP line from ``start`` (at joints ``q_start``) to
        ``target``: IK every ``spacing`` m / ``angle_step`` rad, each within limits, free of
        collisions and without a branch jump.  ([q_start, ...], "") or ([], reason)."""
        dist, angle = start.distance_to(target)
        n = max(1, math.ceil(dist / spacing), math.ceil(angle / angle_step))
        q = np.asarray(q_start, dtype=float)
        plan = [q]
        for i in range(1, n + 1):
            s = i / n
            r = self.solve(start.interpolate(target, s), q, q, opening)
            where = f"at {100 * s:.0f}% of the line"
            if not r.converged:
                return [], (
                    f"IK did not converge {where} (position error {r.position_error * 1000:.1f} mm)"
                )
            if np.max(np.abs(r.q - q)) > max_joint_jump:
                return [], f"IK jumped between branches {where} (near a singularity or limit)"
            problem = self.check(r.q, opening)
            if problem:
                return [], f"{problem} {where}"
            q = r.q
            plan.append(q)
        return plan, ""

    def check_joint_path(
        self, q_start: np.ndarray, q_target: np.ndarray, opening: float, step: float = 0.05
    ) -> str:
        """Empty if the straight joint path is within limits and free of collisions (checked
        every ``step`` rad), else the reason."""
        q_target = np.asarray(q_target, dtype=float)
        problem = self.limit_violation(q_target)
        if problem:
            return f"joint limit: {problem}"
        q0 = np.asarray(q_start, dtype=float)
        n = max(1, math.ceil(np.max(np.abs(q_target - q0)) / step))
        touching = self._hose_contacts(q0, opening)
        for i in range(1, n + 1):
            problem = self.check(q0 + (q_target - q0) * i / n, opening, touching, hoses=True)
            if problem:
                return f"{problem} at {100 * i / n:.0f}% of the joint path"
        return ""

    def check(
        self,
        q: np.ndarray,
        opening: float = 0.08,
        ignore: set[tuple[int, int]] = frozenset(),  # type: ignore[assignment]
        hoses: bool = False,
    ) -> str:
        """Empty string if ``q`` is within limits and collision-free, else the reason; with
        ``hoses`` the hose capsules count too (:meth:`collisions`)."""
        reason = self.limit_violation(q)
        if reason:
            return f"joint limit: {reason}"
        hits = self.collisions(q, opening, ignore=ignore, hoses=hoses)
        if hits:
            a, b, dist = hits[0]
            return f"collision: {a} with {b} (penetration {-dist * 1000:.1f} mm)"
        return ""


class ArmModelChecks:
    """``solve_ik`` and ``check_reachable`` of the ``Robot`` interface on an ``ArmModel``
    (``self.arm``), so the simulated and the real Panda judge reachability alike."""

    arm: ArmModel
    joint_positions: np.ndarray
    gripper_opening: float

    def solve_ik(self, pose: Pose, seeds: Sequence[np.ndarray] | None = None) -> np.ndarray | None:
        """Arm joints of a collision-free IK solution within limits for ``pose``, or None."""
        ok, _, result = self._reachable(pose, seeds)
        return result.q if ok and result is not None else None

    def check_reachable(self, pose: Pose) -> tuple[bool, str]:
        ok, reason, _ = self._reachable(pose, None)
        return ok, reason

    def _reachable(
        self, pose: Pose, seeds: Sequence[np.ndarray] | None
    ) -> tuple[bool, str, IKResult | None]:
        # the movable obstacles as they are now: the checks of a dry run of the interaction
        # (plan_interaction), which follow, plan on this arm model too
        self._update_obstacles()
        if seeds is None:
            seeds = self.arm.seeds(pose, self.joint_positions)
        return self.arm.reach(pose, seeds, self._opening_for_checks())

    def _update_obstacles(self) -> None:
        """Bring the arm model's movable obstacles up to date (none here; the simulated arm
        sets the hoses)."""

    def _opening_for_checks(self) -> float:
        """The finger opening the collision checks assume (fully open when it is unknown)."""
        opening = self.gripper_opening
        return opening if math.isfinite(opening) else MAX_OPENING
