"""The twin's camera: frames pushed live into a librealsense software device and read back
through ``RealSenseCamera``'s real streaming code (no camera attached)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

pytest.importorskip(
    "pyrealsense2", reason="the real extra (pyrealsense2 + libusb) is not installed"
)

from cablesim.camera.realsense import RealSenseCamera  # noqa: E402
from cablesim.errors import InputError, RecordingError  # noqa: E402
from cablesim.frames import Intrinsics  # noqa: E402
from cablesim.twin.realsense import SoftwareRealSense  # noqa: E402

W, H = 64, 48
K = Intrinsics(60.0, 61.0, 31.5, 23.5, W, H)


def _frame(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame ``n``: every pixel's red value and depth (mm above 500) encode ``n``."""
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 0] = n % 256
    rgb[..., 1] = np.arange(W, dtype=np.uint8)[None, :]
    depth = np.full((H, W), 0.5 + 0.001 * (n % 200), np.float32)
    depth[:3] = 0.0  # no measurement stays no measurement
    return rgb, depth


class _Pusher:
    """Pushes frames at ``fps`` on a thread, pausing ``stall`` s after frame ``stall_at``."""

    def __init__(self, feed: SoftwareRealSense, fps: float, stall_at: int = -1, stall: float = 0.0):
        self.feed, self.period, self.stall_at, self.stall = feed, 1.0 / fps, stall_at, stall
        self.stop = threading.Event()
        self.stamps: list[float] = []
        self.t0 = time.monotonic()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        n = 0
        while not self.stop.is_set():
            stamp = time.monotonic() - self.t0
            # listed before it is pushed: the camera may hand the frame over before this
            # thread runs again (a CI run under load read a stamp the list did not hold yet)
            self.stamps.append(stamp)
            self.feed.push(*_frame(n), stamp)
            n += 1
            self.stop.wait(self.period + (self.stall if n == self.stall_at else 0.0))

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5.0)


def _check(img, pusher: _Pusher) -> int:
    n = int(img.rgb[5, 0, 0])
    np.testing.assert_array_equal(img.rgb[..., 1], np.arange(W)[None, :].repeat(H, 0))
    # depth and colour of the same frame (z16 in millimetres)
    assert img.depth[5:] == pytest.approx(0.5 + 0.001 * (n % 200), abs=6e-4)
    assert (img.depth[:3] == 0).all()
    assert any(abs(img.timestamp - s) < 1e-6 for s in pusher.stamps)
    return n


def test_live_software_device_reads_like_a_camera() -> None:
    T = np.eye(4)
    T[:3, 3] = (1.0, 2.0, 3.0)
    with SoftwareRealSense(K, fps=30) as feed:
        pusher = _Pusher(feed, fps=30)
        try:
            cam = feed.camera(T, timeout_s=2.0)
            k = cam.intrinsics
            assert (k.fx, k.fy, k.cx, k.cy, k.width, k.height) == (60.0, 61.0, 31.5, 23.5, W, H)
            assert cam._depth_scale == pytest.approx(0.001)
            np.testing.assert_array_equal(cam.T_world_camera, T)
            numbers = [_check(cam.capture(), pusher) for _ in range(10)]
            assert numbers == sorted(numbers) and len(set(numbers)) == 10  # live, in order
            cam.close()  # stops reading only: the device keeps streaming
            again = feed.camera(T, timeout_s=0.5)
            _check(again.capture(), pusher)
        finally:
            pusher.close()
    with pytest.raises(RecordingError, match="no frames"):  # the device stopped
        for _ in range(3):  # a frame set may still wait in the syncer
            again.capture()


def test_depth_and_colour_stay_paired_across_a_stall() -> None:
    """After a pause in the stream librealsense's syncer hands depth and colour over in
    separate frame sets; the camera pairs them by time, never across frames."""
    with SoftwareRealSense(K, fps=30) as feed:
        pusher = _Pusher(feed, fps=30, stall_at=8, stall=1.5)
        try:
            cam = feed.camera(timeout_s=3.0)
            t_end = time.monotonic() + 3.5
            numbers = []
            while time.monotonic() < t_end:
                numbers.append(_check(cam.capture(), pusher))
            assert max(numbers) > 8  # frames from after the stall were read
        finally:
            pusher.close()


def test_bad_use_is_named() -> None:
    with SoftwareRealSense(K) as feed:
        with pytest.raises(InputError, match="device= and syncer="):
            RealSenseCamera(device=feed.device)
        with pytest.raises(InputError, match="streams 64x48"):
            feed.push(np.zeros((10, 10, 3), np.uint8), np.zeros((10, 10), np.float32), 0.0)
    with pytest.raises(InputError, match="Intrinsics"):
        SoftwareRealSense((60.0, 60.0, 31.5, 23.5, W, H))  # type: ignore[arg-type]
