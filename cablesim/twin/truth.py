"""Ground truth of the digital twin: the runner's :class:`~cablesim.episode.truth.TruthProvider`.

Everything comes from the twin's published states and rendered frames (never from its live
MuJoCo data, which the twin thread keeps stepping):

- ``hose_under``: labels of the latest rendered frame under the segment;
- ``grasp_probe``: waits until the twin has caught up with the robot (measurements applied,
  arm within tolerance, fingers at rest on whatever they closed on), then follows the material
  hose point nearest the grasp pose (within ``GRASP_MAX_DISTANCE``); the runner's hold check
  compares its motion with the robot's;
- ``on_tick`` / ``action_truth``: per camera frame the twin's TCP, the grasped hose point and
  every hose's vertices; the follow gain is the slope of the hose point's displacement on the
  twin TCP's along the action direction (how well the hose followed the gripper *in the twin*).
  Also recorded: the gain against the measured (robot) gripper, and per frame the *pairing
  error* -- the distance between the gripper position the clock paired with the frame and the
  twin TCP the frame shows -- and the frame's latency: from the instant it shows (its twin
  time) to its arrival at the clock;
- ``frame_truth``: the labels of the very frame, found by its timestamp (the twin stamps the
  frames it feeds to the camera);
- ``finish``: ground-truth flow from the target frame to every kept frame, from the frames'
  snapshots (as in pure simulation).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.camera.base import CameraImage
from cablesim.episode.clock import Tick
from cablesim.episode.truth import ActionTruth, FrameSink, HosePointProbe
from cablesim.frames import Frame, FrameTruth
from cablesim.pose import Pose
from cablesim.sim.flow_gt import flow_to_target
from cablesim.sim.truth import GRASP_MAX_DISTANCE, MotionLog


@dataclass(frozen=True)
class HosePointRef:
    """Point at parameter ``tau`` of edge ``edge`` of hose ``hose`` (in vertex snapshots)."""

    hose: int
    edge: int
    tau: float

    def position(self, vertices: Sequence[np.ndarray]) -> np.ndarray:
        v = vertices[self.hose]
        return v[self.edge] + self.tau * (v[self.edge + 1] - v[self.edge])

    @staticmethod
    def nearest(
        vertices: Sequence[np.ndarray], point: np.ndarray, hose: int | None = None
    ) -> tuple[HosePointRef, float]:
        p = np.asarray(point, dtype=float)
        best: tuple[HosePointRef, float] | None = None
        for h in range(len(vertices)) if hose is None else (hose,):
            v = vertices[h]
            a, ab = v[:-1], v[1:] - v[:-1]
            t = np.clip(
                np.einsum("ij,ij->i", p - a, ab) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1
            )
            d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
            e = int(np.argmin(d))
            if best is None or d[e] < best[1]:
                best = (HosePointRef(h, e, float(t[e])), float(d[e]))
        assert best is not None
        return best


@dataclass
class TwinTruthReport:
    """Diagnostics of the twin's ground truth over one interaction."""

    gain: dict[int, float] = field(default_factory=dict)  # hose point vs twin TCP
    gain_r2: dict[int, float] = field(default_factory=dict)
    gain_measured: dict[int, float] = field(default_factory=dict)  # vs the robot's gripper
    pairing_mm: list[float] = field(default_factory=list)  # paired pose vs the frame's TCP
    latency_ms: list[float] = field(default_factory=list)  # shown state -> frame arrived
    grasp_hose_mm: float = float("nan")  # nearest hose point to the commanded grasp pose
    grasp_tcp_mm: float = float("nan")  # twin TCP to the commanded grasp pose, when closed
    grasp_opening_mm: float = float("nan")  # twin finger opening, when closed
    unlabelled_frames: int = 0  # frames no longer (or never) kept by the twin
    sync_timeouts: int = 0  # the twin did not catch up with the robot in time

    def summary(self) -> dict[str, Any]:
        p, lat = np.asarray(self.pairing_mm, float), np.asarray(self.latency_ms, float)

        def stats(x: np.ndarray) -> dict[str, float]:
            if not x.size:
                return {}
            return {
                "median": float(np.median(x)),
                "p95": float(np.percentile(x, 95)),
                "max": float(x.max()),
            }

        return {
            "gain": self.gain,
            "gain_r2": self.gain_r2,
            "gain_vs_measured_gripper": self.gain_measured,
            "pairing_error_mm": stats(p),
            "frame_latency_ms": stats(lat),
            "grasp_hose_mm": self.grasp_hose_mm,
            "grasp_tcp_mm": self.grasp_tcp_mm,
            "grasp_opening_mm": self.grasp_opening_mm,
            "unlabelled_frames": self.unlabelled_frames,
            "sync_timeouts": self.sync_timeouts,
        }


class TwinTruth:
    """Ground truth of a :class:`~cablesim.twin.world.TwinWorld` (module docstring)."""

    def __init__(
        self, twin: Any, sync_timeout: float = 30.0, joint_tolerance: float = 0.003
    ) -> None:
        self.twin = twin
        self.sync_timeout = float(sync_timeout)
        self.joint_tolerance = float(joint_tolerance)
        self.hose: int | None = None
        self.point: HosePointRef | None = None
        self.log = MotionLog()
        self.measured = MotionLog()
        self.report = TwinTruthReport()
        self._snaps: list[Any] = []
        self._label = True  # whether the next frame is labelled (label_next)

    def _synced(self) -> Any:
        state, ok = self.twin.synced(self.sync_timeout, self.joint_tolerance)
        if not ok:
            self.report.sync_timeouts += 1
        return state

    # ---- TruthProvider ------------------------------------------------------------------
    def hose_under(self, mask: np.ndarray) -> int | None:
        frame = self.twin.latest_frame()
        if frame is not None:
            labels = frame.snapshot.labels
        else:
            labels = self.twin.call(lambda t: t.camera.render_labels())
        ids = labels[np.asarray(mask, bool)]
        ids = ids[ids >= 0]
        return int(np.bincount(ids).argmax()) if len(ids) else None

    def grasp_probe(self, pose: Pose, hose: int | None) -> HosePointProbe | None:
        state = self._synced()
        ref, dist = HosePointRef.nearest(state.hose_vertices, pose.position, hose)
        self.report.grasp_hose_mm = 1000.0 * dist
        self.report.grasp_tcp_mm = 1000.0 * float(np.linalg.norm(state.tcp - pose.position))
        self.report.grasp_opening_mm = 1000.0 * state.opening
        if dist > GRASP_MAX_DISTANCE:
            return None

        def probe() -> np.ndarray:
            return ref.position(self._synced().hose_vertices)

        return probe

    def label_next(self, on: bool) -> None:
        self._label = bool(on)

    def begin_interaction(self, hose: int | None, grasp: Pose | None) -> None:
        self.hose = hose
        self._snaps, self._label = [], True
        self.point = None
        if hose is not None and grasp is not None:
            self.point, _ = HosePointRef.nearest(self._synced().hose_vertices, grasp.position, hose)
        self.log, self.measured = MotionLog(), MotionLog()
        grasp = self.report
        self.report = TwinTruthReport(
            grasp_hose_mm=grasp.grasp_hose_mm,
            grasp_tcp_mm=grasp.grasp_tcp_mm,
            grasp_opening_mm=grasp.grasp_opening_mm,
            sync_timeouts=grasp.sync_timeouts,
        )

    def on_tick(self, action: int, tick: Tick) -> None:
        state = self.twin.state()
        verts = list(state.hose_vertices)
        for log, gripper in ((self.log, state.tcp), (self.measured, tick.gripper.position)):
            log.times.setdefault(action, []).append(float(tick.time))
            log.gripper.setdefault(action, []).append(np.asarray(gripper, float).copy())
            log.vertices.setdefault(action, []).append(verts)
            if self.point is not None:
                log.point.setdefault(action, []).append(self.point.position(verts))
        if tick.frame is not None:
            frame = self.twin.frame_at(tick.frame.timestamp)
            if frame is not None:
                err = np.linalg.norm(np.asarray(tick.gripper.position) - frame.state.tcp)
                self.report.pairing_mm.append(1000.0 * float(err))
                self.report.latency_ms.append(1000.0 * (time.monotonic() - frame.twin_time))

    def action_truth(self, action: int, direction: np.ndarray) -> ActionTruth:
        gain, r2 = self.log.follow_gain(action, direction)
        self.report.gain[action], self.report.gain_r2[action] = gain, r2
        self.report.gain_measured[action] = self.measured.follow_gain(action, direction)[0]
        return ActionTruth(gain, r2, self.log.hose_displacement(action))

    def frame_truth(self, image: CameraImage) -> FrameTruth | None:
        if not self._label:
            self._snaps.append(None)
            return None
        frame = self.twin.frame_at(image.timestamp)
        if frame is None:
            self.report.unlabelled_frames += 1
            self._snaps.append(None)
            return None
        self._snaps.append(frame.snapshot)
        return FrameTruth(labels=frame.snapshot.labels, grasped_hose=self.hose)

    def finish(
        self, frames: Sequence[Frame], sink: FrameSink | None, say: Callable[[str], None]
    ) -> float:
        """Ground-truth flow from the target (the last frame) to every earlier labelled one."""

        spent = 0.0
        if not frames or not frames[-1].is_target or len(self._snaps) != len(frames):
            return spent
        target_snap = self._snaps[-1]
        if target_snap is None:
            return spent
        for i, (frame, snap) in enumerate(zip(frames[:-1], self._snaps[:-1], strict=True)):
            if snap is None or frame.truth is None:
                continue
            t0 = time.perf_counter()
            gt = flow_to_target(snap, target_snap)
            spent += time.perf_counter() - t0
            frame.truth.flow_to_target = gt.flow
            frame.truth.flow_valid = gt.valid
            if sink is not None:
                sink.add_flow(i, gt.flow, gt.valid)
            self._snaps[i] = None
        last = frames[-1]
        assert last.truth is not None
        h, w = last.shape
        last.truth.flow_to_target = np.zeros((h, w, 2), np.float32)
        last.truth.flow_valid = np.ones((h, w), bool)
        self._snaps = []
        return spent


__all__ = ["HosePointRef", "TwinTruth", "TwinTruthReport"]
