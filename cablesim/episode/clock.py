"""Clocks: when the frames of an interaction are taken, and when the hoses are still.

The interaction runner moves the arm with blocking motions (as franky does) and records the
frames a clock delivers meanwhile.  A clock has four parts:

- ``now()``: its time in seconds (simulated time, or the host's monotonic clock);
- ``grab()``: one frame now (the target frame);
- ``streaming(on_tick)``: a context; while inside, ``on_tick(tick)`` is called for every camera
  frame, each :class:`Tick` with the gripper pose measured at (or nearest to) the frame's time;
- ``wait_still(cfg)``: wait until the hoses are still, a :class:`StillResult`.

:class:`~cablesim.sim.clock.SimClock` takes frames on simulated time through a world step hook
(the gripper pose is read at the same physics step, skew 0) and waits by settling the physics.
:class:`StreamClock` here serves real devices: the camera's own stream is read on a capture
thread while franky moves the arm, a second thread samples the robot's state, and each frame is
paired with the pose sample nearest its arrival time (the skew is recorded) -- or, when the
camera's timestamps tell when a frame was taken (``frame_time``), nearest that time: then the
stream holds the frames *taken* inside the ``streaming`` block, also those that arrive a little
after it (waiting at most ``drain`` s), and none taken before it.  The finger
opening is read on a third thread: a franky gripper read blocks until the hand's next state
packet (60 Hz on franka-sim), which would otherwise hold every pose sample back to that rate.
Stillness is judged from consecutive RGB and depth frames.
"""

from __future__ import annotations

import bisect
import contextlib
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from cablesim.camera.base import Camera, CameraImage
from cablesim.errors import InputError
from cablesim.pose import Pose
from cablesim.robot.base import Robot


@dataclass
class Tick:
    """One camera frame of the stream and the gripper state that goes with it."""

    time: float  # the frame's time on the clock (s)
    gripper: Pose  # TCP pose (world) measured at, or nearest to, ``time``
    opening: float  # finger opening (m)
    joints: np.ndarray  # (7,) arm joints (rad)
    skew: float = 0.0  # s between the frame and the pose measurement
    grab: Callable[[], CameraImage] | None = None  # how to get the frame (lazily: sim)
    frame: CameraImage | None = None  # the frame, when it already exists (camera stream)

    def image(self) -> CameraImage:
        if self.frame is None:
            if self.grab is None:
                raise InputError("a tick without a frame and without a way to grab one")
            self.frame = self.grab()
        return self.frame


@dataclass
class StillResult:
    """Outcome of waiting for the hoses to come to rest."""

    still: bool
    measure: float  # the last measured motion (m/s of the fastest hose vertex in simulation,
    # mean grey-level change between frames on a camera)
    waited: float  # s
    description: str = ""

    def __bool__(self) -> bool:
        return self.still


class Clock(Protocol):
    """What the interaction runner needs from a clock (see the module docstring)."""

    def now(self) -> float: ...

    def grab(self) -> CameraImage: ...

    def streaming(self, on_tick: Callable[[Tick], None]) -> contextlib.AbstractContextManager: ...

    def wait_still(self, cfg) -> StillResult: ...


# ---------------------------------------------------------------------- planning
class PlanningClock:
    """The clock of a dry run: no frames while the (virtual) arm moves, nothing to wait for;
    ``grab`` reads the camera."""

    def __init__(self, camera: Camera) -> None:
        self.camera = camera
        self._t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._t0

    def grab(self) -> CameraImage:
        return self.camera.capture()

    @contextlib.contextmanager
    def streaming(self, on_tick: Callable[[Tick], None]) -> Iterator[None]:
        yield

    def wait_still(self, cfg) -> StillResult:
        return StillResult(True, 0.0, 0.0, "dry run: nothing moved")


# ---------------------------------------------------------------------- real devices
@dataclass
class _PoseSample:
    time: float
    pose: Pose
    opening: float
    joints: np.ndarray


@dataclass
class StreamStats:
    """What a :class:`StreamClock` measured while streaming."""

    frames: int = 0
    skews: list[float] = field(default_factory=list)
    opening_read_failures: int = 0  # gripper reads that failed and kept the last opening

    def summary(self) -> dict[str, float]:
        s = np.asarray(self.skews, float)
        out: dict[str, float] = {"frames": self.frames}
        if s.size:
            out.update(skew_median_s=float(np.median(s)), skew_max_s=float(s.max()))
        if self.opening_read_failures:
            out["opening_read_failures"] = self.opening_read_failures
        return out


def frame_change(a: CameraImage, b: CameraImage, depth_threshold: float) -> tuple[float, float]:
    """(mean absolute grey-level change, fraction of pixels valid in both whose depth changed
    by more than ``depth_threshold``) between two frames."""
    ga = a.rgb.astype(np.float32).mean(axis=2)
    gb = b.rgb.astype(np.float32).mean(axis=2)
    rgb = float(np.abs(ga - gb).mean())
    da, db = a.depth, b.depth
    valid = (da > 0) & (db > 0) & np.isfinite(da) & np.isfinite(db)
    n = int(valid.sum())
    moved = float(np.count_nonzero(np.abs(da[valid] - db[valid]) > depth_threshold)) / max(n, 1)
    return rgb, moved


class StreamClock:
    """Frames from the camera's own stream while the robot moves (see the module docstring).

    ``pose_rate``: how often the robot state is sampled (Hz).  The camera's ``capture()`` must
    block until its next frame (a RealSense does).  ``history``: seconds of pose samples kept.
    ``frame_time``: when a frame was taken, on this clock (``time.monotonic()``), from its
    image (e.g. from the camera's timestamps); None: when it arrived.  ``drain``: with
    ``frame_time``, how long to wait after the block for the frames taken inside it.
    ``opening_patience``: how long (s) reads of the gripper's opening may keep failing while
    streaming before the failure ends the block; until then a failed read keeps the last
    opening (it is sampled for the frames' poses, nothing moves on it) and is counted in
    ``stats.opening_read_failures``.  A gripper's state server starved by a loaded host fails
    a read now and then (libfranka's ``Net Exception``, seen on franka-sim at load 6 on two
    cores) and answers the next.
    """

    def __init__(
        self,
        robot: Robot,
        camera: Camera,
        pose_rate: float = 250.0,
        history: float = 10.0,
        frame_time: Callable[[CameraImage], float] | None = None,
        drain: float = 2.0,
        opening_patience: float = 2.0,
    ) -> None:
        if not pose_rate > 0:
            raise InputError(f"pose_rate must be > 0, got {pose_rate}")
        if not opening_patience >= 0:
            raise InputError(f"opening_patience must be >= 0 s, got {opening_patience}")
        self.opening_patience = float(opening_patience)
        self.robot = robot
        self.camera = camera
        self.pose_period = 1.0 / float(pose_rate)
        self.history = float(history)
        self.frame_time = frame_time
        self.drain = float(drain)
        self.stats = StreamStats()

    def now(self) -> float:
        return time.monotonic()

    def grab(self) -> CameraImage:
        """The next frame; with ``frame_time`` the first one taken after this call (waiting at
        most ``drain`` s for it)."""
        if self.frame_time is None:
            return self.camera.capture()
        t = self.now()
        while True:
            image = self.camera.capture()
            if float(self.frame_time(image)) >= t or self.now() - t > self.drain:
                return image

    def _sample(self, opening: float) -> _PoseSample:
        """The arm's state now, timed at the middle of the reads."""
        r = self.robot
        t0 = self.now()
        pose, joints = r.ee_pose(), r.joint_positions
        return _PoseSample(0.5 * (t0 + self.now()), pose, opening, joints)

    @contextlib.contextmanager
    def streaming(self, on_tick: Callable[[Tick], None]) -> Iterator[None]:
        stop = threading.Event()  # the pose samplers
        stop_frames = threading.Event()
        begin, end = self.now(), [math.inf]
        lock = threading.Lock()
        opening = [float(self.robot.gripper_opening)]
        samples: list[_PoseSample] = [self._sample(opening[0])]
        errors: list[BaseException] = []

        def read_opening() -> None:
            failing_since: float | None = None
            try:
                while not stop.is_set():
                    try:
                        opening[0] = float(self.robot.gripper_opening)
                        failing_since = None
                    except Exception:
                        now = self.now()
                        failing_since = now if failing_since is None else failing_since
                        if now - failing_since > self.opening_patience:
                            raise
                        self.stats.opening_read_failures += 1
                    stop.wait(self.pose_period)
            except BaseException as e:  # noqa: BLE001 - handed to the main thread
                errors.append(e)
                stop.set()
                stop_frames.set()

        def sample_poses() -> None:
            try:
                while not stop.is_set():
                    s = self._sample(opening[0])
                    with lock:
                        samples.append(s)
                        while samples and samples[0].time < s.time - self.history:
                            samples.pop(0)
                    stop.wait(self.pose_period)
            except BaseException as e:  # noqa: BLE001 - handed to the main thread
                errors.append(e)
                stop.set()
                stop_frames.set()

        def capture_frames() -> None:
            try:
                while not stop_frames.is_set():
                    image = self.camera.capture()
                    t = self.now() if self.frame_time is None else float(self.frame_time(image))
                    if t < begin:  # taken before the block (arrived late)
                        continue
                    if t > end[0]:  # taken after the block: all frames of it are in
                        break
                    with lock:
                        times = [s.time for s in samples]
                        i = bisect.bisect_left(times, t)
                        near = [j for j in (i - 1, i) if 0 <= j < len(samples)]
                        best = min(near, key=lambda j: abs(samples[j].time - t))
                        s = samples[best]
                    tick = Tick(t, s.pose, s.opening, s.joints, abs(s.time - t), frame=image)
                    self.stats.frames += 1
                    self.stats.skews.append(tick.skew)
                    on_tick(tick)
            except BaseException as e:  # noqa: BLE001 - handed to the main thread
                errors.append(e)
                stop.set()
                stop_frames.set()

        frames = threading.Thread(target=capture_frames, name="cablesim-frames", daemon=True)
        threads = [
            threading.Thread(target=sample_poses, name="cablesim-poses", daemon=True),
            threading.Thread(target=read_opening, name="cablesim-gripper", daemon=True),
            frames,
        ]
        for th in threads:
            th.start()
        try:
            yield
        finally:
            end[0] = self.now()
            if self.frame_time is not None and not errors:
                frames.join(timeout=self.drain)  # the frames taken inside the block
            stop_frames.set()
            stop.set()
            for th in threads:
                th.join(timeout=5.0)
        if errors:
            raise errors[0]

    def wait_still(self, cfg) -> StillResult:
        """Frames until ``cfg.still_time`` s of consecutive frames changed less than the
        thresholds of ``cfg`` (a :class:`~cablesim.episode.config.RetreatConfig`), or
        ``cfg.settle_max_time`` s passed.  With ``frame_time`` only frames taken after the
        call count, timed by when they were taken."""
        t0 = self.now()
        prev = self.grab()  # with frame_time: taken after the call
        calm_since: float | None = None
        rgb = moved = math.inf
        while True:
            image = self.camera.capture()
            now = self.now()
            taken = now if self.frame_time is None else float(self.frame_time(image))
            rgb, moved = frame_change(prev, image, cfg.still_depth)
            prev = image
            if rgb <= cfg.still_rgb and moved <= cfg.still_depth_fraction:
                calm_since = taken if calm_since is None else calm_since
                if taken - calm_since >= cfg.still_time:
                    return StillResult(True, rgb, now - t0, _still_text(rgb, moved))
            else:
                calm_since = None
            if now - t0 >= cfg.settle_max_time:
                return StillResult(False, rgb, now - t0, _still_text(rgb, moved))


def _still_text(rgb: float, moved: float) -> str:
    return f"frames change by {rgb:.2f} grey levels, {100 * moved:.2f}% of pixels in depth"
