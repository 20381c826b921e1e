"""Eye-to-hand camera calibration with a ChArUco board held by the gripper (issue 8).

The camera is fixed; the robot holds a ChArUco board and shows it to the camera at N poses.
Each pose gives two transforms of the same board: through the robot (the TCP pose ``B_i`` in the
world, then the unknown, constant board-on-TCP transform ``Y = T_tcp_board``) and through the
camera (the unknown ``X = T_world_camera``, then the board pose ``C_i = T_camera_board`` that
perspective-n-point gives from the detected corners)::

    B_i Y = X C_i        for every pose i

:func:`solve_eye_to_hand` finds X and Y in closed form: OpenCV's ``cv2.calibrateHandEye`` (Park
and Martin) fed, as is standard for eye-to-hand, the *inverse* TCP poses (the base in the
gripper frame) and the board poses, which then returns the camera in the robot's world frame.
The Python bindings of OpenCV 5.0.0 lack ``calibrateHandEye`` (opencv/opencv#29565, fixed after
that release by opencv/opencv#29584); with such an OpenCV the same Park-Martin solution is
computed here in NumPy (:func:`park_martin`).  :func:`refine_eye_to_hand` then adjusts X and Y
together to minimise the reprojection error of every detected corner in every image (the
maximum-likelihood estimate when the robot's poses are exact), with a robust (Huber) loss.

Files.  :func:`write_calibration` writes JSON (``FORMAT = "cablesim-calibration"``,
``VERSION = 1``)::

    {"format", "version", "kind": "eye-to-hand", "date" (ISO 8601, UTC),
     "T_world_camera" (4x4, OpenCV camera axes: x right, y down, z forward),
     "T_world_base" (4x4, where the robot base stands in the world), "T_base_camera" (4x4),
     "T_tcp_board" (4x4, estimated), "intrinsics" {fx fy cx cy width height},
     "board" {BoardSpec}, "residuals" {...}, "poses" [{per pose}], "robot", "camera", "method"}

:func:`load_calibration` reads one back (what the real-robot session uses); any problem raises
:class:`~cablesim.errors.CalibrationError` naming the file and the field.

Driving the devices.  :func:`plan_poses` draws (from the seed's ``calibration`` stream) board
poses in front of the camera around a given centre, facing a rough camera position, with tilts
and rolls for rotation diversity, keeps those the robot's ``check_reachable`` accepts and picks
the most diverse N; :func:`collect_samples` moves any :class:`~cablesim.robot.base.Robot` there
(``move_to``; a joint-space move to the IK solution where the straight line is blocked) and
detects the board in any :class:`~cablesim.camera.base.Camera`'s image.  The same code runs the
simulated Panda with a board in its hand (``RobotConfig.hand_board``) and the real one.

Pure OpenCV/NumPy (and SciPy's least squares): no simulator, no MuJoCo at import time.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from cablesim.errors import CalibrationError, ConfigError, InputError
from cablesim.jsonutil import json_default
from cablesim.panda.description import RETRACT_QPOS
from cablesim.perception.frames import Intrinsics

if TYPE_CHECKING:  # pragma: no cover
    from cablesim.camera.base import Camera
    from cablesim.robot.base import Robot

FORMAT = "cablesim-calibration"
VERSION = 1
MIN_CORNERS = 8  # detected ChArUco corners for a usable view
MIN_POSES = 5  # usable views for a calibration

Say = Callable[[str], None]


def _quiet(_msg: str) -> None:
    pass


# ---------------------------------------------------------------------- rigid transforms
def rotation_angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation matrix."""
    c = (float(np.trace(R)) - 1.0) / 2.0
    return math.acos(min(1.0, max(-1.0, c)))


def pose_difference(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """(translation distance in m, rotation angle in rad) between two 4x4 transforms."""
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), rotation_angle(A[:3, :3].T @ B[:3, :3])


def _transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.ravel(t)
    return T


def _invert(T: np.ndarray) -> np.ndarray:
    R, t = T[:3, :3], T[:3, 3]
    return _transform(R.T, -R.T @ t)


def _rodrigues(v: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(v, np.float64).reshape(3, 1))[0]


def _log(R: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(R, np.float64))[0].ravel()


def _nearest_rotation(M: np.ndarray) -> np.ndarray:
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


# ---------------------------------------------------------------------- the board
_DICTIONARIES = {n: getattr(cv2.aruco, n) for n in dir(cv2.aruco) if n.startswith("DICT_")}


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board and how the gripper holds it.

    ``squares_x`` x ``squares_y`` chessboard squares of ``square_length`` m with ArUco markers
    of ``marker_length`` m from ``dictionary`` in the white squares (OpenCV's layout), on a
    plate with a white ``margin`` (m) around the squares.  Board frame (OpenCV's): origin at the
    outer corner of the first square, x along the rows, y down the columns, z into the board.

    Nominal mount (used to plan poses and by the simulated hand board; the calibration
    estimates the true one): the plate stands ``mount_offset`` m ahead of the TCP along the
    approach axis (TCP z), centred on it, its printed face looking along TCP z, its x along TCP
    y and its y along TCP x.
    """

    squares_x: int = 7
    squares_y: int = 5
    square_length: float = 0.03
    marker_length: float = 0.022
    dictionary: str = "DICT_5X5_100"
    margin: float = 0.01
    mount_offset: float = 0.03

    def validate(self) -> BoardSpec:
        for name in ("squares_x", "squares_y"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 3:
                raise ConfigError(f"board.{name}", f"need an integer >= 3, got {v!r}")
        for name in ("square_length", "marker_length"):
            v = getattr(self, name)
            if not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
                raise ConfigError(f"board.{name}", f"must be a positive length in m, got {v!r}")
        if self.marker_length >= self.square_length:
            raise ConfigError(
                "board.marker_length",
                f"{self.marker_length} must be smaller than square_length {self.square_length}",
            )
        if self.dictionary not in _DICTIONARIES:
            raise ConfigError(
                "board.dictionary",
                f"unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_5X5_100)",
            )
        n_markers = (self.squares_x * self.squares_y) // 2
        size = cv2.aruco.getPredefinedDictionary(_DICTIONARIES[self.dictionary]).bytesList.shape[0]
        if n_markers > size:
            raise ConfigError(
                "board.dictionary",
                f"{self.dictionary} has {size} markers, the board needs {n_markers}",
            )
        if not math.isfinite(self.margin) or self.margin < 0:
            raise ConfigError("board.margin", f"must be >= 0 m, got {self.margin!r}")
        if not math.isfinite(self.mount_offset):
            raise ConfigError("board.mount_offset", f"must be finite, got {self.mount_offset!r}")
        return self

    @property
    def size(self) -> tuple[float, float]:
        """(width, height) in m of the squares."""
        return self.squares_x * self.square_length, self.squares_y * self.square_length

    @property
    def plate_size(self) -> tuple[float, float]:
        """(width, height) in m of the plate (squares and margin)."""
        w, h = self.size
        return w + 2 * self.margin, h + 2 * self.margin

    def cv_board(self) -> cv2.aruco.CharucoBoard:
        d = cv2.aruco.getPredefinedDictionary(_DICTIONARIES[self.dictionary])
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square_length, self.marker_length, d
        )

    def image(self, px_per_m: float = 4000.0) -> np.ndarray:
        """The plate as a grey uint8 image (squares and margin), ``px_per_m`` pixels per metre;
        pixel (0, 0) is the plate's corner at board coordinates (-margin, -margin)."""
        w, h = self.plate_size
        size = (int(round(w * px_per_m)), int(round(h * px_per_m)))
        margin = int(round(self.margin * px_per_m))
        return self.cv_board().generateImage(size, marginSize=margin, borderBits=1)

    def T_tcp_board(self) -> np.ndarray:
        """The nominal board frame in the TCP frame (see the class docstring)."""
        w, h = self.size
        R = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # cols: x, y, z
        centre = np.array([0.0, 0.0, self.mount_offset])
        return _transform(R, centre - R @ np.array([w / 2, h / 2, 0.0]))

    def centre(self) -> np.ndarray:
        """The centre of the squares in board coordinates."""
        w, h = self.size
        return np.array([w / 2, h / 2, 0.0])

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BoardSpec:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError("board", f"unknown fields {unknown}")
        return cls(**d).validate()


@dataclass
class BoardDetection:
    """ChArUco corners found in one image: ids (N,), pixels (N, 2), board points (N, 3)."""

    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray
    markers: int

    def __len__(self) -> int:
        return len(self.ids)


def detect_board(image: np.ndarray, board: BoardSpec) -> BoardDetection | None:
    """The board's ChArUco corners in an RGB (or grey) uint8 image, or None if fewer than
    :data:`MIN_CORNERS` were found."""
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise InputError(f"image must be an HxW or HxWx3 uint8 array, got {img.dtype} {img.shape}")
    grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    cvb = board.cv_board()
    corners, ids, marker_corners, _ = cv2.aruco.CharucoDetector(cvb).detectBoard(grey)
    if ids is None or corners is None or len(ids) < MIN_CORNERS:
        return None
    obj, pix = cvb.matchImagePoints(corners, ids)
    return BoardDetection(
        ids=np.asarray(ids, int).ravel(),
        image_points=np.asarray(pix, np.float64).reshape(-1, 2),
        object_points=np.asarray(obj, np.float64).reshape(-1, 3),
        markers=0 if marker_corners is None else len(marker_corners),
    )


def _project(T_cam_board: np.ndarray, points: np.ndarray, K: np.ndarray) -> np.ndarray:
    p = points @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    uv = p[:, :2] / p[:, 2:3]
    return uv * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def board_pose(det: BoardDetection, intrinsics: Intrinsics) -> tuple[np.ndarray, float]:
    """``T_camera_board`` (4x4) of a detection by planar PnP (IPPE, then Levenberg-Marquardt)
    and its RMS reprojection error in pixels.  No lens distortion: the images are assumed
    rectified (RealSense colour streams and the simulated camera are)."""
    K = intrinsics.K
    obj = det.object_points.astype(np.float64)
    pix = det.image_points.astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, pix, K, None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationError("the board pose could not be estimated (PnP failed)")
    rvec, tvec = cv2.solvePnPRefineLM(obj, pix, K, None, rvec, tvec)
    T = _transform(_rodrigues(rvec), tvec)
    return T, _rms(_project(T, obj, K), pix)


# ---------------------------------------------------------------------- hand-eye
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
            A = Bs[j] @ _invert(Bs[i])
            B = Cs[j] @ _invert(Cs[i])
            pairs.append((A, B))
    H = np.zeros((3, 3))
    for A, B in pairs:
        H += np.outer(_log(B[:3, :3]), _log(A[:3, :3]))
    # R_X maximises sum alpha^T R beta: R = V diag(1, 1, d) U^T for H = U S V^T
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R_X = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    M = np.concatenate([A[:3, :3] - np.eye(3) for A, _ in pairs])
    rhs = np.concatenate([R_X @ B[:3, 3] - A[:3, 3] for A, B in pairs])
    t_X = np.linalg.lstsq(M, rhs, rcond=None)[0]
    X = _transform(R_X, t_X)
    return X, _mean_board_on_tcp(X, Bs, Cs)


def _mean_board_on_tcp(X: np.ndarray, Bs: Sequence[np.ndarray], Cs: Sequence[np.ndarray]):
    Ys = [_invert(B) @ X @ C for B, C in zip(Bs, Cs, strict=True)]
    R = _nearest_rotation(sum(Y[:3, :3] for Y in Ys))
    return _transform(R, np.mean([Y[:3, 3] for Y in Ys], axis=0))


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
        inv = [_invert(np.asarray(b, float)) for b in T_world_tcp]  # eye-to-hand: base in TCP
        R, t = cv2.calibrateHandEye(
            [T[:3, :3] for T in inv],
            [T[:3, 3] for T in inv],
            [np.asarray(C, float)[:3, :3] for C in T_camera_board],
            [np.asarray(C, float)[:3, 3] for C in T_camera_board],
            method=cv2.CALIB_HAND_EYE_PARK,
        )
        X = _transform(R, t)
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
    from scipy.optimize import least_squares

    K = intrinsics.K
    Bs = [np.asarray(b, float) for b in T_world_tcp]

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Xp = _transform(X[:3, :3] @ _rodrigues(p[0:3]), X[:3, 3] + p[3:6])
        Yp = _transform(Y[:3, :3] @ _rodrigues(p[6:9]), Y[:3, 3] + p[9:12])
        return Xp, Yp

    def residuals(p: np.ndarray) -> np.ndarray:
        Xp, Yp = unpack(p)
        Xi = _invert(Xp)
        out = [
            (_project(Xi @ B @ Yp, d.object_points, K) - d.image_points).ravel()
            for B, d in zip(Bs, detections, strict=True)
        ]
        return np.concatenate(out)

    sol = least_squares(residuals, np.zeros(12), loss="huber", f_scale=1.0, x_scale="jac")
    return unpack(sol.x)


# ---------------------------------------------------------------------- samples and result
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
        return _invert(self.T_world_base) @ self.T_world_camera

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
    Xi = _invert(X)
    poses = []
    for s, B, C in zip(samples, Bs, Cs, strict=True):
        d = s.detection
        model = _rms(_project(Xi @ B @ Y, d.object_points, K), d.image_points)
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


def write_calibration(result: CalibrationResult, path: str | os.PathLike[str]) -> Path:
    """Write ``result`` as JSON (atomically: a temporary file renamed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(result.to_dict(), indent=2, default=json_default) + "\n")
    os.replace(tmp, path)
    return path


# ---------------------------------------------------------------------- reading a file
@dataclass(frozen=True)
class Calibration:
    """A calibration file as read by :func:`load_calibration`."""

    path: Path
    T_world_camera: np.ndarray
    T_world_base: np.ndarray
    intrinsics: Intrinsics
    board: BoardSpec | None
    residuals: dict[str, Any]
    date: str
    doc: dict[str, Any]

    @property
    def T_base_camera(self) -> np.ndarray:
        return _invert(self.T_world_base) @ self.T_world_camera

    def check_intrinsics(self, intrinsics: Intrinsics, rel_tol: float = 0.02) -> None:
        """Raise :class:`CalibrationError` unless ``intrinsics`` (the camera's now) are those
        the calibration was made with: same image size, focal lengths and principal point
        within ``rel_tol`` of the focal length."""
        a, b = self.intrinsics, intrinsics
        if (a.width, a.height) != (b.width, b.height):
            raise CalibrationError(
                f"{self.path}: intrinsics are for {a.width}x{a.height}, the camera gives "
                f"{b.width}x{b.height}"
            )
        tol = rel_tol * a.f
        for name in ("fx", "fy", "cx", "cy"):
            if abs(getattr(a, name) - getattr(b, name)) > tol:
                raise CalibrationError(
                    f"{self.path}: intrinsics.{name} is {getattr(a, name):.2f}, the camera "
                    f"reports {getattr(b, name):.2f}"
                )


def load_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read a calibration file written by :func:`write_calibration` (or by hand: only
    ``format``, ``version``, ``T_world_camera`` and ``intrinsics`` are required;
    ``T_world_base`` defaults to the identity, i.e. the world is the robot base frame).
    Raises :class:`CalibrationError` naming the file and the field."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as e:
        raise CalibrationError(f"{path}: no such calibration file") from e
    except (OSError, UnicodeDecodeError) as e:
        raise CalibrationError(f"{path}: unreadable ({e})") from e
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise CalibrationError(f"{path}: not valid JSON ({e})") from e
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CalibrationError(f"{path}: format: not a {FORMAT} file")
    if doc.get("version") != VERSION:
        raise CalibrationError(f"{path}: version: unknown version {doc.get('version')!r}")

    def transform(name: str, default: np.ndarray | None = None) -> np.ndarray:
        if name not in doc:
            if default is not None:
                return default
            raise CalibrationError(f"{path}: {name}: missing")
        try:
            return check_transform(doc[name], name)
        except (InputError, ValueError, TypeError) as e:
            raise CalibrationError(f"{path}: {name}: {e}") from e

    T_world_camera = transform("T_world_camera")
    T_world_base = transform("T_world_base", np.eye(4))
    if "T_base_camera" in doc:
        T_base_camera = transform("T_base_camera")
        dt, dr = pose_difference(T_base_camera, _invert(T_world_base) @ T_world_camera)
        if dt > 1e-6 or dr > 1e-6:
            raise CalibrationError(
                f"{path}: T_base_camera: disagrees with T_world_base^-1 T_world_camera by "
                f"{dt * 1000:.3f} mm, {math.degrees(dr):.4f} deg"
            )
    if not isinstance(doc.get("intrinsics"), dict):
        raise CalibrationError(f"{path}: intrinsics: missing or not an object")
    try:
        intrinsics = Intrinsics.from_dict(doc["intrinsics"])
    except (InputError, ValueError, TypeError) as e:
        raise CalibrationError(f"{path}: intrinsics: {e}") from e
    board = None
    if doc.get("board") is not None:
        try:
            board = BoardSpec.from_dict(dict(doc["board"]))
        except (ConfigError, TypeError, ValueError) as e:
            raise CalibrationError(f"{path}: board: {e}") from e
    residuals = doc.get("residuals") or {}
    if not isinstance(residuals, dict):
        raise CalibrationError(f"{path}: residuals: not an object")
    return Calibration(
        path=path,
        T_world_camera=T_world_camera,
        T_world_base=T_world_base,
        intrinsics=intrinsics,
        board=board,
        residuals=residuals,
        date=str(doc.get("date", "")),
        doc=doc,
    )


# ---------------------------------------------------------------------- driving the devices
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
    T_board_tcp = _invert(board.T_tcp_board())
    out = []
    for _ in range(n):
        c = centre + rng.uniform(-plan.spread, plan.spread, 3)
        tilt = np.radians(rng.uniform(-plan.max_tilt_deg, plan.max_tilt_deg, 2))
        roll = math.radians(rng.uniform(-plan.max_roll_deg, plan.max_roll_deg))
        R = (
            _facing(c - look)
            @ _rodrigues([0.0, 0.0, roll])
            @ _rodrigues([tilt[0], 0.0, 0.0])
            @ _rodrigues([0.0, tilt[1], 0.0])
        )
        T_board = _transform(R, c - R @ board.centre())
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


def _pose(T: np.ndarray):
    from cablesim.robot.pose import Pose

    return Pose.from_matrix(T)


def plan_poses(
    robot: Robot,
    board: BoardSpec,
    n: int,
    plan: PlanConfig,
    rng: np.random.Generator,
    say: Say = _quiet,
) -> tuple[list[PlannedPose], list[PlannedPose]]:
    """(the chosen reachable poses in visiting order, every candidate with its verdict).

    Draws ``plan.candidates`` board poses, keeps those ``robot.check_reachable`` accepts (the
    arm model's IK, limits and collisions; the board itself is not in that model) and picks
    the ``n`` most diverse."""
    if isinstance(n, bool) or not isinstance(n, int) or n < MIN_POSES:
        raise ConfigError("poses", f"need an integer >= {MIN_POSES}, got {n!r}")
    candidates = draw_board_poses(board, plan, max(plan.candidates, n), rng)
    for c in candidates:
        c.reachable, c.reason = robot.check_reachable(_pose(c.T_world_tcp))
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
    nominal = _transform(R, c - R @ board.centre())
    return _ordered(_diverse(ok, n, nominal)), candidates


def _move(robot: Robot, T: np.ndarray, speed: float) -> tuple[bool, str]:
    """Straight line to the TCP pose; where that is blocked (from the park pose, or an IK
    branch switch on the way), a joint-space move to its IK solution; where that path collides,
    through the retract configuration (then the line, else the joint move again)."""
    pose = _pose(T)
    res = robot.move_to(pose, speed=speed)
    if res:
        return True, "line"
    q = robot.solve_ik(pose)
    if q is None:
        return False, f"line: {res.reason}; no IK solution"
    res = robot.move_joints(q)
    if res:
        return True, "joints"
    if not res.reason.startswith("collision"):
        return False, f"joints: {res.reason}"
    via = robot.move_joints(RETRACT_QPOS)
    if not via:
        return False, f"joints: {res.reason}; to retract: {via.reason}"
    res = robot.move_to(pose, speed=speed)
    if res:
        return True, "retract, line"
    res = robot.move_joints(q)
    return (True, "retract, joints") if res else (False, f"from retract: {res.reason}")


def collect_samples(
    robot: Robot,
    camera: Camera,
    board: BoardSpec,
    poses: Sequence[PlannedPose],
    speed: float = 0.1,
    flush_frames: int = 0,
    say: Say = _quiet,
) -> tuple[list[Sample], list[dict[str, Any]]]:
    """Move to each pose, grab an image (after ``flush_frames`` older frames of a streaming
    camera), detect the board and estimate its pose.  A pose the robot cannot get to is tried
    again after the others.  Returns the usable samples and a log entry per pose (moved how,
    corners, or why it was skipped)."""
    samples: list[Sample] = []
    log: list[dict[str, Any]] = []
    intr = camera.intrinsics
    # a pose the robot could not get to is tried once more at the end, from another view
    order = list(range(len(poses)))
    tried: set[int] = set()
    for i in order:
        p = poses[i]
        ok, how = _move(robot, p.T_world_tcp, speed)
        if not ok and i not in tried:
            tried.add(i)
            order.append(i)
            say(f"pose {i + 1}/{len(poses)}: the robot could not get there ({how}); later again")
            continue
        entry: dict[str, Any] = {"index": i, "moved": ok, "motion": how}
        log.append(entry)
        if not ok:
            say(f"pose {i + 1}/{len(poses)}: skipped, the robot could not get there ({how})")
            continue
        for _ in range(flush_frames):
            camera.capture()
        image = camera.capture()
        T_tcp = robot.ee_pose().matrix()
        joints = robot.joint_positions
        det = detect_board(image.rgb, board)
        if det is None:
            entry["corners"] = 0
            say(f"pose {i + 1}/{len(poses)}: skipped, board not detected")
            continue
        T_cb, rms = board_pose(det, intr)
        entry.update(corners=len(det), reprojection_px=rms)
        samples.append(Sample(i, T_tcp, joints, det, T_cb, rms))
        say(f"pose {i + 1}/{len(poses)}: {len(det)} corners, PnP {rms:.3f} px ({how})")
    return samples, log


@dataclass
class Session:
    """What :func:`calibrate_devices` did: the plan (chosen poses, every candidate), the motion
    log, the samples and the result (None on a dry run)."""

    poses: list[PlannedPose]
    candidates: list[PlannedPose]
    log: list[dict[str, Any]] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)
    result: CalibrationResult | None = None


def calibrate_devices(
    robot: Robot,
    camera: Camera,
    board: BoardSpec,
    n: int,
    plan: PlanConfig,
    rng: np.random.Generator,
    T_world_base: np.ndarray | None = None,
    dry_run: bool = False,
    speed: float = 0.1,
    flush_frames: int = 0,
    return_home: bool = True,
    say: Say = _quiet,
) -> Session:
    """Plan ``n`` reachable board poses, show each to the camera, calibrate (module docstring).

    ``dry_run``: plan and check the poses without moving.  ``return_home``: move back to the
    joint configuration the robot started in."""
    board.validate()
    if not speed > 0:
        raise ConfigError("speed", f"must be > 0 m/s, got {speed}")
    if flush_frames < 0:
        raise ConfigError("flush_frames", f"must be >= 0, got {flush_frames}")
    poses, candidates = plan_poses(robot, board, n, plan, rng, say)
    session = Session(poses, candidates)
    if dry_run:
        return session
    start = robot.joint_positions
    try:
        session.samples, session.log = collect_samples(
            robot, camera, board, poses, speed, flush_frames, say
        )
    finally:
        if return_home:
            from cablesim.robot.grasping import move_joints_safely

            res = move_joints_safely(robot, start)
            reached = [e["index"] for e in session.log if e["moved"]]
            if not res and reached:  # back through the first view reached, then home
                _move(robot, poses[reached[0]].T_world_tcp, speed)
                res = move_joints_safely(robot, start)
            if not res:
                say(f"could not return to the start configuration: {res.reason}")
    session.result = calibrate(session.samples, camera.intrinsics, board, T_world_base)
    session.result.meta.update(
        poses_planned=len(poses),
        poses_used=len(session.samples),
        plan=dataclasses.asdict(plan),
        motion_log=session.log,
    )
    return session
