"""Interaction primitives on the :class:`~cablesim.robot.base.Robot` interface (SPEC section 3).

They only use the robot interface, so the same code drives the simulated Panda and the real
one.  None of them raises for an unreachable target, a joint limit or a collision: each
returns a :class:`PrimitiveResult` that is falsy, says why and names the
:class:`~cablesim.outcomes.Outcome`: the failed motion's own (``MoveResult.outcome``) where the
robot named one, else the primitive's for the step that failed (a grasp that does not hold:
``GRASP_NOT_HELD``; a pre-grasp or push pose out of reach: ``UNREACHABLE``; an action stroke:
``ACTION_FAILED``; ``RELEASE_FAILED``, ``RETREAT_FAILED``).

- :func:`grasp_at`: pre-grasp in front of the point, straight approach along the board normal
  (made orthogonal to the hose axis: the hand's approach axis), close across the hose axis, and a hold check (pull back by a few millimetres and compare the
  hose point's motion with the hand's).  The hose point is only observable in simulation: the
  check takes an optional ``hose_point`` probe (ground truth, used for *verification* only,
  never by perception); without one (real robot) the gripper's opening decides, as in franky.
- :func:`periodic_action`: g1 -> g1+D -> g1 -> g1-D -> g1, ``periods`` times, along any
  direction.
- :func:`push`: the closed gripper presses by a displacement and returns, ``periods`` times.
- :func:`release`, :func:`retreat`: open, back off along the approach, joint motion out of view.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.episode.config import ActionConfig, GraspConfig, InteractionConfig, RetreatConfig
from cablesim.episode.surface import BOARD, Surface
from cablesim.outcomes import Outcome
from cablesim.panda.description import RETRACT_QPOS
from cablesim.pose import Pose, grasp_pose
from cablesim.robot.base import MoveResult, Robot
from cablesim.robot.dry_run import DryRunRobot
from cablesim.robot.grasping import avoiding_hoses, move_joints_safely

#: The default approach: the hand points at the board (world +x); the board normal is -x.
DEFAULT_APPROACH = BOARD.approach

HosePointProbe = Callable[[], np.ndarray]


@dataclass
class PrimitiveResult:
    """What a primitive did; truthy on success.  ``details`` holds measured numbers,
    ``outcome`` names a failure (``Outcome.OK`` on success), ``moved`` says whether the arm
    moved at all (a failure before any motion leaves nothing to clean up)."""

    success: bool
    reason: str = ""
    pose: Pose | None = None
    details: dict[str, Any] = field(default_factory=dict)
    outcome: Outcome = Outcome.OK
    moved: bool = True

    def __bool__(self) -> bool:
        return self.success

    @staticmethod
    def fail(
        step: str, move: MoveResult | str, outcome: Outcome, **details: Any
    ) -> PrimitiveResult:
        """A failed ``step``: ``move`` (a failed motion, or why in words) and the step's
        ``outcome``, which a motion that names its own outcome overrides."""
        why = move if isinstance(move, str) else move.reason
        if isinstance(move, MoveResult) and move.outcome is not None:
            outcome = move.outcome
        return PrimitiveResult(False, f"{step}: {why}", details=dict(details), outcome=outcome)


def _unit(v: Sequence[float] | np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(3)
    n = float(np.linalg.norm(v))
    if n < 1e-12 or not np.isfinite(n):
        raise ValueError(f"not a direction: {v}")
    return v / n


# ---------------------------------------------------------------------- directions
def action_direction(
    name: str,
    axis_world: np.ndarray,
    T_world_camera: np.ndarray,
    surface: Surface = BOARD,
) -> np.ndarray:
    """Unit world direction of a named action (SPEC 3.3) on ``surface`` (normal n =
    -approach: the board's faces the camera, the table's points up).

    - ``along``: the hose axis projected onto the image plane (camera z removed), or onto the
      surface's plane where the surface says so (``Surface.in_plane``: the table, seen
      obliquely from above, where the image plane's direction would push into the table);
    - ``across``: perpendicular to ``along`` in the surface's plane;
    - ``normal``: the surface normal; ``vertical``: world z;
      ``horizontal``: in the surface's plane, perpendicular to world z.
    """
    n = -_unit(surface.approach)
    R = np.asarray(T_world_camera, dtype=float)[:3, :3]
    a_cam = R.T @ _unit(axis_world)
    a_cam[2] = 0.0
    if surface.in_plane or np.linalg.norm(a_cam) < 1e-6:  # (axis along the optical axis)
        along = axis_world - np.dot(axis_world, n) * n
    else:
        along = R @ a_cam
    along = _unit(along)
    if name == "along":
        return along
    if name == "across":
        return _unit(np.cross(n, along))
    if name == "normal":
        return n
    if name == "vertical":
        return np.array([0.0, 0.0, 1.0])
    if name == "horizontal":
        if abs(n[2]) > 0.99:  # a horizontal surface: across the hose in its plane
            return _unit(np.cross(n, along))
        return _unit(np.cross(n, [0.0, 0.0, 1.0]))
    raise ValueError(f"unknown action direction {name!r}")


def action_directions(
    cfg: ActionConfig,
    axis_world: np.ndarray,
    T_world_camera: np.ndarray,
    surface: Surface = BOARD,
) -> list[tuple[str, np.ndarray]]:
    """(label, unit world direction) of every configured action, in order."""
    out = [(d, action_direction(d, axis_world, T_world_camera, surface)) for d in cfg.directions]
    out += [(f"vector{i}", _unit(v)) for i, v in enumerate(cfg.extra_directions)]
    return out


# ---------------------------------------------------------------------- planning
def grasp_centre(
    T_world_camera: np.ndarray, centre_camera: np.ndarray, surface_offset: float
) -> np.ndarray:
    """World grasp centre for the centre of a seen hose surface (camera frame): the hose axis
    lies ``surface_offset`` (its radius) behind the surface along the viewing ray."""
    T = np.asarray(T_world_camera, float)
    R, t = T[:3, :3], T[:3, 3]
    c = np.asarray(centre_camera, float)
    ray = R @ (c / np.linalg.norm(c))
    return R @ c + t + surface_offset * ray


def check_interaction(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: InteractionConfig,
    T_world_camera: np.ndarray,
    surface: Surface = BOARD,
) -> tuple[bool, str]:
    """Whether an interaction at world ``centre``/``axis`` on ``surface`` is reachable without
    moving: the grasp and pre-grasp poses and, for a grasp, every action's end points g1 +- D
    (``centre`` raised where the fingertips would touch the surface)."""
    centre = surface.grasp_centre(centre)
    approach = surface.approach
    g, why = choose_grasp_pose(robot, centre, axis, approach, cfg.grasp.pregrasp_offset)
    if g is None:
        return False, why
    if cfg.kind == "grasp":
        for label, u in action_directions(cfg.actions, axis, T_world_camera, surface):
            for s in (1.0, -1.0):
                ok, why = robot.check_reachable(g.translated(s * cfg.actions.amplitude * u))
                if not ok:
                    return False, f"action {label} end point: {why}"
    return True, ""


def plan_interaction(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: InteractionConfig,
    T_world_camera: np.ndarray,
    surface: Surface = BOARD,
) -> tuple[bool, str]:
    """Whether the interaction's motions on ``surface`` plan, without moving: the grasp approach (retract,
    stand-off, straight lines in) and one period of every action, stroke by stroke, on a
    :class:`~cablesim.robot.dry_run.DryRunRobot` of ``robot`` (its arm model, from its current
    joints; IK along each line, limits, collisions, branch jumps).  Stricter than
    :func:`check_interaction`, which checks the end poses one by one: an end point can be
    reachable while the line to it from the grasp configuration is not (measured: "IK did not
    converge at 100% of the line" on the first stroke).  Robots without an arm model get
    :func:`check_interaction`."""

    ok, why = check_interaction(robot, centre, axis, cfg, T_world_camera, surface)
    if not ok or not hasattr(robot, "arm"):
        return ok, why
    centre, approach = surface.grasp_centre(centre), surface.approach
    dry = DryRunRobot(robot)
    grasp_cfg = dataclasses.replace(cfg.grasp, retries=0)
    if cfg.kind == "push":
        g = approach_for_push(dry, centre, axis, grasp_cfg, approach)
        directions = [("push", np.asarray(approach, float))]
    else:
        g = grasp_at(dry, centre, axis, grasp_cfg, approach)
        directions = action_directions(cfg.actions, axis, T_world_camera, surface)
    if not g or g.pose is None:
        return False, f"planned {g.reason}"
    g1 = g.pose
    if surface.lift > 0 and cfg.kind == "grasp":
        g1 = g1.translated(-surface.lift * _unit(approach))
        r = dry.move_to(g1, speed=cfg.grasp.approach_speed)
        if not r:
            return False, f"planned lift: {r.reason}"
    a = cfg.actions
    for label, u in directions:
        depth = cfg.push_depth if cfg.kind == "push" else a.amplitude
        way = periodic_waypoints(g1, u, depth, 1, one_sided=cfg.kind == "push")
        r = _run_waypoints(dry, way, a.speed, f"planned action {label}")
        if not r:
            return False, r.reason
    return True, ""


# ---------------------------------------------------------------------- grasp
def _to_pose_via_retract(
    robot: Robot,
    pose: Pose,
    speed_factor: float = 0.5,
    standoff: float = 0.0,
    travel_speed: float = 0.25,
) -> MoveResult:
    """Joint motion to ``pose`` through the retract configuration (hand down, pulled back),
    so that the arm does not sweep through the hoses, which the arm-only checks cannot see.

    With ``standoff`` > 0 the joint motion ends ``standoff`` behind ``pose`` along the hand's
    approach axis and a straight line covers the rest: a joint motion that ends right in front
    of the board can sweep the hand sideways through the hanging hoses (measured: it dragged
    the hose of interest 11 cm off its grasp point); one that ends further back does not.  When
    the stand-off pose is out of reach, half the stand-off is tried; when that is out of reach
    too or its line is blocked, the joint motion goes straight to ``pose``."""
    q = robot.solve_ik(pose)
    if q is None:
        return MoveResult(False, "no IK solution", outcome=Outcome.UNREACHABLE)
    q_stage = None
    for back in (standoff, standoff / 2) if standoff > 0 else ():
        stage = pose.translated(-back * pose.rotation[:, 2])
        if robot.check_reachable(stage)[0]:
            q_stage = robot.solve_ik(stage)
            if q_stage is not None:
                break
    r = move_joints_safely(robot, RETRACT_QPOS, speed_factor)
    if not r:
        return MoveResult(False, f"could not retract first: {r.reason}", outcome=r.outcome)
    if q_stage is not None:
        r = robot.move_joints(q_stage, speed_factor)
        if r:
            r = robot.move_to(pose, speed=travel_speed)
            if r:
                return r
    return robot.move_joints(q, speed_factor)


def choose_grasp_pose(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    approach: Sequence[float] = DEFAULT_APPROACH,
    pregrasp_offset: float = 0.08,
) -> tuple[Pose | None, str]:
    """A reachable grasp pose (of the two hand flips) whose pre-grasp (``pregrasp_offset``
    back along the hand's approach axis) is reachable too."""
    reasons = []
    app = _unit(approach)
    for flip in (False, True):
        try:
            g = grasp_pose(centre, axis, approach=app, flip=flip)
        except ValueError as e:
            return None, str(e)
        ok, why = robot.check_reachable(g)
        if ok:
            ok, why = robot.check_reachable(g.translated(-pregrasp_offset * g.rotation[:, 2]))
            why = f"pre-grasp {why}" if not ok else why
        if ok:
            return g, ""
        reasons.append(f"{'flipped' if flip else 'upright'} hand: {why}")
    return None, "unreachable (" + "; ".join(reasons) + ")"


def grasp_at(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: GraspConfig | None = None,
    approach: Sequence[float] = DEFAULT_APPROACH,
    hose_point: Callable[[Pose], HosePointProbe | None] | None = None,
    rng: np.random.Generator | None = None,
) -> PrimitiveResult:
    """Grasp at world point ``centre`` with the fingers closing across world ``axis``.

    ``hose_point(grasp_pose)`` (simulation only) returns a probe of the grasped hose's
    material point, used to verify that the hose follows the hand within
    ``cfg.hold_tolerance``; it may return None when no hose is near the hand.

    A grasp that does not hold (the fingers close on nothing, the hold check sees the hose lag
    or the hand cannot pull back, the approach stops short) is retried up to ``cfg.retries``
    times, with or without ground truth: open, back out to the pre-grasp, re-approach a
    neighbouring point of the segment ``k * cfg.retry_shift`` along its axis, alternating
    sides (``rng``, the ``grasp_retry`` stream in simulation, picks the first side; without
    one, +axis first).  A neighbouring point that is out of reach is skipped.  A grasp that is
    unreachable before any motion is not retried.  The arm links are planned around the hoses
    throughout (:func:`~cablesim.robot.grasping.avoiding_hoses`).  ``details["retries"]`` counts the
    re-approaches made, ``details["attempts"]`` lists each attempt's offset and result and
    ``details["moved"]`` says whether the arm moved at all.
    """
    with avoiding_hoses(robot):
        return _grasp_at(robot, centre, axis, cfg or GraspConfig(), approach, hose_point, rng)


def _grasp_at(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: GraspConfig,
    approach: Sequence[float],
    hose_point: Callable[[Pose], HosePointProbe | None] | None,
    rng: np.random.Generator | None,
) -> PrimitiveResult:
    app = _unit(approach)
    along = _unit(axis)
    side = 1.0 if rng is None else float(rng.choice((-1.0, 1.0)))
    offsets = [0.0] + [
        side * (1 if k % 2 else -1) * ((k + 1) // 2) * cfg.retry_shift
        for k in range(1, cfg.retries + 1)
    ]
    attempts: list[dict[str, Any]] = []
    retries = 0
    moved = False
    at_pregrasp = False  # the hand waits at a pre-grasp after a failed attempt
    result = PrimitiveResult(False, "grasp: no attempt", outcome=Outcome.UNREACHABLE)
    for k, off in enumerate(offsets):
        point = np.asarray(centre, float) + off * along
        result = _grasp_once(robot, point, axis, cfg, app, hose_point, at_pregrasp)
        attempts.append({"offset_m": off, "result": "held" if result else result.reason})
        if result.details.get("moved", True):
            moved = True
            retries += k > 0
        if result:
            break
        if not result.details.get("moved", True):
            if k == 0:
                break  # unreachable before any motion: the segment itself is out of reach
            continue  # this neighbouring point is out of reach: try the next one
        if not result.details.get("retriable", False):
            break
        backed = _back_out(robot, cfg, result.details.get("pose"))
        if not backed:
            attempts[-1]["back_out"] = backed.reason
            break
        if "short_by" in backed.details:
            attempts[-1]["back_out_short_by_m"] = backed.details["short_by"]
        at_pregrasp = True
    result.details.pop("pose", None)
    result.details.pop("retriable", None)
    result.details.update(retries=retries, attempts=attempts, moved=moved)
    result.moved = moved
    return result


def _back_out(robot: Robot, cfg: GraspConfig, g: Pose | None) -> PrimitiveResult:
    """Open and move straight back to the pre-grasp of the failed grasp pose ``g``."""
    robot.open(cfg.open_width)
    if g is None:
        return PrimitiveResult(False, "back out: no grasp pose", outcome=Outcome.GRASP_NOT_HELD)
    pre = g.translated(-cfg.pregrasp_offset * g.rotation[:, 2])
    with robot.transit():
        r = robot.move_to(pre, speed=cfg.approach_speed)
    # stopping a few mm short of the pre-grasp (a hose brushing the open hand) still leaves
    # the hand clear of the hose for the next attempt, which starts with a move to its own
    # pre-grasp; a refused or colliding motion does not
    if not r and not _stopped_short(r, cfg.hold_check_distance):
        return PrimitiveResult.fail("back out", r, Outcome.GRASP_NOT_HELD)
    return PrimitiveResult(True, details={"short_by": float(r.position_error)} if not r else {})


def _stopped_short(r: MoveResult, within: float) -> bool:
    """Whether a failed motion ran and only ended off its target, by at most ``within`` m."""
    return r.reason.startswith("target not reached") and r.position_error <= within


def _grasp_once(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: GraspConfig,
    app: np.ndarray,
    hose_point: Callable[[Pose], HosePointProbe | None] | None,
    from_pregrasp: bool,
) -> PrimitiveResult:
    """One grasp attempt (see :func:`grasp_at`).  ``details``: ``moved`` (False when it failed
    before any motion), ``retriable`` (a failure a neighbouring point may cure), ``pose``."""
    g, why = choose_grasp_pose(robot, centre, axis, app, cfg.pregrasp_offset)
    if g is None:
        return PrimitiveResult(
            False, f"grasp: {why}", details={"moved": False}, outcome=Outcome.UNREACHABLE
        )
    app = g.rotation[:, 2]  # the hand's approach axis: the board normal made orthogonal to the hose
    pre = g.translated(-cfg.pregrasp_offset * app)
    if not robot.open(cfg.open_width):
        # the gripper's failure, not the grasp point's: no neighbouring point cures it, so it
        # is not retried (in simulation, fingers that closed on nothing fast enough to pass
        # through each other stay crossed; table rope seed 11608)
        return PrimitiveResult.fail(
            "grasp",
            f"the gripper did not open (opening {robot.gripper_opening * 1000:.1f} mm)",
            Outcome.RELEASE_FAILED,
            moved=from_pregrasp,
        )
    with robot.transit():  # the open hand to the hose: what it does not touch may rest
        r = robot.move_to(pre, speed=cfg.approach_speed) if from_pregrasp else MoveResult(False)
        if not r:
            r = _to_pose_via_retract(
                robot, pre, standoff=cfg.standoff, travel_speed=cfg.travel_speed
            )
        if not r:
            return PrimitiveResult.fail("move to pre-grasp", r, Outcome.UNREACHABLE, moved=True)
        r = robot.move_to(g, speed=cfg.approach_speed)
    if not r:
        return PrimitiveResult.fail(
            "approach", r, Outcome.GRASP_NOT_HELD, moved=True, retriable=True, pose=g
        )
    held = robot.grasp(
        width=cfg.width,
        force=cfg.force,
        epsilon_inner=cfg.epsilon,
        epsilon_outer=cfg.epsilon,
    )
    opening = robot.gripper_opening
    details: dict[str, Any] = {"opening": opening, "moved": True, "retriable": True, "pose": g}
    if not held:
        why = f"nothing held (fingers closed to {opening * 1000:.1f} mm)"
        return PrimitiveResult.fail("close", why, Outcome.GRASP_NOT_HELD, **details)
    probe = hose_point(g) if hose_point is not None else None
    if hose_point is not None and probe is None:
        return PrimitiveResult.fail(
            "close", "no hose between the fingers", Outcome.GRASP_NOT_HELD, **details
        )
    if probe is not None and cfg.hold_check_distance > 0:
        p0, h0 = probe(), robot.ee_pose().position
        r = robot.move_to(g.translated(-cfg.hold_check_distance * app), speed=cfg.approach_speed)
        p1, h1 = probe(), robot.ee_pose().position
        pulled = float(np.dot(h1 - h0, -app))
        if not r and (
            not r.reason.startswith("target not reached") or pulled < 0.3 * cfg.hold_check_distance
        ):
            # the hand did not pull back far enough to tell whether the hose follows
            return PrimitiveResult.fail(
                "hold check", r, Outcome.GRASP_NOT_HELD, pulled=pulled, **details
            )
        err = float(np.linalg.norm((p1 - p0) - (h1 - h0)))
        details["hold_error"] = err
        if not r:  # a taut hose held the hand short of its target: the hold is judged all the same
            details["hold_check_short_by"] = float(r.position_error)
        r = robot.move_to(g, speed=cfg.approach_speed)
        if not r and not _stopped_short(r, cfg.hold_check_distance):
            return PrimitiveResult.fail("hold check return", r, Outcome.GRASP_NOT_HELD, **details)
        if err > cfg.hold_tolerance:
            return PrimitiveResult.fail(
                "hold check",
                f"the hose lagged the hand by {err * 1000:.1f} mm "
                f"(tolerance {cfg.hold_tolerance * 1000:.1f} mm)",
                Outcome.GRASP_NOT_HELD,
                **details,
            )
    details.pop("retriable")
    details.pop("pose")
    return PrimitiveResult(True, "", pose=g, details=details)


# ---------------------------------------------------------------------- actions
def periodic_waypoints(
    g1: Pose, direction: np.ndarray, amplitude: float, periods: int, one_sided: bool = False
) -> list[Pose]:
    """g1+D, g1, g1-D, g1 per period (or g1+D, g1 per period when ``one_sided``)."""
    D = amplitude * _unit(direction)
    one = [g1.translated(D), g1] if one_sided else [g1.translated(D), g1, g1.translated(-D), g1]
    return one * int(periods)


def _run_waypoints(
    robot: Robot,
    waypoints: list[Pose],
    speed: float,
    step: str,
    tolerance: float = 0.0,
    min_coverage: float = 1.0,
) -> PrimitiveResult:
    """Stroke by stroke; a stroke that ends off its target because the hose pulls the hand
    back counts as done when it ends within ``tolerance`` of the target or the hand covered at
    least ``min_coverage`` of the stroke along its direction (a taut hose stopped it); each is
    noted (distance to the target) in ``details["short_strokes"]``.  A stroke that fails is
    ``ACTION_FAILED`` unless its motion named the outcome (unreachable, a collision)."""
    short: list[float] = []
    for i, w in enumerate(waypoints):
        start = robot.ee_pose().position
        r = robot.move_to(w, speed=speed)
        if not r:
            ok = _stopped_short(r, tolerance) or (
                r.reason.startswith("target not reached")
                and _coverage(start, robot.ee_pose().position, w.position) >= min_coverage
            )
            if not ok:
                return PrimitiveResult.fail(
                    f"{step} stroke {i + 1}/{len(waypoints)}",
                    r,
                    Outcome.ACTION_FAILED,
                    short_strokes=short,
                )
            short.append(float(r.position_error))
    return PrimitiveResult(
        True, pose=waypoints[-1] if waypoints else None, details={"short_strokes": short}
    )


def _coverage(start: np.ndarray, end: np.ndarray, target: np.ndarray) -> float:
    """The share of the stroke start -> target that the hand covered, along its direction."""
    d = np.asarray(target, float) - np.asarray(start, float)
    n2 = float(d @ d)
    if n2 < 1e-12:
        return 1.0
    return float((np.asarray(end, float) - start) @ d / n2)


def periodic_action(
    robot: Robot,
    g1: Pose,
    direction: np.ndarray,
    amplitude: float = 0.02,
    periods: int = 3,
    speed: float = 0.05,
    tolerance: float = 0.01,
    min_coverage: float = 1.0,
) -> PrimitiveResult:
    """Move g1 -> g1+D -> g1 -> g1-D -> g1, ``periods`` times; D = ``amplitude`` * direction.
    A stroke may end up to ``tolerance`` off its target, or further when the hand covered at
    least ``min_coverage`` of it (the hose pulls on the hand: ``_run_waypoints``)."""
    way = periodic_waypoints(g1, direction, amplitude, periods)
    return _run_waypoints(robot, way, speed, "action", tolerance, min_coverage)


def push(
    robot: Robot,
    g1: Pose,
    direction: np.ndarray,
    depth: float = 0.02,
    periods: int = 1,
    speed: float = 0.05,
    tolerance: float = 0.01,
) -> PrimitiveResult:
    """With the gripper closed and holding nothing, press from ``g1`` by ``depth`` along
    ``direction`` and come back, ``periods`` times (the poking stick of thesis chapter 4)."""
    if robot.gripper_opening > 0.005:
        robot.open(0.0)  # closed fingers: a blunt poker
    way = periodic_waypoints(g1, direction, depth, periods, one_sided=True)
    return _run_waypoints(robot, way, speed, "push", tolerance)


def approach_for_push(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: GraspConfig | None = None,
    approach: Sequence[float] = DEFAULT_APPROACH,
    standoff: float = 0.02,
) -> PrimitiveResult:
    """Close the gripper and bring it to ``standoff`` in front of the hose point."""
    with avoiding_hoses(robot):
        return _approach_for_push(robot, centre, axis, cfg or GraspConfig(), approach, standoff)


def _approach_for_push(
    robot: Robot,
    centre: np.ndarray,
    axis: np.ndarray,
    cfg: GraspConfig,
    approach: Sequence[float],
    standoff: float,
) -> PrimitiveResult:
    app = _unit(approach)
    g, why = choose_grasp_pose(robot, centre, axis, app, cfg.pregrasp_offset)
    if g is None:
        return PrimitiveResult(False, f"push: {why}", outcome=Outcome.UNREACHABLE, moved=False)
    app = g.rotation[:, 2]
    g = g.translated(-standoff * app)
    robot.open(0.0)
    with robot.transit():  # the closed, empty hand to the hose: the strokes run awake
        r = _to_pose_via_retract(
            robot,
            g.translated(-cfg.pregrasp_offset * app),
            standoff=cfg.standoff,
            travel_speed=cfg.travel_speed,
        )
        if not r:
            return PrimitiveResult.fail("move to pre-push", r, Outcome.UNREACHABLE)
        r = robot.move_to(g, speed=cfg.approach_speed)
    if not r:
        return PrimitiveResult.fail("push approach", r, Outcome.UNREACHABLE)
    return PrimitiveResult(True, pose=g)


# ---------------------------------------------------------------------- leave
def release(robot: Robot, width: float = 0.08) -> PrimitiveResult:
    ok = robot.open(width)
    if ok:
        return PrimitiveResult(True)
    return PrimitiveResult(
        False, "release: the gripper did not open", outcome=Outcome.RELEASE_FAILED
    )


def retreat(
    robot: Robot,
    qpos: Sequence[float],
    cfg: RetreatConfig | None = None,
    approach: Sequence[float] = DEFAULT_APPROACH,
    travel_speed: float = 0.25,
) -> PrimitiveResult:
    """Back off along -approach (if possible), then joint motion through the retract
    configuration to ``qpos`` (out of the camera's view); a transit (:meth:`Robot.transit`)."""
    with robot.transit():
        return _retreat(robot, qpos, cfg or RetreatConfig(), approach, travel_speed)


def _retreat(
    robot: Robot,
    qpos: Sequence[float],
    cfg: RetreatConfig,
    approach: Sequence[float],
    travel_speed: float,
) -> PrimitiveResult:
    notes = []
    if cfg.back_off > 0:
        r = robot.move_relative(-cfg.back_off * _unit(approach), speed=travel_speed)
        if not r:
            notes.append(f"back-off skipped ({r.reason})")
    # through the retract configuration: the straight joint path from an arm stretched
    # towards the board would sweep the hand along the board and through the hoses
    r = move_joints_safely(robot, RETRACT_QPOS, cfg.speed_factor)
    if not r:
        notes.append(f"retract skipped ({r.reason})")
    r = robot.move_joints(np.asarray(qpos, dtype=float), speed_factor=cfg.speed_factor)
    if not r:
        why = f"{r.reason} ({'; '.join(notes)})" if notes else r.reason
        return PrimitiveResult.fail("retreat", why, Outcome.RETREAT_FAILED, notes=notes)
    return PrimitiveResult(True, details={"notes": notes})
