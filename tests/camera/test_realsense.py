"""The real-camera code path, exercised through a RealSense recording made by librealsense's
software device (no camera attached)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip(
    "pyrealsense2", reason="the real extra (pyrealsense2 + libusb) is not installed"
)

from cablesim.camera.base import CameraImage  # noqa: E402
from cablesim.camera.realsense import RealSenseCamera, write_recording  # noqa: E402
from cablesim.errors import InputError, RecordingError  # noqa: E402
from cablesim.frames import Intrinsics  # noqa: E402


def _images(n: int = 4, w: int = 64, h: int = 48) -> list[CameraImage]:
    k = Intrinsics(60.0, 61.0, 31.5, 23.5, w, h)
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        rgb = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
        depth = np.full((h, w), 0.9 + 0.01 * i, np.float32)
        depth[:5] = 0.0  # invalid rows stay invalid
        out.append(CameraImage(rgb, depth, 1.0 + i / 15, k))
    return out


def test_recording_plays_back_through_the_camera_interface(tmp_path) -> None:
    images = _images()
    path = tmp_path / "session.db3"
    assert write_recording(path, images) == len(images)
    cam = RealSenseCamera(path)
    k = cam.intrinsics
    assert (k.width, k.height) == (64, 48)
    assert k.fx == pytest.approx(60.0) and k.cy == pytest.approx(23.5)
    got = [cam.capture() for _ in images]
    for a, b in zip(images, got, strict=True):
        np.testing.assert_array_equal(b.rgb, a.rgb)
        np.testing.assert_allclose(b.depth, a.depth, atol=0.0006)  # millimetre depth units
        assert b.timestamp == pytest.approx(a.timestamp, abs=1e-3)
    with pytest.raises(RecordingError, match="no more frames"):
        cam.capture()
    cam.close()


def test_missing_or_bad_recordings_are_named(tmp_path) -> None:
    with pytest.raises(RecordingError, match="no RealSense recording"):
        RealSenseCamera(tmp_path / "absent.db3")
    broken = tmp_path / "broken.db3"
    broken.write_bytes(b"this is not a recording")
    with pytest.raises(RecordingError, match="cannot start"):
        RealSenseCamera(broken)
    with pytest.raises(InputError, match=".db3"):
        write_recording(tmp_path / "x.bag", _images(1))
