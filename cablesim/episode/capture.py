"""Turning the clock's ticks into the frames of a stream (SPEC sections 2, 3.5, 6).

:class:`FrameCollector` receives every tick of the clock during an action.  It converts the
tick's gripper pose into the camera frame and keeps the tick only when the gripper moved at
least ``min_gripper_step`` since the last kept sample of the action (the same rule as
:func:`cablesim.perception.subsample_by_gripper`); only kept ticks grab their image.  With a
ground-truth provider the kept frames carry labels, and, once the target frame exists,
ground-truth flow *from the target frame to them* (``FrameTruth.flow_to_target``): every
kept frame, or with ``truth_every`` n > 1 the first kept frame of each action, every n-th
after it and the target frame (the others' ``Frame.truth`` is None; their images are the same).

Each finished frame goes to ``sink`` (e.g. a recording writer) as soon as it is complete: action
frames at capture time (without flow), the target frame, then the flows.  Ticks may arrive on
another thread (a real camera stream); the collector serialises them.

With an ``arm_mask`` function (``(tick) -> HxW bool``, e.g.
:meth:`cablesim.panda.arm_mask.ArmMasker.for_tick`: the arm model rendered at the tick's joint
state through the calibrated camera) every kept frame carries ``Frame.arm_mask``, computed the
same way for the simulated and the real robot.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from cablesim.camera.base import CameraImage
from cablesim.episode.clock import Tick
from cablesim.episode.truth import FrameSink, TruthProvider
from cablesim.frames import TARGET_ACTION, Frame
from cablesim.pose import Pose

#: ``(tick) -> HxW bool`` arm mask of the tick's joint state (see the module docstring)
ArmMaskFunction = Callable[[Tick], np.ndarray]


def pose_in_camera(T_world_camera: np.ndarray, pose: Pose) -> Pose:
    """A world pose in the camera frame."""
    return Pose.from_matrix(np.linalg.inv(T_world_camera) @ pose.matrix())


class FrameCollector:
    """Collects the kept frames of the actions and the target frame of one interaction."""

    def __init__(
        self,
        T_world_camera: np.ndarray,
        min_gripper_step: float = 0.001,
        truth: TruthProvider | None = None,
        sink: FrameSink | None = None,
        arm_mask: ArmMaskFunction | None = None,
        truth_every: int = 1,
    ):
        self.T = np.asarray(T_world_camera, float)
        self.min_step = float(min_gripper_step)
        self.truth = truth
        self.truth_every = max(1, int(truth_every))
        self.sink = sink
        self.arm_mask = arm_mask
        self.frames: list[Frame] = []
        self.action: int | None = None
        self._sample = 0
        self._last: np.ndarray | None = None
        self._lock = threading.Lock()
        self.ticks = 0
        self.skews: list[float] = []
        self.render_time = 0.0  # wall seconds spent grabbing (rendering) kept frames
        self.truth_time = 0.0  # wall seconds spent on ground truth (flow)
        self.render_cpu = 0.0  # the same in CPU seconds of this process
        self.truth_cpu = 0.0
        self.mask_time = 0.0

    # ------------------------------------------------------------------ actions
    def begin_action(self, action: int) -> None:
        self.action, self._sample, self._last = int(action), 0, None

    def end_action(self) -> None:
        with self._lock:
            self.action = None
            if self.truth is not None:
                self.truth.label_next(True)

    def kept(self, action: int) -> int:
        return sum(1 for f in self.frames if f.action == action)

    def on_tick(self, tick: Tick) -> None:
        """A camera tick during an action."""
        with self._lock:
            if self.action is None:
                return
            self.ticks += 1
            if self.truth is not None:
                self.truth.on_tick(self.action, tick)
            tcp = pose_in_camera(self.T, tick.gripper)
            if self._last is not None and np.linalg.norm(tcp.position - self._last) < self.min_step:
                return
            self._last = tcp.position
            if self.truth is not None:
                self.truth.label_next(self._sample % self.truth_every == 0)
            t0, c0 = time.perf_counter(), time.process_time()
            image = tick.image()
            self.render_time += time.perf_counter() - t0
            self.render_cpu += time.process_time() - c0
            self.skews.append(float(tick.skew))
            self._emit(self._frame(image, tcp, tick, self.action, self._sample))
            self._sample += 1

    # ------------------------------------------------------------------ target
    def capture_target(self, grab: Callable[[], CameraImage], tick: Tick) -> Frame:
        """The target frame: grabbed now, with the gripper state of ``tick``."""
        if self.truth is not None:
            self.truth.label_next(True)
        t0, c0 = time.perf_counter(), time.process_time()
        image = grab()
        self.render_time += time.perf_counter() - t0
        self.render_cpu += time.process_time() - c0
        tcp = pose_in_camera(self.T, tick.gripper)
        frame = self._frame(image, tcp, tick, TARGET_ACTION, 0)
        self._emit(frame)
        return frame

    def finish(self, say: Callable[[str], None]) -> None:
        """Ground-truth flow from the target frame to every action frame (with truth)."""
        if self.truth is not None:
            c0 = time.process_time()
            self.truth_time += self.truth.finish(self.frames, self.sink, say)
            self.truth_cpu += time.process_time() - c0

    # ------------------------------------------------------------------ internals
    def _frame(self, image: CameraImage, tcp: Pose, tick: Tick, action: int, sample: int) -> Frame:
        truth = None
        if self.truth is not None:
            t0, c0 = time.perf_counter(), time.process_time()
            truth = self.truth.frame_truth(image)
            self.render_time += time.perf_counter() - t0
            self.render_cpu += time.process_time() - c0
        mask = None
        if self.arm_mask is not None:
            t0 = time.perf_counter()
            mask = np.asarray(self.arm_mask(tick), dtype=bool)
            self.mask_time += time.perf_counter() - t0
        return Frame(
            rgb=image.rgb,
            depth=image.depth,
            intrinsics=image.intrinsics,
            gripper=tcp.position,
            action=action,
            sample=sample,
            timestamp=float(tick.time),
            gripper_quat=tcp.quaternion,
            gripper_opening=float(tick.opening),
            truth=truth,
            arm_mask=mask,
        )

    def _emit(self, frame: Frame) -> None:
        self.frames.append(frame)
        if self.sink is not None:
            self.sink.add_frame(len(self.frames) - 1, frame)
