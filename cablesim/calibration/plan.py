"""Planning the views: board poses drawn in front of the camera, kept where the robot can
reach them, the most diverse chosen and put in a short visiting order.

:func:`plan_poses` draws (from the seed's ``calibration`` stream) board poses around a given
centre, facing a rough camera position, with tilts and rolls for rotation diversity, keeps those
the robot's ``check_reachable`` accepts and picks the most diverse N.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cablesim.calibration.board import BoardSpec
from cablesim.calibration.solve import MIN_POSES
from cablesim.calibration.transforms import invert, make_transform, pose_difference, rodrigues
from cablesim.errors import CalibrationError, ConfigError
from cablesim.pose import Pose

if TYPE_CHECKING:  # pragma: no cover
    from cablesim.robot.base import Robot

Say = Callable[[str], None]


def quiet(_msg: str) -> None:
    """A :data:`Say` that says nothing."""


@dataclass
class PlanConfig:
    """Where the board is shown: its centre within ``spread`` m (per axis, uniform) of
    ``centre`` (world), its face turned to ``look_from`` (a rough camera position, world), then
    tilted up to ``max_tilt_deg`` about both in-plane axes and rolled up to ``max_roll_deg``
    about its normal.  ``candidates``: poses drawn before the most diverse reachable ones are
    kept."""

    centre: tuple[float, float, float]
    look_from: tuple[float, float, float]
    spread: float = 0.08
    max_tilt_deg: float = 30.0
    max_roll_deg: float = 60.0
    candidates: int = 120

    def validate(self) -> PlanConfig:
        for name in ("centre", "look_from"):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise ConfigError(f"plan.{name}", f"need three finite numbers (m), got {v}")
        if np.linalg.norm(np.subtract(self.centre, self.look_from)) < 0.1:
            raise ConfigError("plan.look_from", "must be at least 0.1 m from the centre")
        if not 0 <= self.spread <= 0.5:
            raise ConfigError("plan.spread", f"must be within 0..0.5 m, got {self.spread}")
        if not 0 <= self.max_tilt_deg <= 60:
            raise ConfigError("plan.max_tilt_deg", f"must be within 0..60, got {self.max_tilt_deg}")
        if not 0 <= self.max_roll_deg <= 180:
            raise ConfigError(
                "plan.max_roll_deg", f"must be within 0..180, got {self.max_roll_deg}"
            )
        if self.candidates < 1:
            raise ConfigError("plan.candidates", f"must be >= 1, got {self.candidates}")
        return self


@dataclass
class PlannedPose:
    """A board pose and the TCP pose that shows it; ``reachable`` and ``reason`` from the
    robot's ``check_reachable``."""

    T_world_board: np.ndarray
    T_world_tcp: np.ndarray
    reachable: bool = False
    reason: str = ""


def _facing(normal_to: np.ndarray) -> np.ndarray:
    """Rotation whose z axis is ``normal_to`` (unit), x horizontal, y pointing down."""
    z = normal_to / np.linalg.norm(normal_to)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1)


def draw_board_poses(
    board: BoardSpec, plan: PlanConfig, n: int, rng: np.random.Generator
) -> list[PlannedPose]:
    """``n`` random board poses (and the TCP poses that show them with the nominal mount)."""
    plan.validate()
    centre = np.asarray(plan.centre, float)
    look = np.asarray(plan.look_from, float)
    T_board_tcp = invert(board.T_tcp_board())
    out = []
    for _ in range(n):
        c = centre + rng.uniform(-plan.spread, plan.spread, 3)
        tilt = np.radians(rng.uniform(-plan.max_tilt_deg, plan.max_tilt_deg, 2))
        roll = math.radians(rng.uniform(-plan.max_roll_deg, plan.max_roll_deg))
        R = (
            _facing(c - look)
            @ rodrigues([0.0, 0.0, roll])
            @ rodrigues([tilt[0], 0.0, 0.0])
            @ rodrigues([0.0, tilt[1], 0.0])
        )
        T_board = make_transform(R, c - R @ board.centre())
        out.append(PlannedPose(T_board, T_board @ T_board_tcp))
    return out


def _board_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Distance of two board poses: rotation angle (rad) + position / 0.1 m."""
    dt, dr = pose_difference(a, b)
    return dr + dt / 0.1


def _diverse(poses: list[PlannedPose], n: int, nominal: np.ndarray) -> list[PlannedPose]:
    """``n`` poses: the one nearest the ``nominal`` board pose (the centre, facing the camera),
    then greedy farthest-point choices (rotation diversity conditions the hand-eye problem)."""
    if not poses:
        return []
    first = int(np.argmin([_board_distance(p.T_world_board, nominal) for p in poses]))
    chosen = [poses[first]]
    best = np.array([_board_distance(p.T_world_board, poses[first].T_world_board) for p in poses])
    while len(chosen) < min(n, len(poses)):
        k = int(np.argmax(best))
        chosen.append(poses[k])
        best = np.minimum(
            best, [_board_distance(p.T_world_board, poses[k].T_world_board) for p in poses]
        )
    return chosen


def _ordered(poses: list[PlannedPose]) -> list[PlannedPose]:
    """Nearest-neighbour tour from the first (central) pose: shorter motions between views."""
    left = list(poses[1:])
    tour = [poses[0]] if poses else []
    while left:
        last = tour[-1]
        k = min(
            range(len(left)),
            key=lambda i: sum(
                w * v
                for w, v in zip(
                    (10.0, 1.0), pose_difference(last.T_world_tcp, left[i].T_world_tcp), strict=True
                )
            ),
        )
        tour.append(left.pop(k))
    return tour


def as_pose(T: np.ndarray) -> Pose:
    """A 4x4 transform as the robot's :class:`~cablesim.pose.Pose`."""
    return Pose.from_matrix(T)


def plan_poses(
    robot: Robot,
    board: BoardSpec,
    n: int,
    plan: PlanConfig,
    rng: np.random.Generator,
    say: Say = quiet,
) -> tuple[list[PlannedPose], list[PlannedPose]]:
    """(the chosen reachable poses in visiting order, every candidate with its verdict).

    Draws ``plan.candidates`` board poses, keeps those ``robot.check_reachable`` accepts (the
    arm model's IK, limits and collisions; the board itself is not in that model) and picks
    the ``n`` most diverse."""
    if isinstance(n, bool) or not isinstance(n, int) or n < MIN_POSES:
        raise ConfigError("poses", f"need an integer >= {MIN_POSES}, got {n!r}")
    candidates = draw_board_poses(board, plan, max(plan.candidates, n), rng)
    for c in candidates:
        c.reachable, c.reason = robot.check_reachable(as_pose(c.T_world_tcp))
    ok = [c for c in candidates if c.reachable]
    say(f"plan: {len(ok)} of {len(candidates)} candidate poses reachable")
    if len(ok) < n:
        reasons = sorted({c.reason for c in candidates if not c.reachable})[:3]
        raise CalibrationError(
            f"only {len(ok)} of {len(candidates)} candidate board poses are reachable, need {n} "
            f"(move plan.centre, reduce plan.spread/tilts, or draw more candidates); "
            f"e.g. {reasons}"
        )
    c = np.asarray(plan.centre, float)
    R = _facing(c - np.asarray(plan.look_from, float))
    nominal = make_transform(R, c - R @ board.centre())
    return _ordered(_diverse(ok, n, nominal)), candidates
