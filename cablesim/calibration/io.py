"""Calibration files: writing a result as JSON and reading one back.

:func:`write_calibration` writes JSON (``FORMAT = "cablesim-calibration"``, ``VERSION = 1``)::

    {"format", "version", "kind": "eye-to-hand", "date" (ISO 8601, UTC),
     "T_world_camera" (4x4, OpenCV camera axes: x right, y down, z forward),
     "T_world_base" (4x4, where the robot base stands in the world), "T_base_camera" (4x4),
     "T_tcp_board" (4x4, estimated), "intrinsics" {fx fy cx cy width height},
     "board" {BoardSpec}, "residuals" {...}, "poses" [{per pose}], "robot", "camera", "method"}

:func:`load_calibration` reads one back (what the real-robot session uses); any problem raises
:class:`~cablesim.errors.CalibrationError` naming the file and the field.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cablesim.calibration.board import BoardSpec
from cablesim.calibration.transforms import check_transform, invert, pose_difference
from cablesim.errors import CalibrationError, ConfigError, InputError
from cablesim.frames import Intrinsics
from cablesim.jsonutil import json_default

if TYPE_CHECKING:  # pragma: no cover
    from cablesim.calibration.solve import CalibrationResult

FORMAT = "cablesim-calibration"
VERSION = 1


def write_calibration(result: CalibrationResult, path: str | os.PathLike[str]) -> Path:
    """Write ``result`` as JSON (atomically: a temporary file renamed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(result.to_dict(), indent=2, default=json_default) + "\n")
    os.replace(tmp, path)
    return path


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
        return invert(self.T_world_base) @ self.T_world_camera

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
        dt, dr = pose_difference(T_base_camera, invert(T_world_base) @ T_world_camera)
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
