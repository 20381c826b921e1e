"""Rigid transforms of the calibration: 4x4 matrices, rotation vectors, pose differences.

Pure NumPy and OpenCV's Rodrigues formula: no simulator, no MuJoCo.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from cablesim.errors import InputError


def rotation_angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation matrix."""
    c = (float(np.trace(R)) - 1.0) / 2.0
    return math.acos(min(1.0, max(-1.0, c)))


def pose_difference(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """(translation distance in m, rotation angle in rad) between two 4x4 transforms."""
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), rotation_angle(A[:3, :3].T @ B[:3, :3])


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.ravel(t)
    return T


def invert(T: np.ndarray) -> np.ndarray:
    R, t = T[:3, :3], T[:3, 3]
    return make_transform(R.T, -R.T @ t)


def rodrigues(v: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(v, np.float64).reshape(3, 1))[0]


def rotation_log(R: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(R, np.float64))[0].ravel()


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    return U @ np.diag([1.0, 1.0, d]) @ Vt


def check_transform(T: Any, what: str) -> np.ndarray:
    """``T`` as a 4x4 float rigid transform, else :class:`InputError` naming ``what``."""
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise InputError(f"{what} must be a finite 4x4 matrix, got shape {M.shape}")
    R = M[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InputError(f"{what}: the upper-left 3x3 block is not a rotation")
    if not np.allclose(M[3], [0, 0, 0, 1]):
        raise InputError(f"{what}: the last row must be 0 0 0 1")
    return M
