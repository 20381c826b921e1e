"""Rigid poses: position + unit quaternion (w, x, y, z), and a few rotation helpers.

Part of the ground floor every layer may use: pure NumPy, no MuJoCo.  The quaternion <->
matrix conversions are MuJoCo's ``mju_quat2Mat`` / ``mju_mat2Quat`` written out in NumPy,
operation for operation, so that they give the same bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _unit_quat(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float).reshape(4)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError(f"invalid quaternion {q}")
    q = q / n
    return q if q[0] >= 0 else -q  # canonical hemisphere


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of the quaternion ``q`` (w, x, y, z; unit length assumed)."""
    w, x, y, z = (float(v) for v in np.asarray(q, dtype=float).reshape(4))
    if w == 1.0 and x == 0.0 and y == 0.0 and z == 0.0:
        return np.eye(3)
    q00, q01, q02, q03 = w * w, w * x, w * y, w * z
    q11, q12, q13 = x * x, x * y, x * z
    q22, q23 = y * y, y * z
    q33 = z * z
    return np.array(
        [
            [(q00 - q22) + (q11 - q33), 2 * (q12 - q03), 2 * (q13 + q02)],
            [2 * (q12 + q03), (q00 + q22) - (q11 + q33), 2 * (q23 - q01)],
            [2 * (q13 - q02), 2 * (q23 + q01), (q00 - q22) + (q33 - q11)],
        ]
    )


def mat_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z, w >= 0) of the 3x3 rotation matrix ``R``."""
    m = [float(v) for v in np.asarray(R, dtype=float).reshape(9)]
    if m[0] + m[4] + m[8] > 0:
        w = 0.5 * math.sqrt(1 + m[0] + m[4] + m[8])
        q = [w, 0.25 * (m[7] - m[5]) / w, 0.25 * (m[2] - m[6]) / w, 0.25 * (m[3] - m[1]) / w]
    elif m[0] > m[4] and m[0] > m[8]:
        x = 0.5 * math.sqrt(1 + m[0] - m[4] - m[8])
        q = [0.25 * (m[7] - m[5]) / x, x, 0.25 * (m[1] + m[3]) / x, 0.25 * (m[2] + m[6]) / x]
    elif m[4] > m[8]:
        y = 0.5 * math.sqrt(1 - m[0] + m[4] - m[8])
        q = [0.25 * (m[2] - m[6]) / y, 0.25 * (m[1] + m[3]) / y, y, 0.25 * (m[5] + m[7]) / y]
    else:
        z = 0.5 * math.sqrt(1 - m[0] - m[4] + m[8])
        q = [0.25 * (m[3] - m[1]) / z, 0.25 * (m[2] + m[6]) / z, 0.25 * (m[5] + m[7]) / z, z]
    norm = math.sqrt((q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3]))
    if norm < 1e-15:
        q = [1.0, 0.0, 0.0, 0.0]
    elif abs(norm - 1) > 1e-15:
        inv = 1 / norm
        q = [v * inv for v in q]
    return _unit_quat(np.array(q))


@dataclass(frozen=True)
class Pose:
    """A frame: ``position`` (3,) in metres and ``quaternion`` (4,) as w, x, y, z."""

    position: np.ndarray
    quaternion: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float).reshape(3).copy()
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "quaternion", _unit_quat(self.quaternion))

    @property
    def rotation(self) -> np.ndarray:
        """3x3 rotation matrix (columns are the frame's axes)."""
        return quat_to_mat(self.quaternion)

    def matrix(self) -> np.ndarray:
        """4x4 homogeneous transform."""
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = self.position
        return T

    @staticmethod
    def from_matrix(T: np.ndarray) -> Pose:
        T = np.asarray(T, dtype=float)
        return Pose(T[:3, 3], mat_to_quat(T[:3, :3]))

    @staticmethod
    def from_rotation(position: np.ndarray, R: np.ndarray) -> Pose:
        return Pose(position, mat_to_quat(R))

    def __matmul__(self, other: Pose) -> Pose:
        return Pose.from_matrix(self.matrix() @ other.matrix())

    def inverse(self) -> Pose:
        R = self.rotation
        return Pose.from_rotation(-R.T @ self.position, R.T)

    def translated(self, delta: np.ndarray) -> Pose:
        """The same orientation, position moved by ``delta`` (in the parent frame)."""
        return Pose(self.position + np.asarray(delta, dtype=float), self.quaternion)

    def distance_to(self, other: Pose) -> tuple[float, float]:
        """(translation distance in m, rotation angle in rad) to ``other``."""
        return float(np.linalg.norm(other.position - self.position)), quat_angle(
            self.quaternion, other.quaternion
        )

    def interpolate(self, other: Pose, s: float) -> Pose:
        """Linear in position, spherical-linear in orientation, ``s`` in [0, 1]."""
        return Pose(
            (1.0 - s) * self.position + s * other.position,
            slerp(self.quaternion, other.quaternion, s),
        )


def quat_angle(q0: np.ndarray, q1: np.ndarray) -> float:
    """Rotation angle between two unit quaternions (rad, in [0, pi])."""
    d = abs(float(np.dot(q0, q1)))
    return 2.0 * float(np.arccos(min(1.0, d)))


def slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(d)
    return (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / np.sin(theta)


def grasp_pose(
    center: np.ndarray,
    cable_axis: np.ndarray,
    approach: np.ndarray = (1.0, 0.0, 0.0),
    flip: bool = False,
) -> Pose:
    """TCP pose that grasps a cable at ``center`` with the fingers closing across ``cable_axis``.

    The hand's z axis (the approach direction, from palm to fingertips) is ``approach`` made
    orthogonal to the cable axis; the fingers close along hand y = approach x cable axis.
    ``flip`` rotates the hand by 180 degrees about the approach axis (the same grasp for a
    symmetric hand, with a different joint-7 angle).
    """
    a = np.asarray(cable_axis, dtype=float)
    a = a / np.linalg.norm(a)
    z = np.asarray(approach, dtype=float)
    z = z - np.dot(z, a) * a
    if np.linalg.norm(z) < 1e-6:
        raise ValueError("approach direction is parallel to the cable axis")
    z = z / np.linalg.norm(z)
    y = np.cross(z, a)
    y /= np.linalg.norm(y)
    if flip:
        y = -y
    x = np.cross(y, z)
    return Pose.from_rotation(center, np.column_stack([x, y, z]))
