"""Hand-eye solving: from views of the board (robot TCP pose and camera board pose each) to
the camera in the robot's world frame, the board on the TCP and per-view residuals.

Every pose gives ``B_i Y = X C_i`` (``B_i`` the TCP pose in the world, ``Y = T_tcp_board``,
``X = T_world_camera``, ``C_i = T_camera_board`` from PnP).  :func:`solve_eye_to_hand` finds X
and Y in closed form: OpenCV's ``cv2.calibrateHandEye`` (Park and Martin) fed, as is standard
for eye-to-hand, the *inverse* TCP poses (the base in the gripper frame) and the board poses,
which then returns the camera in the robot's world frame.  The Python bindings of OpenCV 5.0.0
lack ``calibrateHandEye`` (opencv/opencv#29565, fixed after that release by opencv/opencv#29584);
with such an OpenCV the same Park-Martin solution is computed here in NumPy
(:func:`park_martin`).  :func:`refine_eye_to_hand` then adjusts X and Y together to minimise the
reprojection error of every detected corner in every image (the maximum-likelihood estimate
when the robot's poses are exact), with a robust (Huber) loss.  :func:`calibrate` runs both over
a list of :class:`Sample` and gives a :class:`CalibrationResult`.

Pure OpenCV/NumPy (and SciPy's least squares): no simulator, no MuJoCo.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares

from cablesim.calibration.board import BoardDetection, BoardSpec, project_points, rms_distance
from cablesim.calibration.io import FORMAT, VERSION
from cablesim.calibration.transforms import (
    check_transform,
    invert,
    make_transform,
    nearest_rotation,
    pose_difference,
    rodrigues,
    rotation_log,
)
from cablesim.errors import CalibrationError
from cablesim.frames import Intrinsics

MIN_POSES = 5  # usable views for a calibration


def park_martin(T_world_tcp: Sequence[np.ndarray], T_camera_board: Sequence[np.ndarray]):
    """Closed-form eye-to-hand solution (Park and Martin 1994) of ``B_i Y = X C_i``:
    (``X = T_world_camera``, ``Y = T_tcp_board``).  From every pair of poses i < j,
    ``A X = X B`` with ``A = B_j B_i^-1`` and ``B = C_j C_i^-1``: the rotation aligns the
    rotation vectors (``log R_A = R_X log R_B``, solved by SVD), then the translation solves
    ``(R_A - I) t_X = R_X t_B - t_A`` in least squares."""
    Bs = [np.asarray(b, float) for b in T_world_tcp]
    Cs = [np.asarray(c, float) for c in T_camera_board]
    pairs = []
    for i in range(len(Bs)):
        for j in range(i + 1, len(Bs)):
            A = Bs[j] @ invert(Bs[i])
            B = Cs[j] @ invert(Cs[i])
            pairs.append((A, B))
    H = np.zeros((3, 3))
    for A, B in pairs:
        H += np.outer(rotation_log(B[:3, :3]), rotation_log(A[:3, :3]))
    # R_X maximises sum alpha^T R beta: R = V diag(1, 1, d) U^T for H = U S V^T
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R_X = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    M = np.concatenate([A[:3, :3] - np.eye(3) for A, _ in pairs])
    rhs = np.concatenate([R_X @ B[:3, 3] - A[:3, 3] for A, B in pairs])
    t_X = np.linalg.lstsq(M, rhs, rcond=None)[0]
    X = make_transform(R_X, t_X)
    return X, _mean_board_on_tcp(X, Bs, Cs)


def _mean_board_on_tcp(X: np.ndarray, Bs: Sequence[np.ndarray], Cs: Sequence[np.ndarray]):
    Ys = [invert(B) @ X @ C for B, C in zip(Bs, Cs, strict=True)]
    R = nearest_rotation(sum(Y[:3, :3] for Y in Ys))
    return make_transform(R, np.mean([Y[:3, 3] for Y in Ys], axis=0))


def solve_eye_to_hand(
    T_world_tcp: Sequence[np.ndarray], T_camera_board: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray, str]:
    """Closed-form (``X = T_world_camera``, ``Y = T_tcp_board``, method name): OpenCV's
    ``calibrateHandEye`` (Park) where the bindings have it, else :func:`park_martin`."""
    if len(T_world_tcp) < 3 or len(T_world_tcp) != len(T_camera_board):
        raise CalibrationError(
            f"hand-eye calibration needs at least 3 pairs of poses, got "
            f"{len(T_world_tcp)} robot and {len(T_camera_board)} board poses"
        )
    if hasattr(cv2, "calibrateHandEye"):
        inv = [invert(np.asarray(b, float)) for b in T_world_tcp]  # eye-to-hand: base in TCP
        R, t = cv2.calibrateHandEye(
            [T[:3, :3] for T in inv],
            [T[:3, 3] for T in inv],
            [np.asarray(C, float)[:3, :3] for C in T_camera_board],
            [np.asarray(C, float)[:3, 3] for C in T_camera_board],
            method=cv2.CALIB_HAND_EYE_PARK,
        )
        X = make_transform(R, t)
        Bs = [np.asarray(b, float) for b in T_world_tcp]
        Cs = [np.asarray(c, float) for c in T_camera_board]
        return X, _mean_board_on_tcp(X, Bs, Cs), "cv2.calibrateHandEye(PARK)"
    X, Y = park_martin(T_world_tcp, T_camera_board)
    return X, Y, "park_martin (NumPy; this OpenCV's bindings lack calibrateHandEye)"


def refine_eye_to_hand(
    X: np.ndarray,
    Y: np.ndarray,
    T_world_tcp: Sequence[np.ndarray],
    detections: Sequence[BoardDetection],
    intrinsics: Intrinsics,
) -> tuple[np.ndarray, np.ndarray]:
    """X and Y adjusted together to minimise the reprojection error of every corner of every
    view through ``X^-1 B_i Y`` (Huber loss, 1 px)."""

    K = intrinsics.K
    Bs = [np.asarray(b, float) for b in T_world_tcp]

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Xp = make_transform(X[:3, :3] @ rodrigues(p[0:3]), X[:3, 3] + p[3:6])
        Yp = make_transform(Y[:3, :3] @ rodrigues(p[6:9]), Y[:3, 3] + p[9:12])
        return Xp, Yp

    def residuals(p: np.ndarray) -> np.ndarray:
        Xp, Yp = unpack(p)
        Xi = invert(Xp)
        out = [
            (project_points(Xi @ B @ Yp, d.object_points, K) - d.image_points).ravel()
            for B, d in zip(Bs, detections, strict=True)
        ]
        return np.concatenate(out)

    sol = least_squares(residuals, np.zeros(12), loss="huber", f_scale=1.0, x_scale="jac")
    return unpack(sol.x)


@dataclass
class Sample:
    """One view: the robot's TCP pose (world) and joints, the detection and its PnP pose."""

    index: int
    T_world_tcp: np.ndarray
    joints: np.ndarray
    detection: BoardDetection
    T_camera_board: np.ndarray
    pnp_rms: float


@dataclass
class CalibrationResult:
    """An eye-to-hand calibration and its residuals (see :func:`calibrate`)."""

    T_world_camera: np.ndarray
    T_tcp_board: np.ndarray
    T_world_base: np.ndarray
    intrinsics: Intrinsics
    board: BoardSpec
    method: str
    poses: list[dict[str, Any]]
    residuals: dict[str, Any]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def T_base_camera(self) -> np.ndarray:
        return invert(self.T_world_base) @ self.T_world_camera

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": VERSION,
            "kind": "eye-to-hand",
            "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "T_world_camera": self.T_world_camera.tolist(),
            "T_world_base": self.T_world_base.tolist(),
            "T_base_camera": self.T_base_camera.tolist(),
            "T_tcp_board": self.T_tcp_board.tolist(),
            "intrinsics": self.intrinsics.to_dict(),
            "board": self.board.to_dict(),
            "method": self.method,
            "residuals": self.residuals,
            "poses": self.poses,
            **self.meta,
        }

    def summary(self) -> str:
        r = self.residuals
        return (
            f"{len(self.poses)} views; reprojection (PnP) mean {r['reprojection_px']['mean']:.3f} "
            f"max {r['reprojection_px']['max']:.3f} px; hand-eye model reprojection mean "
            f"{r['model_reprojection_px']['mean']:.3f} max {r['model_reprojection_px']['max']:.3f}"
            f" px; hand-eye residual mean {r['handeye_translation_mm']['mean']:.2f} mm "
            f"{r['handeye_rotation_deg']['mean']:.3f} deg, max "
            f"{r['handeye_translation_mm']['max']:.2f} mm {r['handeye_rotation_deg']['max']:.3f} deg"
        )


def _stats(values: Sequence[float]) -> dict[str, float]:
    v = np.asarray(values, float)
    return {"mean": float(v.mean()), "median": float(np.median(v)), "max": float(v.max())}


def calibrate(
    samples: Sequence[Sample],
    intrinsics: Intrinsics,
    board: BoardSpec,
    T_world_base: np.ndarray | None = None,
    refine: bool = True,
) -> CalibrationResult:
    """Eye-to-hand calibration from views of the board (module docstring), with per-view
    residuals: the PnP reprojection error, the reprojection error through the hand-eye model
    (``X^-1 B_i Y``) and the hand-eye residual (the board pose through the robot, ``B_i Y``,
    against the one through the camera, ``X C_i``: translation in mm, rotation in degrees)."""
    if len(samples) < MIN_POSES:
        raise CalibrationError(
            f"only {len(samples)} views with the board detected; need at least {MIN_POSES}"
        )
    Bs = [s.T_world_tcp for s in samples]
    Cs = [s.T_camera_board for s in samples]
    X, Y, method = solve_eye_to_hand(Bs, Cs)
    if refine:
        X, Y = refine_eye_to_hand(X, Y, Bs, [s.detection for s in samples], intrinsics)
        method += " + joint reprojection refinement (Huber, 1 px)"
    K = intrinsics.K
    Xi = invert(X)
    poses = []
    for s, B, C in zip(samples, Bs, Cs, strict=True):
        d = s.detection
        model = rms_distance(project_points(Xi @ B @ Y, d.object_points, K), d.image_points)
        dt, dr = pose_difference(B @ Y, X @ C)
        poses.append(
            {
                "index": s.index,
                "T_world_tcp": B.tolist(),
                "joints": np.asarray(s.joints, float).tolist(),
                "corners": len(d),
                "reprojection_px": s.pnp_rms,
                "model_reprojection_px": model,
                "handeye_translation_mm": 1000.0 * dt,
                "handeye_rotation_deg": math.degrees(dr),
            }
        )
    residuals = {
        key: _stats([p[key] for p in poses])
        for key in (
            "reprojection_px",
            "model_reprojection_px",
            "handeye_translation_mm",
            "handeye_rotation_deg",
        )
    }
    base = np.eye(4) if T_world_base is None else check_transform(T_world_base, "T_world_base")
    return CalibrationResult(X, Y, base, intrinsics, board, method, poses, residuals)
