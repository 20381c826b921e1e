"""Action strokes against a taut hose: a stroke stopped short counts when the hand covered
enough of it, and fails when the hand hardly moved."""

from __future__ import annotations

import numpy as np

from cablesim.episode import primitives as prim
from cablesim.pose import Pose
from cablesim.robot.base import MoveResult


class _Tethered:
    """A hand on a tether: it reaches any target within ``reach`` (m) of ``anchor`` along x
    and stops at the tether's end beyond it, reporting the miss as a real arm does."""

    def __init__(self, reach: float) -> None:
        self.anchor, self.reach = np.zeros(3), reach
        self.position = np.zeros(3)

    def ee_pose(self) -> Pose:
        return Pose(self.position.copy())

    def move_to(self, pose: Pose, speed: float = 0.05) -> MoveResult:
        target = np.asarray(pose.position, float)
        self.position = target.copy()
        self.position[0] = min(target[0], self.anchor[0] + self.reach)
        err = float(np.linalg.norm(self.position - target))
        if err > 0.002:
            return MoveResult(
                False, f"target not reached within tolerance ({err * 1e3:.1f} mm)", err
            )
        return MoveResult(True, "", err)


def _act(reach: float, min_coverage: float) -> prim.PrimitiveResult:
    robot = _Tethered(reach)
    return prim.periodic_action(
        robot, Pose(np.zeros(3)), np.array([1.0, 0.0, 0.0]), 0.02, 2, 0.05, 0.01, min_coverage
    )


def test_a_stroke_stopped_half_way_counts_and_is_noted():
    r = _act(reach=0.009, min_coverage=0.25)  # +x strokes end 11 mm short: 45% covered
    assert r.success
    assert len(r.details["short_strokes"]) == 2
    assert all(abs(e - 0.011) < 1e-9 for e in r.details["short_strokes"])
    assert not _act(reach=0.009, min_coverage=1.0)  # the old rule: 11 mm > 10 mm fails


def test_a_hand_that_hardly_moves_fails_the_action():
    r = _act(reach=0.002, min_coverage=0.25)  # 10% of the stroke
    assert not r and "stroke 1/8" in r.reason
