"""Safety limits around any :class:`~cablesim.robot.base.Robot`: a workspace box and speed caps.

    robot = GuardedRobot(FrankyPanda(...), SafetyConfig(workspace_min=(0.3, -0.5, 0.05)))
    robot.move_to(pose, speed=0.5)       # capped at SafetyConfig.max_speed; refused outside

A Cartesian target outside the box (world frame, TCP position) is refused before anything
moves (``MoveResult(False, "outside the workspace ...", outcome=Outcome.UNREACHABLE)``), and so
is a joint target whose TCP leaves the box anywhere along the joint path (checked on the arm
model, every 0.05 rad).  Speeds
above the caps are lowered to them.  Everything else is delegated unchanged, so the guard works
the same around the simulated and the real arm.
"""

from __future__ import annotations

import math
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any

import numpy as np

from cablesim.config import check_positive
from cablesim.errors import ConfigError
from cablesim.outcomes import Outcome
from cablesim.pose import Pose
from cablesim.robot.base import Frame, MoveResult, Robot


@dataclass
class SafetyConfig:
    """Where the TCP may go and how fast (world frame, metres, seconds)."""

    workspace_min: tuple[float, float, float] = (-0.2, -1.0, 0.02)
    workspace_max: tuple[float, float, float] = (0.9, 1.0, 1.3)
    max_speed: float = 0.25  # m/s, cap on Cartesian motions
    max_angular_speed: float = 1.0  # rad/s
    max_joint_speed_factor: float = 0.5  # fraction of the joint velocity limits

    def validate(self) -> SafetyConfig:
        lo, hi = self.workspace_min, self.workspace_max
        for name, v in (("workspace_min", lo), ("workspace_max", hi)):
            if len(v) != 3 or not all(isinstance(x, int | float) and math.isfinite(x) for x in v):
                raise ConfigError(f"safety.{name}", f"expected three finite numbers, got {v!r}")
        if not all(a < b for a, b in zip(lo, hi, strict=True)):
            raise ConfigError("safety.workspace_min", f"{lo} is not below workspace_max {hi}")
        check_positive("safety.max_speed", self.max_speed)
        check_positive("safety.max_angular_speed", self.max_angular_speed)
        if not 0 < self.max_joint_speed_factor <= 1:
            raise ConfigError(
                "safety.max_joint_speed_factor",
                f"must be in (0, 1], got {self.max_joint_speed_factor}",
            )
        return self

    def contains(self, p: np.ndarray) -> bool:
        p = np.asarray(p, float)
        return bool(np.all(p >= self.workspace_min) and np.all(p <= self.workspace_max))

    def describe(self, p: np.ndarray) -> str:
        return (
            f"outside the workspace: TCP {np.round(np.asarray(p, float), 3).tolist()} not in "
            f"{list(self.workspace_min)}..{list(self.workspace_max)}"
        )


class GuardedRobot(Robot):
    """``robot`` with the limits of ``safety`` (see the module docstring)."""

    def __init__(self, robot: Robot, safety: SafetyConfig | None = None) -> None:
        self.robot = robot
        self.safety = (safety or SafetyConfig()).validate()
        self.T_world_camera = robot.T_world_camera

    def __getattr__(self, name: str) -> Any:  # read-only access to the wrapped robot's extras
        return getattr(self.robot, name)

    # ---- state ---------------------------------------------------------------------------
    def ee_pose(self) -> Pose:
        return self.robot.ee_pose()

    @property
    def gripper_opening(self) -> float:
        return self.robot.gripper_opening

    @property
    def joint_positions(self) -> np.ndarray:
        return self.robot.joint_positions

    # ---- motion --------------------------------------------------------------------------
    def move_to(self, pose: Pose, speed: float = 0.1, angular_speed: float = 0.8) -> MoveResult:
        if not self.safety.contains(pose.position):
            return MoveResult(
                False, self.safety.describe(pose.position), outcome=Outcome.UNREACHABLE
            )
        return self.robot.move_to(
            pose,
            speed=min(speed, self.safety.max_speed),
            angular_speed=min(angular_speed, self.safety.max_angular_speed),
        )

    def move_relative(
        self, delta: np.ndarray, frame: Frame = "world", speed: float = 0.1
    ) -> MoveResult:
        return Robot.move_relative(self, delta, frame, speed)  # through move_to: checked

    def move_joints(self, q: np.ndarray, speed_factor: float = 0.3) -> MoveResult:
        q = np.asarray(q, dtype=float).reshape(7)
        problem = self.joint_path_problem(q)
        if problem:
            return MoveResult(False, problem, outcome=Outcome.UNREACHABLE)
        return self.robot.move_joints(q, min(speed_factor, self.safety.max_joint_speed_factor))

    def joint_path_problem(self, q: np.ndarray, step: float = 0.05) -> str:
        """Why the TCP would leave the workspace on the joint path to ``q`` ('' if it does not)."""
        arm = getattr(self.robot, "arm", None)
        if arm is None:  # no kinematic model: judge the end pose only
            return ""
        q0 = np.asarray(self.robot.joint_positions, float)
        n = max(1, math.ceil(float(np.max(np.abs(q - q0))) / step))
        for i in range(1, n + 1):
            p = arm.fk(q0 + (q - q0) * i / n).position
            if not self.safety.contains(p):
                return f"{self.safety.describe(p)} at {100 * i / n:.0f}% of the joint path"
        return ""

    def solve_ik(self, pose: Pose) -> np.ndarray | None:
        if not self.safety.contains(pose.position):
            return None
        return self.robot.solve_ik(pose)

    def check_reachable(self, pose: Pose) -> tuple[bool, str]:
        if not self.safety.contains(pose.position):
            return False, self.safety.describe(pose.position)
        return self.robot.check_reachable(pose)

    # ---- gripper -------------------------------------------------------------------------
    def open(self, width: float = 0.08, speed: float = 0.1) -> bool:
        return self.robot.open(width, speed)

    def grasp(
        self,
        width: float = 0.015,
        force: float = 70.0,
        speed: float = 0.05,
        epsilon_inner: float = 0.01,
        epsilon_outer: float = 0.01,
    ) -> bool:
        return self.robot.grasp(width, force, speed, epsilon_inner, epsilon_outer)

    def recover(self) -> None:
        self.robot.recover()

    def stop(self) -> None:
        self.robot.stop()

    def transit(self) -> AbstractContextManager[None]:
        return self.robot.transit()
