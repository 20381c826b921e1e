"""One interaction, from a 2D segment to a frame stream (SPEC sections 2, 3), for the simulated
and the real robot alike.

    result = run_interaction(robot, camera, clock, segment, InteractionConfig(), truth=None)
    result.stream            # kept action frames (1 mm rule) ..., target frame last
    print(result.summary())  # frames kept per action (+ follow gain with a truth provider)

Steps: centre + axis of the segment from the current depth image (perception's
``segment_pose``); grasp there across the axis (approach along the board normal, then a hold
check when a ground-truth provider can tell whether the hose follows); one periodic action per
configured direction while the clock streams frames; release, back off, joint motion out of
view, wait until the hoses are still (the clock's ``wait_still``), target frame (with ground
truth: checked for zero robot pixels), and with ground truth the flow from the target frame to
every kept frame.  A failure (unreachable, collision, slipping grasp, robot in view) comes back
as ``InteractionResult(success=False, outcome=..., reason=...)``, ``outcome`` one of
:data:`OUTCOMES`; only a diverging simulation or a lost connection raises.  A grasp that does
not hold is retried at neighbouring points of the segment before the interaction fails
(:func:`~cablesim.episode.primitives.grasp_at`); ``result.grasp_retries`` counts the retries.
With ground truth, a hose that slips during an action (the grasped point follows the hand with
R^2 below ``grasp.min_follow_r2``) is ``grasp_not_held`` too.

Nothing here is simulation-only: the robot, the camera and the clock are interfaces, and what
only a simulator can measure (which hose the segment shows, follow gain, neighbour
displacement, labels, flow) comes from the optional :class:`~cablesim.episode.truth.TruthProvider`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.camera.base import Camera
from cablesim.episode import primitives as prim
from cablesim.episode.capture import ArmMaskFunction, FrameCollector
from cablesim.episode.clock import Clock, Tick
from cablesim.episode.config import InteractionConfig
from cablesim.episode.truth import FrameSink, TruthProvider
from cablesim.errors import InputError
from cablesim.jsonutil import jsonable
from cablesim.perception.frames import LABEL_ROBOT, Stream
from cablesim.perception.geometry import segment_pose
from cablesim.progress import Say, quiet
from cablesim.robot.base import Robot
from cablesim.robot.pose import Pose

#: Named outcomes of an interaction (``InteractionResult.outcome``) and of the runs that
#: record one per seed or start (``simulate_episode``, ``explore``, ``benchmarks/seeds.py``).
OUTCOMES: dict[str, str] = {
    "ok": "the interaction ran; target frame captured",
    "segment_invalid": "the segment is malformed or has too little depth under it",
    "unreachable": "the grasp, its pre-grasp, an action end point or the path there is out of "
    "reach (IK, joint limits, a collision the arm model's check predicts)",
    "collision": "a motion stopped on a contact in the scene (board, table, a coupling)",
    "grasp_not_held": "the fingers closed on nothing or the hose slipped, after every retry; "
    "with ground truth also a grasped hose that did not follow the hand during an action",
    "action_failed": "an action stroke ended off its target (the hose held the hand back)",
    "release_failed": "the gripper did not open",
    "retreat_failed": "the arm could not move out of view",
    "robot_in_view": "the robot is visible in the target frame",
    # simulation: the scene before any interaction (see cablesim.sim.session)
    "scene_unsettled": "no scene draw settled (cablesim.errors.SceneUnsettledError)",
    "no_graspable_segment": "no scene draw had a hose of interest with a graspable segment",
    "diverged": "the physics diverged (cablesim.errors.PhysicsDivergedError): NaN, a MuJoCo "
    "warning, or a hose edge stretched past physics.max_hose_strain",
}


def failure_outcome(reason: str, default: str) -> str:
    """The named outcome of a failed motion step from its reason (``default`` otherwise)."""
    r = reason.lower()
    if "collision in scene" in r or "contact:" in r:
        return "collision"
    if any(k in r for k in ("unreachable", "no ik", "ik did not converge", "joint limit")):
        return "unreachable"
    if "ik jumped" in r or "collision:" in r:  # planned: the arm model predicts it
        return "unreachable"
    return default


@dataclass
class ActionReport:
    """What one action did; gain and displacements only with a ground-truth provider."""

    label: str
    direction: np.ndarray  # unit, world
    ticks: int  # camera ticks during the action
    frames_kept: int
    gain: float = math.nan  # grasped hose point displacement / gripper displacement
    gain_r2: float = math.nan
    hose_displacement: list[float] = field(default_factory=list)  # m, per hose

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "direction": [float(x) for x in self.direction],
            "ticks": self.ticks,
            "frames_kept": self.frames_kept,
            "gain": self.gain,
            "gain_r2": self.gain_r2,
            "hose_displacement_m": self.hose_displacement,
        }


@dataclass
class InteractionResult:
    success: bool
    reason: str = ""
    outcome: str = ""  # one of OUTCOMES ("ok" on success)
    grasp_retries: int = 0  # re-approaches at neighbouring points before the grasp held
    stream: Stream | None = None
    hose: int | None = None
    centre: np.ndarray | None = None  # world, estimated from depth
    axis: np.ndarray | None = None  # world, unit
    grasp: Pose | None = None
    actions: list[ActionReport] = field(default_factory=list)
    target_robot_pixels: int = -1
    settle_speed: float = math.nan  # the clock's last stillness measure
    still: bool = True
    timings: dict[str, float] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.success

    def other_hose_displacement(self) -> list[float]:
        """Largest displacement (m) over the actions of each hose other than the grasped one."""
        out = []
        n = len(self.actions[0].hose_displacement) if self.actions else 0
        for h in range(n):
            if h != self.hose:
                out.append(max(a.hose_displacement[h] for a in self.actions))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "success": self.success,
            "outcome": self.outcome,
            "reason": self.reason,
            "grasp_retries": self.grasp_retries,
            "hose": self.hose,
            "centre": None if self.centre is None else [float(x) for x in self.centre],
            "axis": None if self.axis is None else [float(x) for x in self.axis],
            "frames": 0 if self.stream is None else len(self.stream),
            "actions": [a.to_dict() for a in self.actions],
            "target_robot_pixels": self.target_robot_pixels,
            "settle_speed": self.settle_speed,
            "still": self.still,
            "timings_s": self.timings,
            "details": jsonable(self.details),
        }

    def summary(self) -> str:
        if not self.success:
            return f"interaction FAILED ({self.outcome}): {self.reason}"
        lines = [
            f"interaction ok: hose {self.hose}, {len(self.stream or [])} frames (target last), "
            f"{self.grasp_retries} grasp retries"
        ]
        for a in self.actions:
            others = ", ".join(
                f"hose{h} {d * 1000:.1f} mm"
                for h, d in enumerate(a.hose_displacement)
                if h != self.hose
            )
            lines.append(
                f"  action {a.label:>10}: gain {a.gain:.3f} (R^2 {a.gain_r2:.3f}), "
                f"{a.frames_kept}/{a.ticks} frames kept; other hoses moved: {others or '-'}"
            )
        lines.append(
            f"  target frame: {self.target_robot_pixels} robot pixels; "
            f"{self.details.get('still', '')}"
        )
        wall = {k: v for k, v in self.timings.items() if not k.startswith("cpu_")}
        cpu = {k[4:]: v for k, v in self.timings.items() if k.startswith("cpu_")}
        lines.append("  wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in wall.items()))
        if cpu:
            lines.append("  CPU time: " + ", ".join(f"{k} {v:.1f} s" for k, v in cpu.items()))
        return "\n".join(lines)


# ---------------------------------------------------------------------- segment input
def segment_mask(segment: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """An HxW bool mask from a mask or from an (N, 2) list of pixels as (u=column, v=row)."""
    s = np.asarray(segment)
    if s.shape == tuple(shape):
        return s.astype(bool)
    if s.ndim == 2 and s.shape[1] == 2 and len(s) > 0:
        h, w = shape
        uv = np.rint(s).astype(np.int64)
        if (
            (uv[:, 0] < 0).any()
            or (uv[:, 0] >= w).any()
            or (uv[:, 1] < 0).any()
            or (uv[:, 1] >= h).any()
        ):
            raise InputError(f"segment pixels fall outside the {w}x{h} image")
        m = np.zeros(shape, bool)
        m[uv[:, 1], uv[:, 0]] = True
        return m
    raise InputError(
        f"segment must be an HxW mask {tuple(shape)} or an (N, 2) pixel list, got {s.shape}"
    )


def segment_grasp_target(
    segment: np.ndarray, image: Any, T_world_camera: np.ndarray, surface_offset: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mask, centre, axis) in the world of the hose under a 2D segment (SPEC 3.1): the seen
    surface lies one radius (``surface_offset``) in front of the hose axis along the ray."""
    mask = segment_mask(segment, image.rgb.shape[:2])
    sp = segment_pose(mask, image.depth, image.intrinsics)
    T = np.asarray(T_world_camera, float)
    return mask, prim.grasp_centre(T, sp.centre, surface_offset), T[:3, :3] @ sp.axis


# ---------------------------------------------------------------------- runner
def run_interaction(
    robot: Robot,
    camera: Camera,
    clock: Clock,
    segment: np.ndarray,
    config: InteractionConfig | None = None,
    truth: TruthProvider | None = None,
    sink: FrameSink | None = None,
    say: Say | None = None,
    hose: int | None = None,
    park: Sequence[float] | None = None,
    arm_mask: ArmMaskFunction | None = None,
    retry_rng: np.random.Generator | None = None,
) -> InteractionResult:
    """Grasp (or push) the hose at ``segment`` of the current image and act (module docstring).

    ``segment``: HxW bool mask or (N, 2) pixels (u, v) in the camera's current image.
    ``hose``: the hose's index when it is known without ground truth (recorded only).
    ``park``: the joint configuration out of view used when ``config.retreat.qpos`` is None.
    ``sink`` (e.g. :class:`~cablesim.recording.RecordingWriter`) gets every frame as soon as
    it exists.  ``arm_mask`` (``(tick) -> HxW bool``, e.g.
    :meth:`cablesim.panda.arm_mask.ArmMasker.for_tick`) fills every frame's ``arm_mask``.
    it exists.  ``retry_rng`` picks the side of the first grasp retry (see ``grasp_at``).
    """
    cfg = (config or InteractionConfig()).validate()
    say = say or quiet
    t_start, c_start = time.perf_counter(), time.process_time()
    approach = np.asarray(prim.DEFAULT_APPROACH, float)
    T = np.asarray(
        camera.T_world_camera if camera.T_world_camera is not None else robot.T_world_camera, float
    )
    retreat_q = cfg.retreat.joint_target(None if park is None else tuple(park))
    result = InteractionResult(False, hose=hose)

    # 1. centre and axis of the segment from depth (SPEC 3.1)
    image = camera.capture()
    try:
        mask, centre, axis = segment_grasp_target(segment, image, T, cfg.grasp.surface_offset)
    except InputError as e:
        result.reason, result.outcome = f"segment: {e}", "segment_invalid"
        return result
    if truth is not None and cfg.capture.ground_truth:
        seen = truth.hose_under(mask)
        result.hose = hose if seen is None else seen
    result.centre, result.axis = centre, axis
    say(f"segment: {int(mask.sum())} px, centre {np.round(centre, 3)}, hose {result.hose}")
    truth = truth if cfg.capture.ground_truth else None

    # 2. grasp (or bring the closed gripper in front of the hose for a push)
    t0 = time.perf_counter()
    if cfg.kind == "grasp":
        probe = None
        if truth is not None:
            held_hose = result.hose
            probe = lambda pose: truth.grasp_probe(pose, held_hose)  # noqa: E731
        g = prim.grasp_at(robot, centre, axis, cfg.grasp, approach, hose_point=probe, rng=retry_rng)
    else:
        g = prim.approach_for_push(robot, centre, axis, cfg.grasp, approach)
    result.timings["grasp"] = time.perf_counter() - t0
    result.details["grasp"] = g.details
    result.grasp_retries = int(g.details.get("retries", 0))
    if not g:
        # a push and a grasp's first attempt that fail with "push:"/"grasp:" never moved
        moved = bool(g.details.get("moved", not g.reason.startswith(("grasp:", "push:"))))
        step = g.reason.split(":", 1)[0]
        held = step in ("close", "hold check", "hold check return", "approach", "back out")
        result.outcome = failure_outcome(g.reason, "grasp_not_held" if held else "unreachable")
        return _abort(result, robot, cfg, retreat_q, g.reason, say, moved=moved)
    result.grasp = g.pose
    assert g.pose is not None
    verb = "grasped" if cfg.kind == "grasp" else "at"
    say(f"{verb} hose at {np.round(g.pose.position, 3)} ({jsonable(g.details)})")

    # 3. actions, frames from the clock
    if truth is not None:
        truth.begin_interaction(result.hose, g.pose)
    collector = FrameCollector(T, cfg.capture.min_gripper_step, truth, sink, arm_mask)
    if cfg.kind == "grasp":
        directions = prim.action_directions(cfg.actions, axis, T, approach)
    else:
        directions = [("push", approach)]
    t0 = time.perf_counter()
    for a, (label, u) in enumerate(directions):
        ticks_before = collector.ticks
        collector.begin_action(a)
        try:
            with clock.streaming(collector.on_tick):
                r = _act(robot, cfg, g.pose, u)
        finally:
            collector.end_action()
        rep = ActionReport(label, u, collector.ticks - ticks_before, collector.kept(a))
        if truth is not None and cfg.kind == "grasp":
            at = truth.action_truth(a, u)
            rep.gain, rep.gain_r2, rep.hose_displacement = at.gain, at.gain_r2, at.hose_displacement
        elif truth is not None:
            rep.hose_displacement = truth.action_truth(a, u).hose_displacement
        result.actions.append(rep)
        if r.details.get("short_strokes"):
            result.details[f"action{a}_short_strokes_m"] = r.details["short_strokes"]
        say(f"action {a} ({label}): {rep.frames_kept}/{rep.ticks} frames kept, gain {rep.gain:.3f}")
        if not r:
            result.outcome = failure_outcome(r.reason, "action_failed")
            return _abort(result, robot, cfg, retreat_q, f"action {a} ({label}): {r.reason}", say)
        if rep.gain_r2 < cfg.grasp.min_follow_r2:  # NaN (no truth, no samples) passes
            result.outcome = "grasp_not_held"
            why = (
                f"action {a} ({label}): the grasped hose did not follow the hand (follow R^2 "
                f"{rep.gain_r2:.2f} < {cfg.grasp.min_follow_r2}: it slipped in the gripper or "
                f"was pulled loose; largest hose displacement "
                f"{max(rep.hose_displacement, default=0.0) * 1000:.0f} mm)"
            )
            return _abort(result, robot, cfg, retreat_q, why, say)
    result.timings["actions"] = time.perf_counter() - t0

    # 4. release, out of view, wait until still, target frame
    t0 = time.perf_counter()
    r = prim.release(robot, cfg.grasp.open_width)
    if not r:
        result.outcome = "release_failed"
        return _abort(result, robot, cfg, retreat_q, r.reason, say)
    r = prim.retreat(robot, retreat_q, cfg.retreat, approach, cfg.grasp.travel_speed)
    if not r:
        result.outcome = "retreat_failed"
        return _fail(result, r.reason, say)
    still = clock.wait_still(cfg.retreat)
    result.settle_speed, result.still = still.measure, still.still
    result.details["still"] = still.description
    if not still:
        say(f"warning: the hoses are not still after {still.waited:.1f} s ({still.description})")
    now = Tick(clock.now(), robot.ee_pose(), float(robot.gripper_opening), robot.joint_positions)
    target = collector.capture_target(clock.grab, now)
    result.timings["retreat"] = time.perf_counter() - t0
    if target.truth is not None:
        result.target_robot_pixels = int((target.truth.labels == LABEL_ROBOT).sum())
        if cfg.retreat.verify and result.target_robot_pixels:
            result.outcome = "robot_in_view"
            return _fail(
                result,
                f"the robot is visible in the target frame ({result.target_robot_pixels} pixels)",
                say,
            )

    # 5. ground-truth flow from the target to each kept frame
    if truth is not None:
        say(f"target frame captured; ground-truth flow for {len(collector.frames) - 1} frames")
    collector.finish(say)
    result.stream = Stream(collector.frames, meta=_stream_meta(cfg, result, directions, T))
    result.success, result.outcome = True, "ok"
    total, cpu = time.perf_counter() - t_start, time.process_time() - c_start
    result.timings.update(
        total=total,
        rendering=collector.render_time,
        ground_truth=collector.truth_time,
        physics_control=total - collector.render_time - collector.truth_time,
        cpu_total=cpu,
        cpu_rendering=collector.render_cpu,
        cpu_ground_truth=collector.truth_cpu,
        cpu_physics_control=cpu - collector.render_cpu - collector.truth_cpu,
    )
    result.details["ticks"] = collector.ticks
    if collector.skews:
        result.details["skew_median_s"] = float(np.median(collector.skews))
        result.details["skew_max_s"] = float(np.max(collector.skews))
    say(f"done in {total:.1f} s")
    return result


def _act(robot: Robot, cfg: InteractionConfig, g1: Pose, u: np.ndarray) -> prim.PrimitiveResult:
    a = cfg.actions
    if cfg.kind == "grasp":
        return prim.periodic_action(
            robot, g1, u, a.amplitude, a.periods, a.speed, a.stroke_tolerance, a.min_stroke_coverage
        )
    return prim.push(robot, g1, u, cfg.push_depth, a.periods, a.speed, a.stroke_tolerance)


def _stream_meta(
    cfg: InteractionConfig,
    result: InteractionResult,
    directions: list[tuple[str, np.ndarray]],
    T: np.ndarray,
) -> dict[str, Any]:
    return {
        "source": "cablesim",
        "kind": cfg.kind,
        "hose": result.hose,
        "action_labels": [d[0] for d in directions],
        "action_directions_world": [[float(x) for x in d[1]] for d in directions],
        "grasp_world": None if result.grasp is None else [float(x) for x in result.grasp.position],
        "interaction": cfg.to_dict(),
        "T_world_camera": T.tolist(),
    }


def _fail(result: InteractionResult, reason: str, say: Say) -> InteractionResult:
    result.success, result.reason, result.stream = False, reason, None
    say(f"failed: {reason}")
    return result


def _abort(
    result: InteractionResult,
    robot: Robot,
    cfg: InteractionConfig,
    retreat_q: Sequence[float],
    reason: str,
    say: Say,
    moved: bool = True,
) -> InteractionResult:
    """Leave the scene clean (open, retreat) after a failure, then report it."""
    if moved:
        prim.release(robot, cfg.grasp.open_width)
        r = prim.retreat(
            robot, retreat_q, cfg.retreat, prim.DEFAULT_APPROACH, cfg.grasp.travel_speed
        )
        if not r:
            reason += f"; retreat after the failure failed too ({r.reason})"
    return _fail(result, reason, say)
