"""Intel RealSense (D4xx, e.g. the D456) as a ``Camera``, live or from a recording.

    cam = RealSenseCamera()                          # the first connected camera, 640x480 @ 15 fps
    cam = RealSenseCamera("session.db3")             # a RealSense recording, frame by frame
    cam = RealSenseCamera(device=dev, syncer=sync)   # a device already streaming into a syncer
    img = cam.capture()                              # depth aligned to colour, in metres

``write_recording`` turns any sequence of ``CameraImage`` (for example from ``SimCamera``) into a
RealSense recording through librealsense's software device, so the real-camera code path can be
exercised and tested with no camera attached.  A recording is read whole (every frame,
not real time) when the camera is opened.  ``device``/``syncer`` open a camera on a device
whose depth and colour sensors somebody else already started into an ``rs.syncer``, e.g. a
software device fed frame by frame while it runs (the digital twin, :mod:`cablesim.twin`);
frames are then read exactly as from a camera.  Requires the ``real`` extra (``pyrealsense2``;
on Debian also ``libusb-1.0-0``).  librealsense 2.59 writes and reads ``.db3`` recordings.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from cablesim.camera.base import Camera, CameraImage
from cablesim.errors import InputError, RecordingError
from cablesim.frames import Intrinsics


def _rs():
    try:
        import pyrealsense2 as rs  # lazy: optional heavy package
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise ImportError(
            "RealSenseCamera needs pyrealsense2: pip install 'cablesim[real]' "
            "(and on Debian: apt-get install libusb-1.0-0)"
        ) from e
    return rs


class RealSenseCamera(Camera):
    """Colour + depth aligned to colour from a RealSense device or a recording."""

    def __init__(
        self,
        source: str | Path | None = None,
        width: int = 640,
        height: int = 480,
        fps: int = 15,
        serial: str | None = None,
        T_world_camera: np.ndarray | None = None,
        timeout_s: float = 2.0,
        *,
        device=None,
        syncer=None,
    ):
        rs = _rs()
        self._rs = rs
        self._timeout_ms = int(timeout_s * 1000)
        self._T = None if T_world_camera is None else np.asarray(T_world_camera, float)
        if self._T is not None and self._T.shape != (4, 4):
            raise InputError(f"T_world_camera must be 4x4, got {self._T.shape}")
        self.source = None if source is None else Path(source)
        self._closed = False
        self._owns_pipe = True
        if self.source is not None:
            self._open_recording(self.source)
            return
        if device is not None or syncer is not None:
            self._open_streaming_device(device, syncer)
            return
        self._pipe = rs.pipeline()
        cfg = rs.config()
        if serial:
            cfg.enable_device(serial)
        cfg.enable_stream(rs.stream.depth, width, height, rs.format.z16, fps)
        cfg.enable_stream(rs.stream.color, width, height, rs.format.rgb8, fps)
        try:
            profile = self._pipe.start(cfg)
        except RuntimeError as e:
            raise RecordingError(f"cannot start RealSense streaming from a camera: {e}") from e
        self._depth_scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
        color = profile.get_stream(rs.stream.color).as_video_stream_profile()
        depth = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        self._align = None if _same_camera(depth, color) else rs.align(rs.stream.color)
        self._intrinsics = _intrinsics(color)

    def _open_streaming_device(self, device, syncer) -> None:
        """Read a device whose depth and colour sensors already stream into ``syncer``; the
        caller owns the device and stops its sensors (``close`` only stops reading)."""
        rs = self._rs
        if device is None or syncer is None:
            raise InputError("a streaming device needs both device= and syncer=")
        depth = color = None
        scale = 0.001
        for sensor in device.query_sensors():
            for p in sensor.get_active_streams():
                if p.stream_type() == rs.stream.depth:
                    depth = p.as_video_stream_profile()
                    if sensor.is_depth_sensor():
                        scale = float(sensor.as_depth_sensor().get_depth_scale())
                elif p.stream_type() == rs.stream.color:
                    color = p.as_video_stream_profile()
        if depth is None or color is None:
            raise RecordingError(
                "the RealSense device streams no depth and colour: start its sensors into the "
                "syncer first"
            )
        self._depth_scale = scale
        self._intrinsics = _intrinsics(color)
        self._align = None if _same_camera(depth, color) else rs.align(rs.stream.color)
        self._pipe, self._owns_pipe = syncer, False

    def _open_recording(self, path: Path) -> None:
        """Read a whole recording (non-real-time, nothing dropped) into memory, paired by time."""
        rs = self._rs
        if not path.is_file():
            raise RecordingError(f"no RealSense recording at {path}")
        try:
            device = rs.context().load_device(str(path))
        except RuntimeError as e:
            raise RecordingError(f"cannot start RealSense playback of {path}: {e}") from e
        playback = device.as_playback()
        playback.set_real_time(False)
        got: dict[float, dict[str, object]] = {}
        profiles: dict[str, object] = {}

        def on_frame(f) -> None:
            kind = f.get_profile().stream_type()
            name = (
                "depth" if kind == rs.stream.depth else "color" if kind == rs.stream.color else ""
            )
            if name:
                arr = np.asanyarray(f.as_video_frame().get_data()).copy()
                got.setdefault(f.get_timestamp(), {})[name] = arr
                profiles[name] = f.get_profile().as_video_stream_profile()

        sensors = device.query_sensors()
        scale = 0.001
        for sensor in sensors:
            if sensor.is_depth_sensor():
                scale = float(sensor.as_depth_sensor().get_depth_scale())
            sensor.open(sensor.get_stream_profiles())
        # playback begins with the first started sensor: hold it until every sensor listens,
        # or the first frames of the others are lost
        playback.pause()
        for sensor in sensors:
            sensor.start(on_frame)
        playback.resume()
        # Done when playback has stopped and no frame arrived for a while: the status reads
        # "stopped" also before playback has begun, so the status alone is not enough.
        deadline = time.monotonic() + 60.0
        seen, quiet_since = -1, time.monotonic()
        while time.monotonic() < deadline:
            time.sleep(0.01)
            count = sum(len(v) for v in got.values())
            if count != seen:
                seen, quiet_since = count, time.monotonic()
            elif (
                playback.current_status() == rs.playback_status.stopped
                and time.monotonic() - quiet_since > 0.3
            ):
                break
        for sensor in sensors:
            sensor.stop()
            sensor.close()
        if "depth" not in profiles or "color" not in profiles:
            raise RecordingError(f"{path} holds no depth and colour streams")
        self._depth_scale = scale
        self._intrinsics = _intrinsics(profiles["color"])
        self._align = None
        if not _same_camera(profiles["depth"], profiles["color"]):
            raise RecordingError(
                f"{path}: depth and colour are not registered; record them aligned"
            )
        self._frames = [
            (t, v["depth"], v["color"])
            for t, v in sorted(got.items())
            if "depth" in v and "color" in v
        ]
        self._next = 0

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    @property
    def T_world_camera(self) -> np.ndarray | None:
        return self._T

    def capture(self) -> CameraImage:
        if self._closed:
            raise RecordingError("the RealSense camera was closed")
        if self.source is not None:
            if self._next >= len(self._frames):
                raise RecordingError(f"the recording {self.source} has no more frames")
            t, d, rgb = self._frames[self._next]
            self._next += 1
            z = d.astype(np.float32) * np.float32(self._depth_scale)
            return CameraImage(np.ascontiguousarray(rgb, np.uint8), z, t / 1000.0, self._intrinsics)
        depth = color = None
        for _ in range(8):
            ok, frames = self._pipe.try_wait_for_frames(self._timeout_ms)
            if not ok:
                what = (
                    f"the recording {self.source} has no more frames"
                    if self.source
                    else (f"no frames from the camera within {self._timeout_ms} ms")
                )
                raise RecordingError(what)
            if self._align is not None:
                frames = self._align.process(frames)
            depth = frames.get_depth_frame() or depth
            color = frames.get_color_frame() or color
            # a frame set may hold one stream only (at the start, or after a stall); depth and
            # colour from different sets are paired only when they are of the same instant
            if depth and color and _same_instant(depth, color):
                break
        else:
            raise RecordingError("no matching depth and colour frames in 8 frame sets")
        rgb = np.asanyarray(color.get_data())
        if color.get_profile().format() == self._rs.format.bgr8:
            rgb = rgb[..., ::-1]
        z = np.asanyarray(depth.get_data()).astype(np.float32) * np.float32(self._depth_scale)
        return CameraImage(
            np.ascontiguousarray(rgb, dtype=np.uint8),
            z,
            color.get_timestamp() / 1000.0,
            self._intrinsics,
        )

    def close(self) -> None:
        if not self._closed:
            if self.source is None and self._owns_pipe:
                self._pipe.stop()
            self._closed = True


def _intrinsics(profile) -> Intrinsics:
    i = profile.get_intrinsics()
    return Intrinsics(i.fx, i.fy, i.ppx, i.ppy, i.width, i.height)


def _same_instant(depth, color) -> bool:
    """Whether a depth and a colour frame were taken within half a frame period."""
    fps = color.get_profile().fps() or 15
    return abs(depth.get_timestamp() - color.get_timestamp()) <= 500.0 / fps


def _same_camera(depth, color) -> bool:
    """Whether depth is already registered to colour (same intrinsics, identity extrinsics)."""
    i, j = color.get_intrinsics(), depth.get_intrinsics()
    ext = depth.get_extrinsics_to(color)
    return (
        (i.width, i.height, i.fx, i.fy, i.ppx, i.ppy)
        == (j.width, j.height, j.fx, j.fy, j.ppx, j.ppy)
        and np.allclose(ext.rotation, np.eye(3).ravel())
        and np.allclose(ext.translation, 0)
    )


def write_recording(
    path: str | Path,
    images: Iterable[CameraImage],
    depth_unit: float = 0.001,
    fps: int = 15,
) -> int:
    """Write ``images`` (all of one size) as a RealSense ``.db3`` recording; returns the count.

    The file is read back once: librealsense's recorder runs on its own threads, and a
    recording that lost a frame raises ``RecordingError`` instead of passing silently."""
    n = _write_once(path, list(images), depth_unit, fps)
    cam = RealSenseCamera(path)
    held = len(cam._frames)
    cam.close()
    if held != n:
        raise RecordingError(f"librealsense kept {held} of {n} frames in {path}")
    return n


def _write_once(
    path: str | Path,
    images: Iterable[CameraImage],
    depth_unit: float = 0.001,
    fps: int = 15,
) -> int:
    """Write ``images`` (all of one size) as a RealSense ``.db3`` recording; returns the count."""
    rs = _rs()
    path = Path(path)
    if path.suffix != ".db3":
        raise InputError(f"librealsense writes .db3 recordings, got {path.name}")
    it = iter(images)
    first = next(it, None)
    if first is None:
        raise InputError("no images to record")
    k = first.intrinsics
    w, h = int(k.width), int(k.height)
    intr = rs.intrinsics()
    intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = w, h, k.fx, k.fy, k.cx, k.cy
    intr.model, intr.coeffs = rs.distortion.none, [0.0] * 5

    device = rs.software_device()
    depth_sensor, color_sensor = device.add_sensor("Stereo Module"), device.add_sensor("RGB Camera")
    profiles = []
    for sensor, stream, fmt, bpp, uid in (
        (depth_sensor, rs.stream.depth, rs.format.z16, 2, 0),
        (color_sensor, rs.stream.color, rs.format.rgb8, 3, 1),
    ):
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height = stream, 0, uid, w, h
        vs.fps, vs.bpp, vs.fmt, vs.intrinsics = fps, bpp, fmt, intr
        profiles.append(sensor.add_video_stream(vs))
    identity = rs.extrinsics()
    identity.rotation, identity.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    profiles[0].register_extrinsics_to(profiles[1], identity)
    depth_sensor.add_read_only_option(rs.option.depth_units, depth_unit)

    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists():
        path.unlink()
    recorder = rs.recorder(str(path), device)
    queue = rs.frame_queue(64)
    for sensor, prof in zip((depth_sensor, color_sensor), profiles, strict=True):
        sensor.open(prof)
        sensor.start(queue)
    count = 0
    try:
        for n, img in enumerate(_chain(first, it)):
            if img.rgb.shape[:2] != (h, w):
                raise InputError(
                    f"image {n} is {img.rgb.shape[1]}x{img.rgb.shape[0]}, the recording is {w}x{h}"
                )
            depth = np.nan_to_num(img.depth, nan=0.0) / depth_unit
            z16 = np.clip(np.round(depth), 0, 65535).astype(np.uint16)
            for sensor, prof, pixels, bpp in (
                (depth_sensor, profiles[0], z16, 2),
                (color_sensor, profiles[1], img.rgb, 3),
            ):
                f = rs.software_video_frame()
                f.pixels, f.bpp, f.stride = np.ascontiguousarray(pixels), bpp, w * bpp
                f.timestamp, f.frame_number = img.timestamp * 1000.0, n
                f.domain, f.profile = (
                    rs.timestamp_domain.hardware_clock,
                    prof.as_video_stream_profile(),
                )
                sensor.on_video_frame(f)
                queue.wait_for_frame(5000)  # it went through the recorder
            count += 1
        time.sleep(0.1)
    finally:
        for sensor in (depth_sensor, color_sensor):
            sensor.stop()
            sensor.close()
        del recorder
    return count


def _chain(first: CameraImage, rest: Iterable[CameraImage]) -> Iterable[CameraImage]:
    yield first
    yield from rest
