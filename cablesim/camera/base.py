"""The ``Camera`` interface shared by the simulated camera, a real RealSense and a replayed
recording.  Pure NumPy: importing it never imports MuJoCo.

    with SimCamera(world) as cam:          # any Camera
        img = cam.capture()                # CameraImage: rgb uint8 HxWx3, depth float32 metres
        K = cam.intrinsics.K
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Intrinsics, validate_rgbd


@dataclass(frozen=True)
class CameraImage:
    """One RGB-D capture: ``rgb`` HxWx3 uint8, ``depth`` HxW float32 metric z-depth in metres
    (0 = no measurement), ``timestamp`` in seconds (simulation time for a simulated camera)."""

    rgb: np.ndarray
    depth: np.ndarray
    timestamp: float
    intrinsics: Intrinsics

    def __post_init__(self) -> None:
        validate_rgbd(self.rgb, self.depth, self.intrinsics)
        if not np.isfinite(self.timestamp):
            raise InputError(f"timestamp must be finite, got {self.timestamp!r}")


class Camera(ABC):
    """An RGB-D camera.  ``T_world_camera`` (4x4, OpenCV axes: x right, y down, z forward) is
    ``None`` when the camera pose is unknown (an uncalibrated real camera)."""

    @property
    @abstractmethod
    def intrinsics(self) -> Intrinsics: ...

    @property
    def T_world_camera(self) -> np.ndarray | None:
        return None

    @abstractmethod
    def capture(self) -> CameraImage:
        """Grab the current RGB-D image."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the device or renderer; the camera is unusable afterwards."""

    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
