"""A gripper log beside a RealSense recording, so a real interaction can be segmented.

The robot side writes one JSON object per line (``cablesim-gripper-log``, version 1)::

    {"format": "cablesim-gripper-log", "version": 1, "frame": "camera",
     "robot_base_to_camera_transform": [[...], [...], [...], [...]]}      <- header, first line
    {"t": 12.3456, "action": 0, "position": [0.012, -0.034, 0.981]}        <- one per sample
    ...

- ``t``: seconds on the camera's clock (the RealSense frame timestamp / 1000); records in
  increasing time.  ``time_offset`` (seconds, added to the log's times) corrects a known
  offset between the two clocks.
- ``action``: the action index (0, 1, ...), -1 when the gripper is not in an action
  (approach, release, retreat).
- ``position``: the gripper (TCP) in metres, in the header's ``frame``: ``"camera"`` (OpenCV
  axes) or ``"base"`` (the robot base frame; then the header needs
  ``robot_base_to_camera_transform``, camera point = T [base point; 1], as in the published
  motion-correlation format).

Pairing by time: an image at time t gets the position interpolated linearly between the two
records around t and the action of the record at or before t; images before the first or after
the last record, or whose records around them are more than ``max_gap`` seconds apart, are not
part of any action (-1).  The last image of the recording is the target frame.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cablesim.camera.realsense import RealSenseCamera
from cablesim.errors import InputError, RecordingError
from cablesim.frames import TARGET_ACTION, Frame, Stream

FORMAT = "cablesim-gripper-log"
VERSION = 1


@dataclass
class GripperLog:
    """Records of a gripper log, positions already in the camera frame."""

    t: np.ndarray  # (N,) seconds
    action: np.ndarray  # (N,) int
    position: np.ndarray  # (N, 3) metres, camera frame

    def pair(self, times: Sequence[float], max_gap: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
        """(positions (M, 3), actions (M,)) at image ``times`` (module docstring)."""
        ts = np.asarray(times, np.float64)
        pos = np.empty((len(ts), 3))
        act = np.full(len(ts), TARGET_ACTION, np.int64)
        for j, t in enumerate(ts):
            i = int(np.searchsorted(self.t, t, side="right"))  # records[i-1] <= t < records[i]
            if i == 0:
                pos[j] = self.position[0]
                continue
            if i == len(self.t):
                pos[j] = self.position[-1]
                if t == self.t[-1]:
                    act[j] = self.action[-1]
                continue
            t0, t1 = self.t[i - 1], self.t[i]
            w = (t - t0) / (t1 - t0)
            pos[j] = (1 - w) * self.position[i - 1] + w * self.position[i]
            if t1 - t0 <= max_gap:
                act[j] = self.action[i - 1]
        return pos, act


def write_gripper_log(
    path: str | os.PathLike[str],
    records: Iterable[tuple[float, int, Sequence[float]]],
    frame: str = "camera",
    base_to_camera: np.ndarray | None = None,
) -> Path:
    """Write (t, action, position) records as a gripper log."""
    if frame not in ("camera", "base"):
        raise InputError(f"frame must be 'camera' or 'base', got {frame!r}")
    header: dict[str, Any] = {"format": FORMAT, "version": VERSION, "frame": frame}
    if base_to_camera is not None:
        header["robot_base_to_camera_transform"] = np.asarray(base_to_camera, float).tolist()
    elif frame == "base":
        raise InputError("a base-frame gripper log needs base_to_camera")
    lines = [json.dumps(header)]
    for t, a, p in records:
        lines.append(
            json.dumps({"t": float(t), "action": int(a), "position": [float(x) for x in p]})
        )
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path


def read_gripper_log(path: str | os.PathLike[str]) -> GripperLog:
    """Read and check a gripper log (module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"gripper log not found: {path}")
    lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    if not lines:
        raise RecordingError(f"{path}: empty gripper log")
    try:
        header = json.loads(lines[0])
    except json.JSONDecodeError as e:
        raise RecordingError(f"{path}: line 1 is not JSON ({e})") from e
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise RecordingError(f"{path}: line 1 must be the header with format {FORMAT!r}")
    if header.get("version") != VERSION:
        raise RecordingError(f"{path}: unknown version {header.get('version')!r}")
    frame = header.get("frame")
    if frame not in ("camera", "base"):
        raise RecordingError(f"{path}: header frame must be 'camera' or 'base', got {frame!r}")
    T = header.get("robot_base_to_camera_transform")
    if T is not None:
        T = np.asarray(T, np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise RecordingError(f"{path}: robot_base_to_camera_transform must be 4x4")
    if frame == "base" and T is None:
        raise RecordingError(f"{path}: a base-frame log needs robot_base_to_camera_transform")
    ts, acts, ps = [], [], []
    for n, ln in enumerate(lines[1:], 2):
        try:
            r = json.loads(ln)
            t, a, p = float(r["t"]), r["action"], np.asarray(r["position"], np.float64)
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as e:
            raise RecordingError(f"{path}: line {n} is not a record t/action/position ({e})") from e
        if not isinstance(a, int) or p.shape != (3,) or not np.all(np.isfinite(p)):
            raise RecordingError(f"{path}: line {n}: action must be an int and position [x, y, z]")
        if not np.isfinite(t) or (ts and t <= ts[-1]):
            raise RecordingError(f"{path}: line {n}: times must be finite and increasing")
        ts.append(t)
        acts.append(a)
        ps.append(p)
    if not ts:
        raise RecordingError(f"{path}: no records after the header")
    pos = np.array(ps)
    if frame == "base":
        h = np.c_[pos, np.ones(len(pos))] @ T.T
        pos = h[:, :3] / h[:, 3:]
    return GripperLog(np.array(ts), np.array(acts, np.int64), pos)


def read_realsense(
    recording: str | os.PathLike[str],
    gripper_log: str | os.PathLike[str],
    time_offset: float = 0.0,
    max_gap: float = 0.1,
) -> Stream:
    """A RealSense ``.db3`` recording and its gripper log as a :class:`Stream`."""

    log = read_gripper_log(gripper_log)
    log.t = log.t + float(time_offset)
    cam = RealSenseCamera(recording)
    images = []
    try:
        while True:
            try:
                images.append(cam.capture())
            except RecordingError:
                break
    finally:
        cam.close()
    if not images:
        raise RecordingError(f"{recording}: no frames")
    pos, act = log.pair([im.timestamp for im in images], max_gap)
    act[-1] = TARGET_ACTION
    counters: dict[int, int] = {}
    frames = []
    for im, p, a in zip(images, pos, act, strict=True):
        k = counters.get(int(a), 0)
        counters[int(a)] = k + 1
        frames.append(Frame(im.rgb, im.depth, im.intrinsics, p, int(a), k, float(im.timestamp)))
    meta = {
        "layout": "realsense",
        "source": str(recording),
        "gripper_log": str(gripper_log),
        "time_offset": float(time_offset),
    }
    return Stream(frames, meta)
