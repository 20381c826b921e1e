"""Videos that play everywhere: H.264 mp4 written frame by frame, checked when closed.

:class:`VideoWriter` tries, in order (``encoders``):

- ``"h264"``: libx264 through the ffmpeg binary that the ``imageio-ffmpeg`` wheel ships
  (yuv420p, ``+faststart``): plays in browsers, Jupyter, GitHub and every desktop player;
- ``"mp4v"``: OpenCV's MPEG-4 Part 2 encoder (desktop players only), when the first fails to
  start;
- an animated GIF (half size, at most ``max_gif_frames``) when no mp4 reads back.

A finished mp4 is kept only if OpenCV decodes as many frames as were written and its sample
entry (:func:`video_codec`) is the encoder's (``avc1`` or ``mp4v``).  The same frames give
the same bytes.
"""

from __future__ import annotations

import struct
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import imageio.v2 as imageio
import numpy as np

from cablesim.errors import ConfigError, InputError, RecordingError

ENCODERS = ("h264", "mp4v")
#: libx264's preset: ``veryfast`` encodes the README demo's 665 frames (640x480, crf 20) in
#: 2.0 s of ffmpeg CPU on one core against ``medium``'s 4.0 s, into a file of the same size
#: (1.23 against 1.21 MB; ``ultrafast`` 1.1 s but 4.9 MB); issue 21
PRESET = "veryfast"
FOURCC = {"h264": "avc1", "mp4v": "mp4v"}
_CONTAINERS = {b"moov", b"trak", b"mdia", b"minf", b"stbl"}


class VideoWriter:
    """An mp4 written frame by frame (``write(rgb)``, then ``close()`` -> the file kept)."""

    def __init__(
        self,
        path: str | Path,
        fps: float = 15.0,
        max_gif_frames: int = 300,
        encoders: Sequence[str] = ENCODERS,
        crf: int = 20,
    ) -> None:
        unknown = [e for e in encoders if e not in ENCODERS]
        if unknown:
            raise ValueError(f"unknown encoders {unknown}; choose from {ENCODERS}")
        self.path, self.fps = Path(path), float(fps)
        self.encoders, self.crf = tuple(encoders), int(crf)
        self.frames_written = 0
        self.encoder: str | None = None  # "h264" | "mp4v" | "gif" once known
        self.final_path: Path | None = None
        self._size: tuple[int, int] | None = None
        self._sink: Any = None
        self._gif: list[np.ndarray] = []
        self._max_gif = max_gif_frames

    # ------------------------------------------------------------------ writing
    def write(self, rgb: np.ndarray) -> None:
        h, w = rgb.shape[:2]
        if self._size is None:
            self._size = (w - w % 2, h - h % 2)  # yuv420p needs even sides
            self._open()
        frame = np.ascontiguousarray(rgb[: self._size[1], : self._size[0], :3], dtype=np.uint8)
        if frame.shape[:2] != (self._size[1], self._size[0]):
            frame = _pad(frame, self._size)
        if self._sink is not None:
            try:
                if self.encoder == "h264":
                    self._sink.send(frame.tobytes())
                else:
                    self._sink.write(np.ascontiguousarray(frame[..., ::-1]))
            except (OSError, RuntimeError, StopIteration):
                self._sink = None  # the encoder died; the GIF frames remain
        if len(self._gif) < self._max_gif:  # kept in case the mp4 does not read back
            self._gif.append(cv2.resize(frame, (frame.shape[1] // 2, frame.shape[0] // 2)))
        self.frames_written += 1

    def _open(self) -> None:
        assert self._size is not None
        for enc in self.encoders:
            sink = _open_h264(self.path, self._size, self.fps, self.crf) if enc == "h264" else None
            if enc == "mp4v":
                cvw = cv2.VideoWriter(
                    str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, self._size
                )
                sink = cvw if cvw.isOpened() else None
            if sink is not None:
                self._sink, self.encoder = sink, enc
                return

    # ------------------------------------------------------------------ closing
    def close(self) -> Path | None:
        """Finish the file; returns the path kept (the mp4, else a GIF, else None)."""
        if self._sink is not None:
            sink, self._sink = self._sink, None
            try:
                if self.encoder == "h264":
                    sink.close()
                else:
                    sink.release()
            except (OSError, RuntimeError):
                pass
            if (
                count_video_frames(self.path) == self.frames_written > 0
                and video_codec(self.path) == FOURCC[str(self.encoder)]
            ):
                self.final_path = self.path
                self._gif = []
                return self.final_path
        if self._gif:
            gif = self.path.with_suffix(".gif")
            imageio.mimsave(gif, self._gif[::2], duration=2.0 / self.fps, loop=0)
            self.final_path, self.encoder = gif, "gif"
            if self.path.exists():
                self.path.unlink()
        self._gif = []
        return self.final_path

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _pad(frame: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    out = np.zeros((size[1], size[0], 3), np.uint8)
    h, w = min(frame.shape[0], size[1]), min(frame.shape[1], size[0])
    out[:h, :w] = frame[:h, :w]
    return out


def _open_h264(
    path: Path, size: tuple[int, int], fps: float, crf: int, extra: Sequence[str] = ()
) -> Any:
    """A started imageio-ffmpeg frame sink writing H.264 (``extra``: more ffmpeg output
    options), or None if it cannot start."""
    try:
        import imageio_ffmpeg  # lazy: optional heavy package
    except ImportError:
        return None
    try:
        sink = imageio_ffmpeg.write_frames(
            str(path),
            size,
            fps=fps,
            codec="libx264",
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            quality=None,
            macro_block_size=2,
            ffmpeg_log_level="error",
            output_params=["-crf", str(crf), "-preset", PRESET, "-movflags", "+faststart", *extra],
        )
        sink.send(None)  # starts ffmpeg
    except (OSError, RuntimeError):
        return None
    return sink


def h264_roundtrip(frames: Sequence[np.ndarray], crf: int, fps: float = 15.0) -> list[np.ndarray]:
    """``frames`` (RGB uint8, one size) as an H.264 video shows them: encoded by libx264
    (yuv420p, ``crf``, :data:`PRESET`, one thread, so the same frames give the same result)
    and decoded again.  Blocks, ringing, smeared chroma and motion-predicted frames, as the
    published MovingCables videos have.  An odd last row or column keeps its pixels."""
    if not frames:
        return []
    if not 0 <= int(crf) <= 51:
        raise ConfigError("crf", f"must be in [0, 51], got {crf}")
    h, w = frames[0].shape[:2]
    size = (w - w % 2, h - h % 2)
    if min(size) < 2:
        raise InputError(f"frames of {w}x{h} are too small for H.264")
    try:
        import imageio_ffmpeg  # lazy: optional heavy package
    except ImportError as e:
        raise RecordingError(f"H.264 needs the imageio-ffmpeg package: {e}") from None
    with tempfile.TemporaryDirectory(prefix="cablesim-h264-") as tmp:
        path = Path(tmp) / "clip.mp4"
        sink = _open_h264(path, size, fps, int(crf), ("-threads", "1"))
        if sink is None:
            raise RecordingError("the H.264 encoder (libx264 through imageio-ffmpeg) did not start")
        for f in frames:
            if f.shape[:2] != (h, w):
                raise InputError(f"frames differ in size: {f.shape[:2]} against {(h, w)}")
            sink.send(np.ascontiguousarray(f[: size[1], : size[0], :3], dtype=np.uint8).tobytes())
        sink.close()
        reader = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgb24")
        next(reader)  # the stream's metadata
        decoded = [np.frombuffer(b, np.uint8).reshape(size[1], size[0], 3).copy() for b in reader]
    if len(decoded) != len(frames):
        raise RecordingError(f"H.264 gave back {len(decoded)} of {len(frames)} frames")
    out = []
    for f, d in zip(frames, decoded, strict=True):
        full = np.array(f[..., :3], dtype=np.uint8, copy=True)
        full[: size[1], : size[0]] = d
        out.append(full)
    return out


def count_video_frames(path: str | Path) -> int:
    """Frames OpenCV can decode from a video file (0 if it cannot be opened)."""
    cap = cv2.VideoCapture(str(path))
    n = 0
    try:
        while cap.isOpened():
            ok, _ = cap.read()
            if not ok:
                break
            n += 1
    finally:
        cap.release()
    return n


def video_codec(path: str | Path) -> str | None:
    """The sample-entry code of the first video track of an mp4 (``"avc1"`` for H.264,
    ``"mp4v"`` for MPEG-4 Part 2, ...), read from its ``stsd`` box; None if there is none."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        return None
    return _find_codec(data, 0, len(data))


def _boxes(data: bytes, start: int, end: int):
    pos = start
    while pos + 8 <= end:
        size, kind = struct.unpack(">I4s", data[pos : pos + 8])
        header = 8
        if size == 1 and pos + 16 <= end:
            size, header = struct.unpack(">Q", data[pos + 8 : pos + 16])[0], 16
        elif size == 0:
            size = end - pos
        if size < header or pos + size > end:
            return
        yield kind, pos + header, pos + size
        pos += size


def _find_codec(data: bytes, start: int, end: int) -> str | None:
    for kind, body, stop in _boxes(data, start, end):
        if kind == b"trak":
            if not _is_video_track(data, body, stop):
                continue
        if kind in _CONTAINERS:
            found = _find_codec(data, body, stop)
            if found:
                return found
        elif kind == b"stsd" and stop - body >= 16:
            # version/flags (4), entry count (4), then the first entry: size (4), code (4)
            return data[body + 12 : body + 16].decode("latin-1")
    return None


def _is_video_track(data: bytes, start: int, end: int) -> bool:
    """A ``trak`` whose ``mdia/hdlr`` handler is ``vide`` (or that has no handler box)."""
    for kind, body, stop in _boxes(data, start, end):
        if kind == b"mdia":
            for k2, b2, _s2 in _boxes(data, body, stop):
                if k2 == b"hdlr":
                    # version/flags (4), pre_defined (4), handler_type (4)
                    return data[b2 + 8 : b2 + 12] == b"vide"
    return True
