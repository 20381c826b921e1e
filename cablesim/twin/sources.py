"""Where the twin reads the robot's measured state: the :class:`RobotSource` protocol, franky's
robot (:class:`FrankySource`) and a replayed log of timed way points (:class:`ReplaySource`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from cablesim.errors import InputError
from cablesim.panda.description import MAX_OPENING


class RobotSource(Protocol):
    """Where the twin reads the robot's measured state."""

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Measured arm joint positions (7,) and velocities (7,)."""

    def gripper_state(self) -> tuple[float, bool]:
        """Measured finger opening (m) and whether the hand reports a grasp."""


class FrankySource:
    """The measured state of a :class:`~cablesim.robot.franky_panda.FrankyPanda` (franky)."""

    def __init__(self, robot: Any) -> None:
        self.robot = robot

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.robot.robot.current_joint_state
        return (
            np.asarray(s.position, dtype=float).reshape(7),
            np.asarray(s.velocity, dtype=float).reshape(7),
        )

    def gripper_state(self) -> tuple[float, bool]:
        gripper = self.robot.gripper
        if gripper is None:
            return math.nan, False
        s = gripper.state
        return float(s.width), bool(s.is_grasped)


class ReplaySource:
    """A :class:`RobotSource` that replays timed way points, e.g. a logged robot session:
    ``joints`` as (t, q) pairs, piecewise linear between them; ``gripper`` as
    (t, opening, grasped) steps.  Times are seconds since :meth:`start` (or the first read)."""

    def __init__(
        self,
        joints: Sequence[tuple[float, Sequence[float]]],
        gripper: Sequence[tuple[float, float, bool]] = ((0.0, MAX_OPENING, False),),
    ) -> None:
        if not joints or not gripper:
            raise InputError("a replay needs at least one joint and one gripper way point")
        self.times = np.asarray([float(t) for t, _ in joints])
        self.q = np.asarray([np.asarray(q, float).reshape(7) for _, q in joints])
        if np.any(np.diff(self.times) <= 0):
            raise InputError("joint way points must be in increasing time order")
        self.gripper = sorted((float(t), float(w), bool(g)) for t, w, g in gripper)
        self.t0: float | None = None

    def start(self, t0: float | None = None) -> None:
        self.t0 = time.monotonic() if t0 is None else float(t0)

    def _t(self) -> float:
        if self.t0 is None:
            self.start()
        assert self.t0 is not None
        return time.monotonic() - self.t0

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        t = self._t()
        i = int(np.searchsorted(self.times, t, side="right"))
        if i == 0:
            return self.q[0].copy(), np.zeros(7)
        if i >= len(self.times):
            return self.q[-1].copy(), np.zeros(7)
        t0, t1 = self.times[i - 1], self.times[i]
        rate = (self.q[i] - self.q[i - 1]) / (t1 - t0)
        return self.q[i - 1] + rate * (t - t0), rate

    def gripper_state(self) -> tuple[float, bool]:
        t = self._t()
        _, width, grasped = self.gripper[0]
        for tg, w, g in self.gripper:
            if tg <= t:
                width, grasped = w, g
        return width, grasped
