"""A recorded stream replayed through the :class:`~cablesim.camera.base.Camera` interface.

    cam = ReplayCamera("runs/ep0")          # a directory written by RecordingWriter
    img = cam.capture()                     # frame 0, then 1, ...; RecordingError at the end
    frame = cam.last_frame                  # the full Frame (gripper, action, sample)
    stream = cam.stream()                   # everything as a Stream

Pure NumPy: it never imports MuJoCo.  Replayed images carry the recorded timestamps.
"""

from __future__ import annotations

import os

import numpy as np

from cablesim.camera.base import Camera, CameraImage
from cablesim.errors import RecordingError
from cablesim.frames import Frame, Intrinsics, Stream
from cablesim.recording import Recording


def _pose(T: object, path: os.PathLike[str]) -> np.ndarray | None:
    """The recorded camera pose as a 4x4 rigid transform, or ``RecordingError`` naming it."""
    if T is None:
        return None
    where = f"{os.fspath(path)}/meta.json: meta.T_world_camera"
    try:
        M = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise RecordingError(f"{where} is not a 4x4 matrix of numbers ({e})") from e
    if M.shape != (4, 4):
        raise RecordingError(f"{where} must be a 4x4 matrix, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise RecordingError(f"{where} holds non-finite values")
    R = M[:3, :3]
    if not np.allclose(M[3], [0, 0, 0, 1]) or not np.allclose(R.T @ R, np.eye(3), atol=1e-3):
        raise RecordingError(f"{where} is not a rigid transform (rotation and translation)")
    return M


class ReplayCamera(Camera):
    """Replays the frames of a recording in order (``loop=True`` starts again at the end)."""

    def __init__(self, recording: str | os.PathLike[str] | Recording, loop: bool = False):
        self.recording = recording if isinstance(recording, Recording) else Recording(recording)
        if len(self.recording) == 0:
            raise RecordingError(f"{self.recording.path}: the recording has no frames")
        self.loop = loop
        self.position = 0
        self.last_frame: Frame | None = None
        self._T = _pose(self.recording.meta.get("T_world_camera"), self.recording.path)

    @property
    def intrinsics(self) -> Intrinsics:
        intr = self.recording.intrinsics
        if intr is None:  # pragma: no cover - a recording with frames always has them
            raise RecordingError(f"{self.recording.path}: no intrinsics")
        return intr

    @property
    def T_world_camera(self) -> np.ndarray | None:
        return None if self._T is None else self._T.copy()

    def __len__(self) -> int:
        return len(self.recording)

    def next_frame(self) -> Frame:
        """The next recorded frame (with gripper, indices and any ground truth)."""
        if self.position >= len(self.recording):
            if not self.loop:
                raise RecordingError(
                    f"{self.recording.path}: end of the recording ({len(self.recording)} frames)"
                )
            self.position = 0
        frame = self.recording.frame(self.position)
        self.position += 1
        self.last_frame = frame
        return frame

    def capture(self) -> CameraImage:
        f = self.next_frame()
        return CameraImage(f.rgb, f.depth, float(f.timestamp), f.intrinsics)

    def rewind(self) -> None:
        self.position = 0

    def stream(self) -> Stream:
        return self.recording.to_stream()
