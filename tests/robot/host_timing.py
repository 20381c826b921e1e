"""A bounded, counted retry for robot motions in the tests against franka-sim: a safety net.

The cause is removed since the test server runs in lockstep (``FrankaSimServer(clock=
"lockstep")``, ``test_franka_sim_clock.py``): a cycle ends when the client has answered it, so
a control thread this host runs late loses no cycle.  Measured with the client's process stopped
for 2-12 ms every 50-250 ms: 17 of 18 motions aborted on franka-sim's wall clock, 0 of 18 in
lockstep (0 cycles lost); a stalled *server* process lost no cycle on either clock.  The retry
below stays for what lockstep cannot see (it needs lost cycles or a stalled state stream as
evidence, and the end-of-run summary lists every retry, expected none).  What follows is how
the wall clock fails.

This 2-vCPU virtual machine cannot keep a 1 kHz loop: a thread sleeping to 1 ms deadlines
wakes over 0.5 ms late in 1-7 % of cycles and up to 8-23 ms late, at any priority
(``benchmarks/franka_sim_timing.py``).  Both ends of libfranka's protocol miss cycles: the
franka-sim server's Python publish loop (median 1.3-1.7 ms per state, not 1.0) and the
client's control thread.  The server then extrapolates the motion generator across the missed
cycle, as the robot does, and the client's next real command, differenced against that guess,
trips a ``*_discontinuity`` reflex: 46 of 46 such reflexes measured came within three cycles
of a lost cycle or a stall.  On a real robot with a realtime kernel this does not happen, and
the adapter never retries.  Here, :class:`RetryingPanda` runs a motion again, at most
:data:`LIMIT` times, only when every violation the server's cycle monitor logged for it is
:attr:`~cablesim.twin.franka_sim.CycleViolation.host_timing`.  A genuine discontinuity comes
back on every attempt, so the test still fails on it.  Every retry is recorded in
:data:`RETRIES` and listed at the end of the run (``conftest.py``).
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from cablesim.robot.base import MoveResult
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.twin.franka_sim import CycleViolation, FrankaSimServer

LIMIT = 3  # retries per motion


@dataclass(frozen=True)
class Retry:
    test: str
    motion: str
    reason: str
    violations: tuple[CycleViolation, ...]


RETRIES: list[Retry] = []


def is_host_timing(result: MoveResult, violations: list[CycleViolation]) -> bool:
    """Whether a failed motion was aborted only because this host missed control cycles: a
    recovered reflex, and every violation the server logged for it the host's timing."""
    return (
        not result
        and "reflex" in result.reason
        and result.reason.endswith("; recovered")
        and bool(violations)
        and all(v.host_timing for v in violations)
    )


class RetryingPanda:
    """A :class:`FrankyPanda` whose motions are retried on the host's timing (module doc);
    everything else is the adapter's (``raw``)."""

    def __init__(self, raw: FrankyPanda, server: FrankaSimServer, limit: int = LIMIT) -> None:
        self.raw = raw
        self.server = server
        self.limit = limit

    def __getattr__(self, name: str) -> Any:
        return getattr(self.raw, name)

    def _violations_since(self, seen: int, result: MoveResult) -> list[CycleViolation]:
        """The violations logged after the first ``seen``; the server logs a reflex's before it
        answers the motion, but its log is read from a file, so give it a moment."""
        deadline = time.monotonic() + 1.0
        while True:
            found = self.server.cycle_violations()[seen:]
            if found or "reflex" not in result.reason or time.monotonic() > deadline:
                return found
            time.sleep(0.05)

    def _with_retries(self, motion: str, run: Callable[[], MoveResult]) -> MoveResult:
        seen = len(self.server.cycle_violations())
        result = run()
        for _ in range(self.limit):
            violations = self._violations_since(seen, result)
            if not is_host_timing(result, violations):
                break
            retry = Retry(
                os.environ.get("PYTEST_CURRENT_TEST", "?").split(" ")[0],
                motion,
                result.reason.replace("\n", " "),
                tuple(violations),
            )
            RETRIES.append(retry)
            # also a warning: under pytest-xdist the summary (conftest.py) runs elsewhere
            warnings.warn(
                f"franka-sim host-timing retry: {retry.motion}: {retry.reason}", stacklevel=2
            )
            seen += len(violations)
            result = run()
        return result

    def move_to(self, pose: Any, *args: Any, **kwargs: Any) -> MoveResult:
        return self._with_retries("move_to", lambda: self.raw.move_to(pose, *args, **kwargs))

    def move_joints(self, q: np.ndarray, *args: Any, **kwargs: Any) -> MoveResult:
        return self._with_retries("move_joints", lambda: self.raw.move_joints(q, *args, **kwargs))

    def home(self, *args: Any, **kwargs: Any) -> MoveResult:
        return self._with_retries("home", lambda: self.raw.home(*args, **kwargs))

    def move_relative(
        self, delta: np.ndarray, frame: str = "world", speed: float = 0.1, check: bool = True
    ) -> MoveResult:
        """A retry moves by what is left to the first attempt's target (in ``frame``), so an
        aborted partial motion is not added to."""
        start = self.raw.ee_pose()
        d = np.asarray(delta, dtype=float).reshape(3)
        R = {
            "world": np.eye(3),
            "tcp": start.rotation,
            "camera": self.raw.T_world_camera[:3, :3],
        }[frame]
        target = start.position + R @ d
        first = [True]

        def run() -> MoveResult:
            if first[0]:
                first[0] = False
                return self.raw.move_relative(d, frame, speed, check)
            now = self.raw.ee_pose()
            R_now = now.rotation if frame == "tcp" else R
            return self.raw.move_relative(R_now.T @ (target - now.position), frame, speed, check)

        return self._with_retries("move_relative", run)
