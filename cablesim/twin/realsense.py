"""The twin's camera: frames pushed live into a librealsense software device.

    feed = SoftwareRealSense(intrinsics, fps=15)           # device + sensors, streaming
    feed.push(rgb, depth, stamp)                           # one frame (stamp: seconds)
    camera = feed.camera(T_world_camera)                   # RealSenseCamera on the device
    img = camera.capture()                                 # through the real camera code
    feed.close()

The device has a depth sensor (z16 in ``depth_unit`` metres, the D4xx default 1 mm) and a
colour sensor (rgb8), registered to each other (identity extrinsics, the same intrinsics), and
a timestamp matcher; both sensors stream into one ``rs.syncer`` that
:class:`~cablesim.camera.realsense.RealSenseCamera` then reads like a camera's pipeline.  The
frame timestamps are the ``stamp`` given to :meth:`push` in milliseconds: librealsense's syncer
only pairs frames whose timestamps count from about zero (with timestamps of a monotonic
clock, some 10^6 ms, it passes depth and colour on separately), so a twin stamps its frames
with the seconds since its frame clock started.  After a pause in the stream the syncer hands
depth and colour over in separate frame sets for a while; its queue holds ``queue_size`` = 2
sets so that a depth set is not replaced by the colour set of the same frame before the camera
reads it (``RealSenseCamera`` pairs the two by time).  ``push`` copies the pixels; it may be
called from any thread (the twin calls it on its own).
"""

from __future__ import annotations

import threading

import numpy as np

from cablesim.camera.realsense import RealSenseCamera
from cablesim.errors import InputError
from cablesim.frames import Intrinsics


def _rs():
    try:
        import pyrealsense2 as rs  # lazy: optional heavy package
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise ImportError(
            "the twin's RealSense feed needs pyrealsense2: pip install 'cablesim[real]'"
        ) from e
    return rs


class SoftwareRealSense:
    """A live librealsense software device fed with RGB-D frames (module docstring)."""

    SERIAL = "cablesim-twin"

    def __init__(
        self,
        intrinsics: Intrinsics,
        fps: int = 15,
        depth_unit: float = 0.001,
        queue_size: int = 2,
    ) -> None:
        rs = _rs()
        self._rs = rs
        if not isinstance(intrinsics, Intrinsics):
            raise InputError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")
        if not 0 < depth_unit <= 0.01:
            raise InputError(f"depth_unit must be in (0, 0.01] m, got {depth_unit}")
        self.intrinsics = intrinsics
        self.fps = int(fps)
        self.depth_unit = float(depth_unit)
        self.width, self.height = int(intrinsics.width), int(intrinsics.height)
        intr = rs.intrinsics()
        intr.width, intr.height = self.width, self.height
        intr.fx, intr.fy, intr.ppx, intr.ppy = (
            intrinsics.fx,
            intrinsics.fy,
            intrinsics.cx,
            intrinsics.cy,
        )
        intr.model, intr.coeffs = rs.distortion.none, [0.0] * 5
        self.device = rs.software_device()
        self.device.register_info(rs.camera_info.name, "cablesim digital twin")
        self.device.register_info(rs.camera_info.serial_number, self.SERIAL)
        self.device.create_matcher(rs.matchers.default)
        self._depth_sensor = self.device.add_sensor("Stereo Module")
        self._color_sensor = self.device.add_sensor("RGB Camera")
        profiles = []
        for sensor, stream, fmt, bpp, uid in (
            (self._depth_sensor, rs.stream.depth, rs.format.z16, 2, 0),
            (self._color_sensor, rs.stream.color, rs.format.rgb8, 3, 1),
        ):
            vs = rs.video_stream()
            vs.type, vs.index, vs.uid = stream, 0, uid
            vs.width, vs.height, vs.fps, vs.bpp, vs.fmt = (
                self.width,
                self.height,
                self.fps,
                bpp,
                fmt,
            )
            vs.intrinsics = intr
            profiles.append(sensor.add_video_stream(vs))
        identity = rs.extrinsics()
        identity.rotation, identity.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
        profiles[0].register_extrinsics_to(profiles[1], identity)
        self._depth_sensor.add_read_only_option(rs.option.depth_units, self.depth_unit)
        self._profiles = [p.as_video_stream_profile() for p in profiles]
        self.syncer = rs.syncer(queue_size)
        for sensor, prof in zip((self._depth_sensor, self._color_sensor), profiles, strict=True):
            sensor.open(prof)
            sensor.start(self.syncer)
        self._lock = threading.Lock()
        self._closed = False
        self.frames = 0

    def push(self, rgb: np.ndarray, depth: np.ndarray, stamp: float) -> None:
        """One frame: ``rgb`` HxWx3 uint8, ``depth`` HxW metres (0 = none), ``stamp`` in
        seconds on the feed's clock (counting from about 0)."""
        rs = self._rs
        h, w = self.height, self.width
        if rgb.shape != (h, w, 3) or depth.shape != (h, w):
            raise InputError(
                f"frame is {rgb.shape}/{depth.shape}, the device streams {w}x{h} RGB and depth"
            )
        z16 = np.clip(np.rint(np.nan_to_num(depth, nan=0.0) / self.depth_unit), 0, 65535)
        pixels = (np.ascontiguousarray(z16.astype(np.uint16)), np.ascontiguousarray(rgb, np.uint8))
        with self._lock:
            if self._closed:
                return
            n = self.frames
            for sensor, prof, px, bpp in (
                (self._depth_sensor, self._profiles[0], pixels[0], 2),
                (self._color_sensor, self._profiles[1], pixels[1], 3),
            ):
                f = rs.software_video_frame()
                f.pixels, f.bpp, f.stride = px, bpp, w * bpp  # copied by librealsense
                f.timestamp, f.frame_number = float(stamp) * 1000.0, n
                f.domain, f.profile = rs.timestamp_domain.hardware_clock, prof
                sensor.on_video_frame(f)
            self.frames += 1

    def camera(self, T_world_camera: np.ndarray | None = None, timeout_s: float = 2.0):
        """A :class:`~cablesim.camera.realsense.RealSenseCamera` reading this device."""
        return RealSenseCamera(
            T_world_camera=T_world_camera,
            timeout_s=timeout_s,
            device=self.device,
            syncer=self.syncer,
        )

    def close(self) -> None:
        """Stop the sensors (a camera reading them then times out)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            for sensor in (self._depth_sensor, self._color_sensor):
                sensor.stop()
                sensor.close()

    def __enter__(self) -> SoftwareRealSense:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
