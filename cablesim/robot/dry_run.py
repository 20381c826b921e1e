"""A robot that plans every motion and moves nothing: ``--dry-run``.

    plan = DryRunRobot(FrankyPanda(...))      # starts at the real arm's measured state
    run_interaction(plan, camera, PlanningClock(camera), segment, cfg)
    for step in plan.log: print(step)         # every motion, its target and the check's verdict

Each motion is checked exactly as the real adapter checks it before moving (IK along the
straight TCP line for Cartesian motions, the joint path for joint motions, limits and
collisions on the arm-only model of :mod:`cablesim.panda.ik`); a motion that passes updates
the virtual state, one that fails returns the same ``MoveResult(False, reason)`` the real
robot would (``outcome=Outcome.UNREACHABLE``).  The gripper succeeds at any width (nothing can
be measured without moving).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.outcomes import Outcome
from cablesim.panda.description import MAX_OPENING
from cablesim.pose import Pose
from cablesim.robot.base import MoveResult, Robot


@dataclass
class PlannedMotion:
    kind: str  # move_to | move_joints | open | grasp
    ok: bool
    reason: str = ""
    target: list[float] = field(default_factory=list)  # TCP position (world) or joints

    def __str__(self) -> str:
        verdict = "ok" if self.ok else f"REFUSED: {self.reason}"
        return f"{self.kind:11} {np.round(self.target, 3).tolist()}  {verdict}"


class DryRunRobot(Robot):
    """Plans on ``robot``'s arm model from its current measured state; never moves it."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.arm: Any = robot.arm  # type: ignore[attr-defined]
        self.T_world_camera = robot.T_world_camera
        self._q = np.asarray(robot.joint_positions, float).copy()
        opening = float(robot.gripper_opening)
        self._opening = opening if np.isfinite(opening) else MAX_OPENING
        self.log: list[PlannedMotion] = []

    # ---- state ---------------------------------------------------------------------------
    def ee_pose(self) -> Pose:
        return self.arm.fk(self._q)

    @property
    def gripper_opening(self) -> float:
        return self._opening

    @property
    def joint_positions(self) -> np.ndarray:
        return self._q.copy()

    # ---- motion --------------------------------------------------------------------------
    def move_to(self, pose: Pose, speed: float = 0.1, angular_speed: float = 0.8) -> MoveResult:
        plan, reason = self.arm.plan_line(self.ee_pose(), self._q, pose, self._opening)
        self.log.append(PlannedMotion("move_to", bool(plan), reason, pose.position.tolist()))
        if not plan:
            return MoveResult(False, reason, outcome=Outcome.UNREACHABLE)
        self._q = np.asarray(plan[-1], float)
        return MoveResult(True, "", float(np.linalg.norm(self.ee_pose().position - pose.position)))

    def move_joints(self, q: np.ndarray, speed_factor: float = 0.3) -> MoveResult:
        q = np.asarray(q, float).reshape(7)
        reason = self.arm.check_joint_path(self._q, q, self._opening)
        self.log.append(PlannedMotion("move_joints", not reason, reason, q.tolist()))
        if reason:
            return MoveResult(False, reason, outcome=Outcome.UNREACHABLE)
        self._q = q.copy()
        return MoveResult(True)

    def solve_ik(self, pose: Pose) -> np.ndarray | None:
        return self.robot.solve_ik(pose)

    def check_reachable(self, pose: Pose) -> tuple[bool, str]:
        return self.robot.check_reachable(pose)

    # ---- gripper -------------------------------------------------------------------------
    def open(self, width: float = MAX_OPENING, speed: float = 0.1) -> bool:
        self._opening = float(np.clip(width, 0.0, MAX_OPENING))
        self.log.append(PlannedMotion("open", True, "", [self._opening]))
        return True

    def grasp(
        self,
        width: float = 0.015,
        force: float = 70.0,
        speed: float = 0.05,
        epsilon_inner: float = 0.01,
        epsilon_outer: float = 0.01,
    ) -> bool:
        self._opening = float(width)
        self.log.append(PlannedMotion("grasp", True, "", [width]))
        return True
