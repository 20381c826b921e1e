"""The arm's rest is judged on the robot's clock (issue 19): a state stream that stalls while the
arm moves shows the same joint angles for a while, and must not read as rest.

Found by the robot loop on a loaded host (run 20 of ``tests/robot`` on c765ee0, load 4.5):
``test_a_motion_starts_only_from_rest`` saw the refused motion run, because the joint angles had
not changed over one 50 ms window of host time while the slow motion was under way."""

from __future__ import annotations

import time

import numpy as np

from cablesim.robot.franky_panda import FrankyPanda


class _Stream:
    """Joint 1 moves at ``speed`` rad/s of robot time; the robot's clock advances ``rate`` s per
    s of host time (1: a healthy stream, 0: stalled, 0.1: ten times slower than real time)."""

    def __init__(self, speed: float, rate: float) -> None:
        self.speed, self.rate, self.start = speed, rate, time.monotonic()
        self.rest_velocity, self.rest_window, self.rest_timeout = 0.02, 0.05, 0.4

    def _timed_joints(self) -> tuple[np.ndarray, float]:
        t = self.rate * (time.monotonic() - self.start)
        q = np.zeros(7)
        q[0] = self.speed * t
        return q, t


def _wait(stream: _Stream) -> str:
    return FrankyPanda.wait_for_rest(stream)  # type: ignore[arg-type]


def test_an_arm_at_rest_is_at_rest() -> None:
    assert _wait(_Stream(speed=0.0, rate=1.0)) == ""
    assert _wait(_Stream(speed=0.0, rate=0.5)) == ""  # a slow clock still shows the rest


def test_a_moving_arm_is_not_at_rest_on_a_slow_or_stalled_stream() -> None:
    moving = _wait(_Stream(speed=0.2, rate=1.0))
    assert moving.startswith("arm not at rest: a joint moved at 0.2"), moving
    slow = _wait(_Stream(speed=0.2, rate=0.3))  # host-time windows would read 0.06 rad/s
    assert slow.startswith("arm not at rest: a joint moved at 0.2"), slow
    stalled = _wait(_Stream(speed=0.2, rate=0.0))  # same angles, same time: no evidence
    assert stalled.startswith("arm not at rest: the robot's clock advanced 0 ms"), stalled
