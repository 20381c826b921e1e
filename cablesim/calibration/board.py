"""The ChArUco board: its specification and nominal mount, detection of its corners in an
image, and its pose in the camera by perspective-n-point.

Pure OpenCV/NumPy: no simulator, no MuJoCo.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cablesim.calibration.transforms import make_transform, rodrigues
from cablesim.errors import CalibrationError, ConfigError, InputError
from cablesim.frames import Intrinsics

MIN_CORNERS = 8  # detected ChArUco corners for a usable view

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
        return make_transform(R, centre - R @ np.array([w / 2, h / 2, 0.0]))

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


def project_points(T_cam_board: np.ndarray, points: np.ndarray, K: np.ndarray) -> np.ndarray:
    p = points @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    uv = p[:, :2] / p[:, 2:3]
    return uv * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]


def rms_distance(a: np.ndarray, b: np.ndarray) -> float:
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
    T = make_transform(rodrigues(rvec), tvec)
    return T, rms_distance(project_points(T, obj, K), pix)
