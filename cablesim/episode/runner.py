"""One simulated interaction, from a 2D segment to a frame stream (SPEC sections 2, 3, 6).

    world = World.build(cfg.scene_config())
    robot, camera = SimPanda(world), SimCamera(world)
    segment = pick_segment(world, robot, camera, hose=1, rng=rng)   # or a user's mask
    result = run_episode(world, robot, camera, segment, cfg)
    result.stream            # kept action frames (1 mm rule) ..., target frame last
    print(result.summary())  # gain per action, other hoses' displacement, frames kept

Steps: centre + axis of the segment from the current depth image (perception's
``segment_pose``); grasp there across the axis (approach along the board normal, hold check);
one periodic action per configured direction with the camera triggered every 1/15 s of
simulated time; release, back off, joint motion out of view, settle (hoses slower than
1 mm/s), target frame (checked: zero robot pixels), ground-truth flow from the target frame
to every kept frame.  A failure (unreachable, collision, slipping grasp, robot in view) comes
back as ``EpisodeResult(success=False, reason=...)``; only a diverging simulation raises.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.camera.base import Camera
from cablesim.episode import primitives as prim
from cablesim.episode.capture import FrameCollector, FrameSink
from cablesim.episode.config import EpisodeConfig
from cablesim.episode.sim_truth import HosePoint, MotionLog, settle_hoses
from cablesim.episode.trigger import SimTrigger
from cablesim.errors import InputError
from cablesim.perception.frames import LABEL_ROBOT, Stream
from cablesim.perception.geometry import segment_pose
from cablesim.robot.base import Robot
from cablesim.robot.pose import Pose

#: A hose farther than this from the closed hand is not held (simulation check).
GRASP_MAX_DISTANCE = 0.02


@dataclass
class ActionReport:
    """What one action did (measured in simulation)."""

    label: str
    direction: np.ndarray  # unit, world
    ticks: int  # camera ticks during the action
    frames_kept: int
    gain: float  # grasped hose point displacement / gripper displacement along the direction
    gain_r2: float
    hose_displacement: list[float]  # m, largest vertex displacement of every hose

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
class EpisodeResult:
    success: bool
    reason: str = ""
    stream: Stream | None = None
    hose: int | None = None
    centre: np.ndarray | None = None  # world, estimated from depth
    axis: np.ndarray | None = None  # world, unit
    grasp: Pose | None = None
    actions: list[ActionReport] = field(default_factory=list)
    target_robot_pixels: int = -1
    settle_speed: float = math.nan
    timings: dict[str, float] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.success

    def other_hose_displacement(self) -> list[float]:
        """Largest displacement (m) over the actions of each hose other than the grasped one."""
        out = []
        for h in range(len(self.actions[0].hose_displacement) if self.actions else 0):
            if h != self.hose:
                out.append(max(a.hose_displacement[h] for a in self.actions))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "success": self.success,
            "reason": self.reason,
            "hose": self.hose,
            "centre": None if self.centre is None else [float(x) for x in self.centre],
            "axis": None if self.axis is None else [float(x) for x in self.axis],
            "frames": 0 if self.stream is None else len(self.stream),
            "actions": [a.to_dict() for a in self.actions],
            "target_robot_pixels": self.target_robot_pixels,
            "settle_speed": self.settle_speed,
            "timings_s": self.timings,
            "details": _jsonable(self.details),
        }

    def summary(self) -> str:
        if not self.success:
            return f"episode FAILED: {self.reason}"
        lines = [f"episode ok: hose {self.hose}, {len(self.stream or [])} frames (target last)"]
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
            f"  target frame: {self.target_robot_pixels} robot pixels, hoses settled to "
            f"{self.settle_speed * 1000:.2f} mm/s"
        )
        lines.append("  wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.timings.items()))
        return "\n".join(lines)


def _jsonable(v: Any) -> Any:
    try:
        json.dumps(v)
        return v
    except TypeError:
        if isinstance(v, dict):
            return {str(k): _jsonable(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [_jsonable(x) for x in v]
        if isinstance(v, np.ndarray):
            return v.tolist()
        return repr(v)


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


def _camera_to_world(T: np.ndarray, p: np.ndarray, direction: bool = False) -> np.ndarray:
    R = np.asarray(T, float)[:3, :3]
    return R @ p if direction else R @ p + np.asarray(T, float)[:3, 3]


# ---------------------------------------------------------------------- runner
class _Progress:
    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if self.enabled:
            print(f"[episode {time.perf_counter() - self.t0:6.1f}s] {msg}", flush=True)


def run_episode(
    world: Any,
    robot: Robot,
    camera: Camera,
    segment: np.ndarray,
    config: EpisodeConfig | None = None,
    sink: FrameSink | None = None,
    progress: Callable[[str], None] | None = None,
) -> EpisodeResult:
    """Grasp (or push) the hose at ``segment`` of the current image and act; see the module doc.

    ``segment``: HxW bool mask or (N, 2) pixels (u, v) in the camera's current image.
    ``sink`` (e.g. :class:`~cablesim.episode.recording.RecordingWriter`) gets every frame as
    soon as it exists.
    """
    cfg = (config or EpisodeConfig()).validate()
    say = progress or _Progress(cfg.progress)
    t_start = time.perf_counter()
    approach = np.asarray(prim.DEFAULT_APPROACH, float)
    T = np.asarray(
        camera.T_world_camera if camera.T_world_camera is not None else robot.T_world_camera, float
    )

    # 1. centre and axis of the segment from depth (SPEC 3.1)
    image = camera.capture()
    mask = segment_mask(segment, image.rgb.shape[:2])
    try:
        sp = segment_pose(mask, image.depth, image.intrinsics)
    except InputError as e:
        return EpisodeResult(False, f"segment: {e}")
    # the seen surface lies one radius in front of the hose axis along the viewing ray
    ray = _camera_to_world(T, sp.centre / np.linalg.norm(sp.centre), direction=True)
    centre = _camera_to_world(T, sp.centre) + cfg.grasp.surface_offset * ray
    axis = _camera_to_world(T, sp.axis, direction=True)
    hose = _hose_under(camera, mask, cfg.hose) if cfg.capture.ground_truth else cfg.hose
    say(f"segment: {int(mask.sum())} px, centre {np.round(centre, 3)}, hose {hose}")
    result = EpisodeResult(False, hose=hose, centre=centre, axis=axis)

    # 2. grasp (or bring the closed gripper in front of the hose for a push)
    t0 = time.perf_counter()
    if cfg.kind == "grasp":
        g = prim.grasp_at(
            robot,
            centre,
            axis,
            cfg.grasp,
            approach,
            hose_point=lambda pose: _hose_point(world, pose, hose),
        )
    else:
        g = prim.approach_for_push(robot, centre, axis, cfg.grasp, approach)
    result.timings["grasp"] = time.perf_counter() - t0
    result.details["grasp"] = g.details
    if not g:
        say(f"failed: {g.reason}")
        moved = not g.reason.startswith(("grasp:", "push:"))  # those fail before moving
        return _abort(result, robot, world, cfg, g.reason, say, moved=moved)
    result.grasp = g.pose
    assert g.pose is not None
    say(
        f"{'grasped' if cfg.kind == 'grasp' else 'at'} hose at {np.round(g.pose.position, 3)} "
        f"({json.dumps(_jsonable(g.details))})"
    )

    # 3. actions, camera triggered on simulated time
    hp = None
    if hose is not None:
        hp, _ = HosePoint.nearest(world, g.pose.position, hose)
    log = MotionLog(hose_point=hp)
    collector = FrameCollector(
        camera,
        robot,
        cfg.capture.min_gripper_step,
        cfg.capture.ground_truth,
        hose,
        sink,
        on_tick=lambda a, t: log.record(a, t, robot.ee_pose().position, world),
    )
    if cfg.kind == "grasp":
        directions = prim.action_directions(cfg.actions, axis, T, approach)
    else:
        directions = [("push", approach)]
    t0 = time.perf_counter()
    for a, (label, u) in enumerate(directions):
        collector.begin_action(a)
        with SimTrigger(world, collector.on_frame, cfg.capture.frame_rate):
            if cfg.kind == "grasp":
                r = prim.periodic_action(
                    robot,
                    g.pose,
                    u,
                    cfg.actions.amplitude,
                    cfg.actions.periods,
                    cfg.actions.speed,
                    cfg.actions.stroke_tolerance,
                )
            else:
                r = prim.push(
                    robot,
                    g.pose,
                    u,
                    cfg.push_depth,
                    cfg.actions.periods,
                    cfg.actions.speed,
                    cfg.actions.stroke_tolerance,
                )
        collector.end_action()
        kept = len([f for f in collector.frames if f.action == a])
        gain, r2 = log.follow_gain(a, u) if cfg.kind == "grasp" else (math.nan, math.nan)
        rep = ActionReport(
            label, u, len(log.times.get(a, [])), kept, gain, r2, log.hose_displacement(a)
        )
        result.actions.append(rep)
        if r.details.get("short_strokes"):
            result.details[f"action{a}_short_strokes_m"] = r.details["short_strokes"]
        say(f"action {a} ({label}): {kept}/{rep.ticks} frames kept, gain {gain:.3f}")
        if not r:
            return _abort(result, robot, world, cfg, f"action {a} ({label}): {r.reason}", say)
    result.timings["actions"] = time.perf_counter() - t0

    # 4. release, out of view, settle, target frame
    t0 = time.perf_counter()
    r = prim.release(robot, cfg.grasp.open_width)
    if not r:
        return _abort(result, robot, world, cfg, r.reason, say)
    r = prim.retreat(
        robot,
        cfg.retreat.joint_target(getattr(world, "cfg", None)),
        cfg.retreat,
        approach,
        cfg.grasp.travel_speed,
    )
    if not r:
        return _fail(result, r.reason, say)
    settled, speed = settle_hoses(
        world, cfg.retreat.settle_speed, cfg.retreat.settle_max_time, cfg.retreat.settle_check_every
    )
    result.settle_speed = speed
    if not settled:
        say(f"warning: hoses still move at {speed * 1000:.2f} mm/s after settling")
    target = collector.capture_target(world.time)
    result.timings["retreat"] = time.perf_counter() - t0
    if target.truth is not None:
        result.target_robot_pixels = int((target.truth.labels == LABEL_ROBOT).sum())
        if cfg.retreat.verify and result.target_robot_pixels:
            return _fail(
                result,
                f"the robot is visible in the target frame ({result.target_robot_pixels} pixels)",
                say,
            )

    # 5. ground truth flow from the target to each kept frame
    say(f"target frame captured; ground-truth flow for {len(collector.frames) - 1} frames")
    collector.add_flows(say)
    meta = _stream_meta(cfg, result, directions)
    meta["T_world_camera"] = T.tolist()
    result.stream = Stream(collector.frames, meta=meta)
    result.success = True
    total = time.perf_counter() - t_start
    result.timings.update(
        total=total,
        rendering=collector.render_time,
        ground_truth=collector.truth_time,
        physics_control=total - collector.render_time - collector.truth_time,
    )
    result.details["ticks"] = collector.ticks
    say(f"done in {total:.1f} s")
    return result


def _hose_under(camera: Camera, mask: np.ndarray, fallback: int | None) -> int | None:
    """The hose index most of the segment's pixels show (ground-truth labels)."""
    if not hasattr(camera, "render_labels"):
        return fallback
    labels = camera.render_labels()  # type: ignore[attr-defined]
    ids = labels[mask]
    ids = ids[ids >= 0]
    if len(ids) == 0:
        return fallback
    return int(np.bincount(ids).argmax())


def _hose_point(world: Any, pose: Pose, hose: int | None) -> Callable[[], np.ndarray] | None:
    hp, dist = HosePoint.nearest(world, pose.position, hose)
    return hp.position if dist <= GRASP_MAX_DISTANCE else None


def _stream_meta(
    cfg: EpisodeConfig, result: EpisodeResult, directions: list[tuple[str, np.ndarray]]
) -> dict[str, Any]:
    return {
        "source": "cablesim",
        "seed": cfg.seed,
        "kind": cfg.kind,
        "hose": result.hose,
        "action_labels": [d[0] for d in directions],
        "action_directions_world": [[float(x) for x in d[1]] for d in directions],
        "grasp_world": None if result.grasp is None else [float(x) for x in result.grasp.position],
        "config": cfg.to_dict(),
    }


def _fail(result: EpisodeResult, reason: str, say: Callable[[str], None]) -> EpisodeResult:
    result.success, result.reason, result.stream = False, reason, None
    say(f"failed: {reason}")
    return result


def _abort(
    result: EpisodeResult,
    robot: Robot,
    world: Any,
    cfg: EpisodeConfig,
    reason: str,
    say: Callable[[str], None],
    moved: bool = True,
) -> EpisodeResult:
    """Leave the scene clean (open, retreat) after a failure, then report it."""
    if moved:
        prim.release(robot, cfg.grasp.open_width)
        r = prim.retreat(
            robot,
            cfg.retreat.joint_target(getattr(world, "cfg", None)),
            cfg.retreat,
            prim.DEFAULT_APPROACH,
            cfg.grasp.travel_speed,
        )
        if not r:
            reason += f"; retreat after the failure failed too ({r.reason})"
    return _fail(result, reason, say)
