"""What the twin thread publishes for other threads: its state (:class:`TwinState`), its rendered
frames (:class:`TwinFrame`) and statistics (:class:`TwinStats`), and where they are read:
the latest state on a :class:`StateBoard` (with waiting for a state that satisfies a
condition), the recent frames in a :class:`FrameHistory` (found by their timestamp).
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cablesim.sim.camera import SimSnapshot


@dataclass(frozen=True)
class TwinState:
    """A published copy of the twin's state (read by other threads)."""

    wall: float  # time.monotonic() when published
    twin_time: float  # the wall time the world's state stands for (monotonic time base)
    sim_time: float  # the world's simulated time
    following: bool
    q: np.ndarray  # twin arm joints (7,)
    q_target: np.ndarray  # the measured joints replayed at twin_time (7,)
    joints_measured_at: float  # wall time of the newest joint sample replayed
    gripper_measured: tuple[float, bool]  # opening (m) and grasp flag in effect at twin_time
    gripper_measured_at: float  # wall time of that gripper sample
    gripper_ctrl: float  # the twin gripper's command (m; 0 = closing with force)
    tcp: np.ndarray  # twin grasp-site position (world)
    tcp_rotation: np.ndarray  # 3x3
    opening: float  # twin finger opening (m)
    fingers_settled: bool  # the fingers have rested since their command last changed
    hose_vertices: tuple[np.ndarray, ...]

    @property
    def joint_error(self) -> float:
        """Largest difference (rad) between the twin's arm and the replayed measurement."""
        return float(np.max(np.abs(self.q - self.q_target)))

    @property
    def lag(self) -> float:
        """How far (s) the twin was behind the wall clock when this was published."""
        return self.wall - self.twin_time


@dataclass
class TwinFrame:
    """One rendered frame of the twin."""

    number: int
    stamp: float  # s of twin time since following started: the camera device's timestamp
    twin_time: float  # the wall time the frame shows (monotonic time base)
    wall: float  # time.monotonic() when rendered
    snapshot: SimSnapshot
    state: TwinState

    @property
    def rgb(self) -> np.ndarray:
        return self.snapshot.image.rgb

    @property
    def depth(self) -> np.ndarray:
        return self.snapshot.image.depth


@dataclass
class TwinStats:
    """What the twin measured about itself while following."""

    steps: int = 0
    frames: int = 0
    followed_s: float = 0.0  # wall time spent following
    skipped_s: float = 0.0  # twin time skipped because the twin fell too far behind
    skips: int = 0
    dropped: int = 0  # frames not rendered to let the physics catch up
    render_s: float = 0.0
    physics_s: float = 0.0
    lag_ms: list[float] = field(default_factory=list)  # per frame: wall - twin time
    tracking_mm: list[float] = field(default_factory=list)  # per frame: TCP, twin vs replayed
    timestep: float = 0.004  # s per physics step

    def summary(self) -> dict[str, float]:
        def q(x: list[float], p: float) -> float:
            return float(np.percentile(x, p)) if x else math.nan

        return {
            "steps": self.steps,
            "frames": self.frames,
            "followed_s": round(self.followed_s, 3),
            "frame_rate_hz": round(self.frames / self.followed_s, 2) if self.followed_s else 0.0,
            "dropped_frames": self.dropped,
            "skipped_s": round(self.skipped_s, 3),
            "skips": self.skips,
            "render_ms_per_frame": round(1000 * self.render_s / max(self.frames, 1), 2),
            "physics_realtime_factor": round(
                self.steps * self.timestep / self.physics_s if self.physics_s else 0.0, 2
            ),
            "lag_ms_median": q(self.lag_ms, 50),
            "lag_ms_max": max(self.lag_ms) if self.lag_ms else math.nan,
            "tracking_mm_median": q(self.tracking_mm, 50),
            "tracking_mm_p95": q(self.tracking_mm, 95),
        }


class StateBoard:
    """The latest published :class:`TwinState`: written by the twin thread, read (and waited
    for) by the others."""

    def __init__(self, state: TwinState) -> None:
        self._state = state
        self._changed = threading.Condition()

    def publish(self, state: TwinState) -> None:
        with self._changed:
            self._state = state
            self._changed.notify_all()

    def latest(self) -> TwinState:
        with self._changed:
            return self._state

    def wait(
        self,
        predicate: Callable[[TwinState], bool],
        timeout: float,
        give_up: Callable[[], bool],
    ) -> TwinState:
        """The first published state (the current one, or a later one) for which
        ``predicate`` holds, or the latest after ``timeout`` s or once ``give_up()``."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while not predicate(self._state):
                left = deadline - time.monotonic()
                if left <= 0 or give_up():
                    break
                self._changed.wait(min(left, 0.1))
            return self._state


class FrameHistory:
    """The rendered frames of the last ``seconds`` s of wall time, found by their timestamp."""

    def __init__(self, seconds: float) -> None:
        self.seconds = float(seconds)
        self._frames: collections.deque[TwinFrame] = collections.deque()
        self._lock = threading.Lock()

    def add(self, frame: TwinFrame) -> None:
        """Keep ``frame``; forget those rendered more than ``seconds`` s before it."""
        with self._lock:
            self._frames.append(frame)
            while self._frames and self._frames[0].wall < frame.wall - self.seconds:
                self._frames.popleft()

    def at(self, stamp: float, tolerance: float = 5e-4) -> TwinFrame | None:
        """The kept frame with timestamp ``stamp`` (within ``tolerance`` s), if any."""
        with self._lock:
            for f in reversed(self._frames):
                if abs(f.stamp - stamp) <= tolerance:
                    return f
            return None

    def latest(self) -> TwinFrame | None:
        with self._lock:
            return self._frames[-1] if self._frames else None
