"""The sampler threads: the robot's measurements recorded with the wall times they were taken.

Two threads read the attached :class:`~cablesim.twin.sources.RobotSource` while the twin
follows: the joints (every ``joint_period`` s; stamped with the middle of the read) and the
gripper (a franky gripper read blocks until the hand's next state packet: 60 Hz on
franka-sim).  Each keeps its samples in a :class:`Track`, where the twin thread replays them
(:mod:`cablesim.twin.replay`).
"""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from cablesim.twin.sources import RobotSource


class Track:
    """Time-stamped measurements (appended by a sampler, read by the twin thread)."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.values: list[Any] = []
        self.lock = threading.Lock()

    def add(self, t: float, value: Any) -> None:
        with self.lock:
            self.times.append(t)
            self.values.append(value)

    def newest_time(self) -> float:
        with self.lock:
            return self.times[-1] if self.times else -math.inf

    def around(self, t: float) -> tuple[tuple[float, Any] | None, tuple[float, Any] | None]:
        """The newest sample at or before ``t`` and the first one after it."""
        with self.lock:
            i = bisect.bisect_right(self.times, t)
            before = (self.times[i - 1], self.values[i - 1]) if i > 0 else None
            after = (self.times[i], self.values[i]) if i < len(self.times) else None
            return before, after

    def forget_before(self, t: float) -> None:
        """Drop samples older than ``t`` (keeping the newest one at or before it)."""
        with self.lock:
            i = bisect.bisect_right(self.times, t) - 1
            if i > 0:
                del self.times[:i]
                del self.values[:i]


class Samplers:
    """The joint and gripper sampler threads and their tracks (:attr:`joints`: (q, dq) pairs;
    :attr:`gripper`: (opening, grasped) pairs).  The threads run from :meth:`start` until
    :meth:`stop` or until ``stopped`` (the twin's own stop) is set; an error in a read is
    handed to ``on_error`` and ends its thread."""

    def __init__(
        self,
        joint_period: float,
        stopped: threading.Event,
        on_error: Callable[[BaseException], None],
    ) -> None:
        self.joint_period = float(joint_period)
        self.joints = Track()
        self.gripper = Track()
        self._stopped = stopped
        self._on_error = on_error
        self._source: RobotSource | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def start(self, source: RobotSource) -> None:
        """Start sampling ``source`` (nothing happens while the threads still run)."""
        if any(t.is_alive() for t in self._threads):
            return
        self._source = source
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._sample, args=(read,), name=name, daemon=True)
            for name, read in (
                ("cablesim-twin-joints", self._read_joints),
                ("cablesim-twin-gripper", self._read_gripper),
            )
        ]
        for t in self._threads:
            t.start()

    def stop(self) -> None:
        """Stop the threads (each is given 5 s to end)."""
        self._stop.set()
        for t in self._threads:
            t.join(5.0)
        self._threads = []

    def _sample(self, read: Callable[[], None]) -> None:
        try:
            while not (self._stop.is_set() or self._stopped.is_set()):
                read()
        except BaseException as e:  # noqa: BLE001 - handed to the other threads
            self._on_error(e)

    def _read_joints(self) -> None:
        assert self._source is not None
        t0 = time.monotonic()
        q, dq = self._source.joint_state()
        t = 0.5 * (t0 + time.monotonic())
        self.joints.add(t, (np.asarray(q, float).copy(), np.asarray(dq, float).copy()))
        self._stop.wait(self.joint_period)

    def _read_gripper(self) -> None:
        assert self._source is not None
        width, grasped = self._source.gripper_state()
        self.gripper.add(time.monotonic(), (float(width), bool(grasped)))
        self._stop.wait(0.002)  # a franky read blocks ~17 ms by itself
