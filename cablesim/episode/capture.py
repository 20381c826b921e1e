"""Turning camera ticks into the frames of a stream (SPEC sections 2, 3.5, 6).

:class:`FrameCollector` is called at every camera tick during an action.  It reads the
gripper position in the camera frame from the robot and keeps the tick only when the gripper
moved at least ``min_gripper_step`` since the last kept sample of the action (the same rule
as :func:`cablesim.perception.subsample_by_gripper`); only kept ticks are rendered.  With a
:class:`~cablesim.sim.camera.SimCamera` and ``ground_truth=True`` each kept frame carries
labels, and, once the target frame exists, the ground-truth flow *from the target frame to it*
(``FrameTruth.flow_to_target``: target pixel p shows the point that is at p + flow in the
frame, computed by ``cablesim.sim.flow_gt.flow_to_target``).  Snapshots are kept only until
the flow is computed.

Each finished frame goes to ``sink`` (e.g. a recording writer) as soon as it is complete: action
frames at capture time (without flow), the target frame, then the flows.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from cablesim.camera.base import Camera
from cablesim.perception.frames import TARGET_ACTION, Frame, FrameTruth
from cablesim.robot.base import Robot


class FrameSink(Protocol):
    def add_frame(self, index: int, frame: Frame) -> None: ...

    def add_flow(self, index: int, flow: np.ndarray, valid: np.ndarray) -> None: ...


class FrameCollector:
    """Collects the kept frames of the actions and the target frame of one interaction."""

    def __init__(
        self,
        camera: Camera,
        robot: Robot,
        min_gripper_step: float = 0.001,
        ground_truth: bool = True,
        grasped_hose: int | None = None,
        sink: FrameSink | None = None,
        on_tick: Callable[[int, float], None] | None = None,
    ):
        self.camera = camera
        self.robot = robot
        self.min_step = float(min_gripper_step)
        self.ground_truth = bool(ground_truth) and hasattr(camera, "snapshot")
        self.grasped_hose = grasped_hose
        self.sink = sink
        self.on_tick = on_tick
        self.frames: list[Frame] = []
        self._snaps: list[Any] = []
        self.action: int | None = None
        self._sample = 0
        self._last: np.ndarray | None = None
        self.ticks = 0
        self.render_time = 0.0
        self.truth_time = 0.0

    # ------------------------------------------------------------------ actions
    def begin_action(self, action: int) -> None:
        self.action, self._sample, self._last = int(action), 0, None

    def end_action(self) -> None:
        self.action = None

    def on_frame(self, sim_time: float) -> None:
        """A camera tick at simulated time ``sim_time``."""
        if self.action is None:
            return
        self.ticks += 1
        if self.on_tick is not None:
            self.on_tick(self.action, sim_time)
        tcp = self.robot.ee_pose_camera()
        g = tcp.position
        if self._last is not None and np.linalg.norm(g - self._last) < self.min_step:
            return
        self._last = g
        frame = self._capture(self.action, self._sample, sim_time)
        self._sample += 1
        self._emit(frame)

    # ------------------------------------------------------------------ target
    def capture_target(self, sim_time: float) -> Frame:
        frame = self._capture(TARGET_ACTION, 0, sim_time)
        self._emit(frame)
        return frame

    def add_flows(self, progress: Callable[[str], None] | None = None) -> None:
        """Ground-truth flow from the target (the last captured frame) to every action frame."""
        if not self.ground_truth or not self.frames or not self.frames[-1].is_target:
            return
        from cablesim.sim.flow_gt import flow_to_target

        target_snap = self._snaps[-1]
        n = len(self.frames) - 1
        for i, (frame, snap) in enumerate(zip(self.frames[:-1], self._snaps[:-1], strict=True)):
            t0 = time.perf_counter()
            gt = flow_to_target(snap, target_snap)
            self.truth_time += time.perf_counter() - t0
            assert frame.truth is not None
            frame.truth.flow_to_target = gt.flow
            frame.truth.flow_valid = gt.valid
            if self.sink is not None:
                self.sink.add_flow(i, gt.flow, gt.valid)
            self._snaps[i] = None
            if progress is not None and (i + 1) % 25 == 0:
                progress(f"ground-truth flow {i + 1}/{n}")
        last = self.frames[-1]
        assert last.truth is not None
        h, w = last.shape
        last.truth.flow_to_target = np.zeros((h, w, 2), np.float32)
        last.truth.flow_valid = np.ones((h, w), bool)
        self._snaps = []

    # ------------------------------------------------------------------ internals
    def _capture(self, action: int, sample: int, sim_time: float) -> Frame:
        tcp = self.robot.ee_pose_camera()
        truth = None
        t0 = time.perf_counter()
        if self.ground_truth:
            snap = self.camera.snapshot()  # type: ignore[attr-defined]
            image = snap.image
            truth = FrameTruth(labels=snap.labels, grasped_hose=self.grasped_hose)
            self._snaps.append(snap)
        else:
            image = self.camera.capture()
        self.render_time += time.perf_counter() - t0
        return Frame(
            rgb=image.rgb,
            depth=image.depth,
            intrinsics=image.intrinsics,
            gripper=tcp.position,
            action=action,
            sample=sample,
            timestamp=float(sim_time),
            gripper_quat=tcp.quaternion,
            gripper_opening=float(self.robot.gripper_opening),
            truth=truth,
        )

    def _emit(self, frame: Frame) -> None:
        self.frames.append(frame)
        if self.sink is not None:
            self.sink.add_frame(len(self.frames) - 1, frame)
