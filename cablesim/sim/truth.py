"""Simulation-only measurements of an interaction (ground truth, for verification/evaluation).

- :class:`HosePoint`: a material point of a hose (edge + parameter along it) followed through
  the simulation: "the hose point under the fingers".
- :class:`MotionLog`: per camera tick, the gripper position, the grasped hose point and every
  hose's vertices; :meth:`MotionLog.follow_gain` regresses the hose point's displacement on the
  gripper's along the action direction, :meth:`MotionLog.hose_displacement` is the largest
  vertex displacement of each hose since the action started.
- :class:`SimTruth`: the :class:`~cablesim.episode.truth.TruthProvider` of a simulated world
  (the runner's access to all of the above, labels and ground-truth flow).
"""

from __future__ import annotations

import math
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

#: A hose farther than this from the closed hand is not held (simulation check).
GRASP_MAX_DISTANCE = 0.02


@dataclass(frozen=True)
class HosePoint:
    """Point at parameter ``tau`` of edge ``edge`` (vertex edge -> edge+1) of hose ``hose``."""

    world: Any
    hose: int
    edge: int
    tau: float

    def position(self) -> np.ndarray:
        v = self.world.hose_vertices(self.hose)
        return v[self.edge] + self.tau * (v[self.edge + 1] - v[self.edge])

    __call__ = position

    @staticmethod
    def nearest(world: Any, point: np.ndarray, hose: int | None = None) -> tuple[HosePoint, float]:
        """The hose point nearest to world ``point`` (of hose ``hose``, or of any hose) and
        its distance."""
        p = np.asarray(point, dtype=float)
        best: tuple[HosePoint, float] | None = None
        hoses = range(len(world.hoses)) if hose is None else (hose,)
        for h in hoses:
            v = world.hose_vertices(h)
            a, b = v[:-1], v[1:]
            ab = b - a
            t = np.clip(
                np.einsum("ij,ij->i", p - a, ab) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1
            )
            d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
            e = int(np.argmin(d))
            if best is None or d[e] < best[1]:
                best = (HosePoint(world, h, e, float(t[e])), float(d[e]))
        assert best is not None
        return best


@dataclass
class MotionLog:
    """Gripper and hose positions (world) at every camera tick of each action."""

    hose_point: HosePoint | None = None
    times: dict[int, list[float]] = field(default_factory=dict)
    gripper: dict[int, list[np.ndarray]] = field(default_factory=dict)
    point: dict[int, list[np.ndarray]] = field(default_factory=dict)
    vertices: dict[int, list[list[np.ndarray]]] = field(default_factory=dict)

    def record(self, action: int, time: float, gripper_world: np.ndarray, world: Any) -> None:
        self.times.setdefault(action, []).append(float(time))
        self.gripper.setdefault(action, []).append(np.asarray(gripper_world, float).copy())
        if self.hose_point is not None:
            self.point.setdefault(action, []).append(self.hose_point.position())
        verts = [world.hose_vertices(i) for i in range(len(world.hoses))]
        self.vertices.setdefault(action, []).append(verts)

    def follow_gain(self, action: int, direction: np.ndarray) -> tuple[float, float]:
        """(gain, R^2): least-squares slope of the hose point's displacement on the gripper's,
        both projected on ``direction``, over the action's ticks."""
        if action not in self.point or len(self.point[action]) < 3:
            return math.nan, math.nan
        u = np.asarray(direction, float) / np.linalg.norm(direction)
        g = np.asarray(self.gripper[action])
        p = np.asarray(self.point[action])
        x = (g - g[0]) @ u
        y = (p - p[0]) @ u
        xc, yc = x - x.mean(), y - y.mean()
        sxx = float(xc @ xc)
        if sxx <= 1e-12:
            return math.nan, math.nan
        gain = float(xc @ yc) / sxx
        syy = float(yc @ yc)
        r2 = (float(xc @ yc) ** 2 / (sxx * syy)) if syy > 0 else math.nan
        return gain, r2

    def hose_displacement(self, action: int) -> list[float]:
        """Largest displacement (m) of any vertex of each hose from the action's first tick."""
        ticks = self.vertices.get(action, [])
        if not ticks:
            return []
        out = []
        for h in range(len(ticks[0])):
            v0 = ticks[0][h]
            out.append(max(float(np.linalg.norm(t[h] - v0, axis=1).max()) for t in ticks))
        return out


class SimTruth:
    """Ground truth of a simulated world seen by a :class:`~cablesim.sim.camera.SimCamera`.

    ``capture()`` is the clock's frame grabber when ground truth is on: it renders RGB, depth
    and labels of the current state and keeps the snapshot, which ``frame_truth`` then turns
    into the frame's labels and ``finish`` into ground-truth flow to the target frame.
    """

    def __init__(self, world: Any, camera: Any) -> None:
        self.world = world
        self.camera = camera
        self.hose: int | None = None
        self.log = MotionLog()
        self._pending: dict[int, Any] = {}  # id(image) -> snapshot, until frame_truth
        self._snaps: list[Any] = []  # snapshots of the frames, in order (None: unlabelled)
        self._label = True  # whether the next grabbed image is labelled (label_next)
        # keep the snapshots of the last interaction's frames in ``kept`` (flow between any
        # two of its frames afterwards, e.g. back to the first one for MovingCables clips)
        self.keep_snapshots = False
        self.kept: list[Any] = []

    # ---- the clock's grabber ------------------------------------------------------------
    def capture(self) -> CameraImage:
        if not self._label:  # the same image, without the label pass
            return self.camera.capture_unlabelled()
        snap = self.camera.snapshot()
        self._pending[id(snap.image)] = snap
        return snap.image

    # ---- TruthProvider ------------------------------------------------------------------
    def hose_under(self, mask: np.ndarray) -> int | None:
        ids = self.camera.render_labels()[mask]
        ids = ids[ids >= 0]
        return int(np.bincount(ids).argmax()) if len(ids) else None

    def grasp_probe(self, pose: Pose, hose: int | None) -> HosePointProbe | None:
        hp, dist = HosePoint.nearest(self.world, pose.position, hose)
        return hp.position if dist <= GRASP_MAX_DISTANCE else None

    def label_next(self, on: bool) -> None:
        self._label = bool(on)

    def begin_interaction(self, hose: int | None, grasp: Pose | None) -> None:
        self.hose = hose
        self._pending, self._snaps, self._label = {}, [], True
        hp = None
        if hose is not None and grasp is not None:
            hp, _ = HosePoint.nearest(self.world, grasp.position, hose)
        self.log = MotionLog(hose_point=hp)

    def on_tick(self, action: int, tick: Tick) -> None:
        self.log.record(action, tick.time, tick.gripper.position, self.world)

    def action_truth(self, action: int, direction: np.ndarray) -> ActionTruth:
        gain, r2 = self.log.follow_gain(action, direction)
        return ActionTruth(gain, r2, self.log.hose_displacement(action))

    def frame_truth(self, image: CameraImage) -> FrameTruth | None:
        if not self._label:
            self._snaps.append(None)
            return None
        snap = self._pending.pop(id(image), None)
        if snap is None:  # a frame grabbed without this provider: label the current state
            snap = self.camera.snapshot_of(image)
        self._snaps.append(snap)
        return FrameTruth(labels=snap.labels, grasped_hose=self.hose)

    def finish(
        self, frames: Sequence[Frame], sink: FrameSink | None, say: Callable[[str], None]
    ) -> float:
        """Ground-truth flow from the target (the last frame) to every earlier labelled
        frame."""

        spent = 0.0
        self.kept = list(self._snaps) if self.keep_snapshots else []
        if not frames or not frames[-1].is_target or len(self._snaps) != len(frames):
            return spent
        target_snap = self._snaps[-1]
        if target_snap is None:
            return spent
        n = len(frames) - 1
        for i, (frame, snap) in enumerate(zip(frames[:-1], self._snaps[:-1], strict=True)):
            if snap is None:
                continue
            t0 = time.perf_counter()
            gt = flow_to_target(snap, target_snap)
            spent += time.perf_counter() - t0
            assert frame.truth is not None
            frame.truth.flow_to_target = gt.flow
            frame.truth.flow_valid = gt.valid
            if sink is not None:
                sink.add_flow(i, gt.flow, gt.valid)
            self._snaps[i] = None
            if (i + 1) % 25 == 0:
                say(f"ground-truth flow {i + 1}/{n}")
        last = frames[-1]
        assert last.truth is not None
        h, w = last.shape
        last.truth.flow_to_target = np.zeros((h, w, 2), np.float32)
        last.truth.flow_valid = np.ones((h, w), bool)
        self._snaps = []
        return spent
