"""The robot interface shared by the simulated Panda and the real one (franky-control).

Conventions: poses are of the TCP (``grasp_site``, between the finger pads) in the world frame
unless a name says ``camera``; the camera frame is OpenCV's (x right, y down, z forward) and is
given by the 4x4 ``T_world_camera``.  Motions never raise for an unreachable target, a joint
limit or a collision: they return a :class:`MoveResult` whose ``reason`` says what went wrong and
whose ``outcome`` names it where the robot can tell (:class:`~cablesim.outcomes.Outcome`).
Each maps directly onto franky-control: ``move_to`` -> ``Robot.move(CartesianMotion(Affine))``
with relative dynamics, ``grasp`` -> ``Gripper.grasp(width, speed, force)``, ``open`` ->
``Gripper.move(width, speed)``, ``recover`` -> ``Robot.recover_from_errors()``.
"""

from __future__ import annotations

import abc
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import Literal

import numpy as np

from cablesim.outcomes import Outcome
from cablesim.panda.description import HOME_QPOS
from cablesim.pose import Pose

Frame = Literal["world", "camera", "tcp"]


@dataclass(frozen=True)
class MoveResult:
    """Outcome of a motion; truthy on success.

    ``outcome`` names a failure where the robot tells it apart: ``Outcome.UNREACHABLE`` for a
    motion its arm-model check refused before moving (IK, joint limits, a predicted
    collision), ``Outcome.COLLISION`` for a motion stopped on a contact in the scene.  It is
    None on success and for a failure the robot cannot name (a motion that ran and ended off
    its target, a reflex of the real arm, a refused argument): the step that asked for the
    motion names those (a grasp's approach: ``GRASP_NOT_HELD``, an action stroke:
    ``ACTION_FAILED``, ...)."""

    success: bool
    reason: str = ""
    position_error: float = float("nan")  # m, TCP to target at the end
    duration: float = 0.0  # s of (simulated or real) robot time
    outcome: Outcome | None = None

    def __bool__(self) -> bool:
        return self.success


class Robot(abc.ABC):
    """A 7-dof arm with a parallel gripper."""

    #: 4x4 transform of the camera (OpenCV convention) in the world frame.
    T_world_camera: np.ndarray

    # ---- state -------------------------------------------------------------------------------
    @abc.abstractmethod
    def ee_pose(self) -> Pose:
        """Current TCP pose in the world frame."""

    def ee_pose_camera(self) -> Pose:
        """Current TCP pose in the camera frame."""
        return self.world_to_camera(self.ee_pose())

    @property
    @abc.abstractmethod
    def gripper_opening(self) -> float:
        """Distance between the finger pads (m)."""

    @property
    @abc.abstractmethod
    def joint_positions(self) -> np.ndarray:
        """The 7 arm joint angles (rad)."""

    # ---- motion ------------------------------------------------------------------------------
    @abc.abstractmethod
    def move_to(self, pose: Pose, speed: float = 0.1, angular_speed: float = 0.8) -> MoveResult:
        """Move the TCP along a straight line to ``pose`` (world frame).

        ``speed`` (m/s) and ``angular_speed`` (rad/s) are the peak Cartesian velocities.
        """

    def move_relative(
        self, delta: np.ndarray, frame: Frame = "world", speed: float = 0.1
    ) -> MoveResult:
        """Translate the TCP by ``delta`` (m) expressed in ``frame``; orientation is kept."""
        current = self.ee_pose()
        d = np.asarray(delta, dtype=float).reshape(3)
        if frame == "camera":
            d = np.asarray(self.T_world_camera)[:3, :3] @ d
        elif frame == "tcp":
            d = current.rotation @ d
        return self.move_to(current.translated(d), speed=speed)

    @abc.abstractmethod
    def move_joints(self, q: np.ndarray, speed_factor: float = 0.3) -> MoveResult:
        """Joint-space motion to ``q`` (7,), at ``speed_factor`` of the joint velocity limits."""

    def home(self, speed_factor: float = 0.3) -> MoveResult:
        """Joint-space motion to the home configuration."""
        return self.move_joints(HOME_QPOS, speed_factor)

    @abc.abstractmethod
    def solve_ik(self, pose: Pose) -> np.ndarray | None:
        """Arm joints (7,) of a collision-free solution within limits for ``pose``, or None."""

    @abc.abstractmethod
    def check_reachable(self, pose: Pose) -> tuple[bool, str]:
        """Whether an IK solution within limits and free of collisions exists, without moving."""

    # ---- gripper -----------------------------------------------------------------------------
    @abc.abstractmethod
    def open(self, width: float = 0.08, speed: float = 0.1) -> bool:
        """Move the fingers apart to ``width`` (m); releases whatever is held."""

    @abc.abstractmethod
    def grasp(
        self,
        width: float = 0.015,
        force: float = 70.0,
        speed: float = 0.05,
        epsilon_inner: float = 0.01,
        epsilon_outer: float = 0.01,
    ) -> bool:
        """Close on an object of about ``width`` with ``force`` (N); True if it is held.

        Held means the fingers stopped at an opening in
        ``[width - epsilon_inner, width + epsilon_outer]`` (franky / libfranka semantics).
        """

    def recover(self) -> None:  # noqa: B027 - optional hook, nothing to do in simulation
        """Clear reflex errors after a collision (real robot)."""

    def stop(self) -> None:  # noqa: B027 - optional hook: simulated motions block
        """Stop any motion now (Ctrl-C on the real robot); the robot stays usable."""

    def transit(self) -> AbstractContextManager[None]:
        """The motions inside bring the hand to a hose or away from it, holding nothing (the
        approach to a grasp or push and the retreat; not the actions).  A simulated robot lets
        the hoses it does not touch rest meanwhile (``physics.transit_sleep``); a real robot
        runs them as any other motion."""
        return nullcontext()

    # ---- frames ------------------------------------------------------------------------------
    def world_to_camera(self, pose: Pose) -> Pose:
        T_camera_world = np.linalg.inv(np.asarray(self.T_world_camera, dtype=float))
        return Pose.from_matrix(T_camera_world @ pose.matrix())

    def camera_to_world(self, pose: Pose) -> Pose:
        return Pose.from_matrix(np.asarray(self.T_world_camera, dtype=float) @ pose.matrix())
