"""One interaction, from a 2D segment to a frame stream (SPEC sections 2, 3), for the simulated
and the real robot alike.

    result = run_interaction(robot, camera, clock, segment, InteractionConfig(), truth=None)
    result.stream            # kept action frames (1 mm rule) ..., target frame last
    print(result.summary())  # frames kept per action (+ follow gain with a truth provider)

The interaction is five phases (:data:`PHASES`) over one :class:`InteractionState`, each
returning whether the interaction goes on:

1. :func:`locate`: centre + axis of the segment from the current depth image (perception's
   ``segment_pose``);
2. :func:`grasp`: grasp there across the axis (approach along the board normal, then a hold
   check when a ground-truth provider can tell whether the hose follows), or bring the closed
   gripper in front of the hose for a push;
3. :func:`act`: one periodic action per configured direction while the clock streams frames;
4. :func:`retreat`: release, back off, joint motion out of view, wait until the hoses are still
   (the clock's ``wait_still``), target frame (with ground truth: checked for zero robot
   pixels);
5. :func:`finish`: with ground truth the flow from the target frame to every kept frame; the
   stream and the timings.

A failure (unreachable, collision, slipping grasp, robot in view) comes back as
``InteractionResult(success=False, outcome=..., reason=...)``, ``outcome`` an
:class:`~cablesim.outcomes.Outcome` named where the failure was detected (the robot's motion,
the primitive, the phase); only a diverging simulation or a lost connection raises.  A grasp
that does not hold is retried at neighbouring points of the segment before the interaction
fails (:func:`~cablesim.episode.primitives.grasp_at`); ``result.grasp_retries`` counts the
retries.
With ground truth, a hose that slips during an action (the grasped point follows the hand with
R^2 below ``grasp.min_follow_r2``) is ``grasp_not_held`` too.

Nothing here is simulation-only: the robot, the camera and the clock are interfaces, and what
only a simulator can measure (which hose the segment shows, follow gain, neighbour
displacement, labels, flow) comes from the optional :class:`~cablesim.episode.truth.TruthProvider`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.camera.base import Camera
from cablesim.episode import primitives as prim
from cablesim.episode.capture import ArmMaskFunction, FrameCollector
from cablesim.episode.clock import Clock, Tick
from cablesim.episode.config import InteractionConfig
from cablesim.episode.surface import BOARD, Surface
from cablesim.episode.truth import FrameSink, TruthProvider
from cablesim.errors import InputError
from cablesim.frames import LABEL_ROBOT, Stream
from cablesim.jsonutil import jsonable
from cablesim.outcomes import OUTCOMES, Outcome
from cablesim.perception.geometry import segment_pose
from cablesim.pose import Pose
from cablesim.progress import Say, quiet
from cablesim.robot.base import Robot


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
    outcome: Outcome | None = None  # set by every return of run_interaction (OK on success)
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


# ---------------------------------------------------------------------- state
@dataclass
class InteractionOptions:
    """What an interaction may be given besides its devices and its configuration: run-time
    companions, none of them saved with a run.

    | field | what it is |
    | --- | --- |
    | `sink` | gets every frame as soon as it exists (e.g. `cablesim.recording.RecordingWriter`) |
    | `say` | progress lines (default: none) |
    | `hose` | the hose's index when it is known without ground truth (recorded only) |
    | `park` | the joint configuration out of view used when `config.retreat.qpos` is None |
    | `arm_mask` | `(tick) -> HxW bool` for every frame's `arm_mask` (`ArmMasker.for_tick`) |
    | `retry_rng` | picks the side of the first grasp retry (`primitives.grasp_at`) |
    | `surface` | what holds the cables (`cablesim.episode.surface`; default the board) |
    """

    sink: FrameSink | None = None
    say: Say | None = None
    hose: int | None = None
    park: Sequence[float] | None = None
    arm_mask: ArmMaskFunction | None = None
    retry_rng: np.random.Generator | None = None
    surface: Surface | None = None


@dataclass
class InteractionState:
    """What the phases of one interaction share: the devices, the validated configuration, the
    result being filled in and what one phase hands to the next (the grasp pose in
    ``result.grasp``, the frame collector, the action directions)."""

    robot: Robot
    camera: Camera
    clock: Clock
    segment: np.ndarray
    cfg: InteractionConfig
    truth: TruthProvider | None  # None also when the configuration asks for no ground truth
    options: InteractionOptions
    say: Say
    T: np.ndarray  # T_world_camera
    retreat_q: Sequence[float]
    result: InteractionResult
    surface: Surface = BOARD
    collector: FrameCollector | None = None
    directions: list[tuple[str, np.ndarray]] = field(default_factory=list)
    t_start: float = field(default_factory=time.perf_counter)
    c_start: float = field(default_factory=time.process_time)

    @classmethod
    def begin(
        cls,
        robot: Robot,
        camera: Camera,
        clock: Clock,
        segment: np.ndarray,
        config: InteractionConfig | None = None,
        truth: TruthProvider | None = None,
        options: InteractionOptions | None = None,
    ) -> InteractionState:
        # a grasp left open closes on the default cable (sessions fit it to theirs)
        cfg = (config or InteractionConfig()).validate().fitted()
        opts = options or InteractionOptions()
        T = camera.T_world_camera if camera.T_world_camera is not None else robot.T_world_camera
        park = None if opts.park is None else tuple(opts.park)
        return cls(
            robot,
            camera,
            clock,
            segment,
            cfg,
            truth if cfg.capture.ground_truth else None,
            opts,
            opts.say or quiet,
            np.asarray(T, float),
            cfg.retreat.joint_target(park),
            InteractionResult(False, hose=opts.hose),
            opts.surface or BOARD,
        )

    @property
    def approach(self) -> np.ndarray:
        """The hand's approach direction (world): the surface's."""
        return np.asarray(self.surface.approach, float)

    def fail(self, outcome: Outcome, reason: str) -> bool:
        """End the interaction as failed with ``outcome`` (False: for a phase to return)."""
        r = self.result
        r.success, r.outcome, r.reason, r.stream = False, outcome, reason, None
        self.say(f"failed: {reason}")
        return False

    def abort(self, outcome: Outcome, reason: str, moved: bool = True) -> bool:
        """Leave the scene clean (open, retreat) after a failure when the arm ``moved``, then
        end the interaction as failed."""
        if moved:
            prim.release(self.robot, self.cfg.grasp.open_width)
            r = prim.retreat(
                self.robot,
                self.retreat_q,
                self.cfg.retreat,
                self.approach,
                self.cfg.grasp.travel_speed,
            )
            if not r:
                reason += f"; retreat after the failure failed too ({r.reason})"
        return self.fail(outcome, reason)


# ---------------------------------------------------------------------- phases
def locate(s: InteractionState) -> bool:
    """Centre and axis of the segment from depth (SPEC 3.1); the hose under it with truth."""
    image = s.camera.capture()
    result = s.result
    try:
        mask, centre, axis = segment_grasp_target(s.segment, image, s.T, s.cfg.grasp.surface_offset)
    except InputError as e:
        result.reason, result.outcome = f"segment: {e}", Outcome.SEGMENT_INVALID
        return False
    if s.truth is not None:
        seen = s.truth.hose_under(mask)
        result.hose = s.options.hose if seen is None else seen
    result.centre, result.axis = centre, axis
    s.say(f"segment: {int(mask.sum())} px, centre {np.round(centre, 3)}, hose {result.hose}")
    return True


def grasp(s: InteractionState) -> bool:
    """Grasp at the centre across the axis (or bring the closed gripper in front of the hose
    for a push); the outcome of a failure is the primitive's."""
    cfg, result = s.cfg, s.result
    assert result.centre is not None and result.axis is not None
    t0 = time.perf_counter()
    centre = s.surface.grasp_centre(result.centre)  # the fingertips above a table
    if cfg.kind == "grasp":
        g = prim.grasp_at(
            s.robot,
            centre,
            result.axis,
            cfg.grasp,
            s.approach,
            hose_point=_hold_probe(s.truth, result.hose),
            rng=s.options.retry_rng,
        )
    else:
        g = prim.approach_for_push(s.robot, centre, result.axis, cfg.grasp, s.approach)
    result.timings["grasp"] = time.perf_counter() - t0
    result.details["grasp"] = g.details
    result.grasp_retries = int(g.details.get("retries", 0))
    if not g:
        return s.abort(g.outcome, g.reason, moved=g.moved)
    result.grasp = g.pose
    assert g.pose is not None
    if cfg.kind == "grasp" and s.surface.lift > 0:  # off the table before the actions
        lifted = g.pose.translated(-s.surface.lift * s.approach)
        r = s.robot.move_to(lifted, speed=cfg.grasp.approach_speed)
        if not r:
            return s.abort(Outcome.ACTION_FAILED, f"lift after the grasp: {r.reason}")
        result.grasp = lifted  # the actions' centre g1
    verb = "grasped" if cfg.kind == "grasp" else "at"
    s.say(f"{verb} hose at {np.round(g.pose.position, 3)} ({jsonable(g.details)})")
    return True


def _hold_probe(truth: TruthProvider | None, hose: int | None) -> Callable[[Pose], Any] | None:
    """The hold check's ``hose_point`` (ground truth only)."""
    if truth is None:
        return None
    return lambda pose: truth.grasp_probe(pose, hose)


def act(s: InteractionState) -> bool:
    """Every configured action while the clock streams frames into the collector."""
    cfg, result = s.cfg, s.result
    assert result.grasp is not None and result.axis is not None
    if s.truth is not None:
        s.truth.begin_interaction(result.hose, result.grasp)
    s.collector = FrameCollector(
        s.T,
        cfg.capture.min_gripper_step,
        s.truth,
        s.options.sink,
        s.options.arm_mask,
        cfg.capture.truth_every,
    )
    if cfg.kind == "grasp":
        s.directions = prim.action_directions(cfg.actions, result.axis, s.T, s.surface)
    else:
        s.directions = [("push", s.approach)]
    t0 = time.perf_counter()
    for a, (label, u) in enumerate(s.directions):
        if not _one_action(s, a, label, u):
            return False
    result.timings["actions"] = time.perf_counter() - t0
    return True


def _one_action(s: InteractionState, a: int, label: str, u: np.ndarray) -> bool:
    """Action ``a`` along ``u``: its frames, its report, and whether the hose followed."""
    cfg, result, collector = s.cfg, s.result, s.collector
    assert collector is not None and result.grasp is not None
    ticks_before = collector.ticks
    collector.begin_action(a)
    try:
        with s.clock.streaming(collector.on_tick):
            r = _strokes(s.robot, cfg, result.grasp, u)
    finally:
        collector.end_action()
    rep = ActionReport(label, u, collector.ticks - ticks_before, collector.kept(a))
    if s.truth is not None and cfg.kind == "grasp":
        at = s.truth.action_truth(a, u)
        rep.gain, rep.gain_r2, rep.hose_displacement = at.gain, at.gain_r2, at.hose_displacement
    elif s.truth is not None:
        rep.hose_displacement = s.truth.action_truth(a, u).hose_displacement
    result.actions.append(rep)
    if r.details.get("short_strokes"):
        result.details[f"action{a}_short_strokes_m"] = r.details["short_strokes"]
    s.say(f"action {a} ({label}): {rep.frames_kept}/{rep.ticks} frames kept, gain {rep.gain:.3f}")
    if not r:
        return s.abort(r.outcome, f"action {a} ({label}): {r.reason}")
    if rep.gain_r2 < cfg.grasp.min_follow_r2:  # NaN (no truth, no samples) passes
        why = (
            f"action {a} ({label}): the grasped hose did not follow the hand (follow R^2 "
            f"{rep.gain_r2:.2f} < {cfg.grasp.min_follow_r2}: it slipped in the gripper or "
            f"was pulled loose; largest hose displacement "
            f"{max(rep.hose_displacement, default=0.0) * 1000:.0f} mm)"
        )
        return s.abort(Outcome.GRASP_NOT_HELD, why)
    return True


def _strokes(robot: Robot, cfg: InteractionConfig, g1: Pose, u: np.ndarray) -> prim.PrimitiveResult:
    a = cfg.actions
    if cfg.kind == "grasp":
        return prim.periodic_action(
            robot, g1, u, a.amplitude, a.periods, a.speed, a.stroke_tolerance, a.min_stroke_coverage
        )
    return prim.push(robot, g1, u, cfg.push_depth, a.periods, a.speed, a.stroke_tolerance)


def retreat(s: InteractionState) -> bool:
    """Release, out of view, wait until the hoses are still, target frame (with ground truth
    and ``retreat.verify``: no robot pixels in it)."""
    cfg, result, collector = s.cfg, s.result, s.collector
    assert collector is not None
    t0 = time.perf_counter()
    r = prim.release(s.robot, cfg.grasp.open_width)
    if not r:
        return s.abort(r.outcome, r.reason)
    r = prim.retreat(s.robot, s.retreat_q, cfg.retreat, s.approach, cfg.grasp.travel_speed)
    if not r:
        return s.fail(r.outcome, r.reason)
    still = s.clock.wait_still(cfg.retreat)
    result.settle_speed, result.still = still.measure, still.still
    result.details["still"] = still.description
    if not still:
        s.say(f"warning: the hoses are not still after {still.waited:.1f} s ({still.description})")
    robot = s.robot
    now = Tick(s.clock.now(), robot.ee_pose(), float(robot.gripper_opening), robot.joint_positions)
    target = collector.capture_target(s.clock.grab, now)
    result.timings["retreat"] = time.perf_counter() - t0
    if target.truth is not None:
        result.target_robot_pixels = int((target.truth.labels == LABEL_ROBOT).sum())
        if cfg.retreat.verify and result.target_robot_pixels:
            n = result.target_robot_pixels
            return s.fail(
                Outcome.ROBOT_IN_VIEW, f"the robot is visible in the target frame ({n} pixels)"
            )
    return True


def finish(s: InteractionState) -> bool:
    """Ground-truth flow from the target to each kept frame; the stream; the timings."""
    result, collector = s.result, s.collector
    assert collector is not None
    if s.truth is not None:
        s.say(f"target frame captured; ground-truth flow for {len(collector.frames) - 1} frames")
    collector.finish(s.say)
    result.stream = Stream(collector.frames, meta=_stream_meta(s))
    result.success, result.outcome = True, Outcome.OK
    total, cpu = time.perf_counter() - s.t_start, time.process_time() - s.c_start
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
    s.say(f"done in {total:.1f} s")
    return True


def _stream_meta(s: InteractionState) -> dict[str, Any]:
    result = s.result
    return {
        "source": "cablesim",
        "kind": s.cfg.kind,
        "hose": result.hose,
        "action_labels": [d[0] for d in s.directions],
        "action_directions_world": [[float(x) for x in d[1]] for d in s.directions],
        "grasp_world": None if result.grasp is None else [float(x) for x in result.grasp.position],
        "interaction": s.cfg.to_dict(),
        "T_world_camera": s.T.tolist(),
    }


#: The phases of an interaction, in order; each returns whether the interaction goes on.
PHASES: tuple[Callable[[InteractionState], bool], ...] = (locate, grasp, act, retreat, finish)


# ---------------------------------------------------------------------- runner
def run_interaction(
    robot: Robot,
    camera: Camera,
    clock: Clock,
    segment: np.ndarray,
    config: InteractionConfig | None = None,
    truth: TruthProvider | None = None,
    options: InteractionOptions | None = None,
) -> InteractionResult:
    """Grasp (or push) the hose at ``segment`` of the current image and act: the
    :data:`PHASES` in turn until one fails (module docstring).

    ``segment``: HxW bool mask or (N, 2) pixels (u, v) in the camera's current image.
    ``truth``: a ground-truth provider (simulation, digital twin), used only when
    ``config.capture.ground_truth``.  ``options``: the run-time companions
    (:class:`InteractionOptions`: frame sink, progress, known hose, park pose, arm masks,
    grasp-retry random stream).  A grasp the config leaves open (``width`` None, ...) closes
    on the default cable kind; sessions fit it to the grasped cable
    (``Session.interaction_config``).
    """
    state = InteractionState.begin(robot, camera, clock, segment, config, truth, options)
    for phase in PHASES:
        if not phase(state):
            break
    return state.result


__all__ = [
    "OUTCOMES",
    "PHASES",
    "ActionReport",
    "InteractionOptions",
    "InteractionResult",
    "InteractionState",
    "Outcome",
    "act",
    "finish",
    "grasp",
    "locate",
    "retreat",
    "run_interaction",
    "segment_grasp_target",
    "segment_mask",
]
