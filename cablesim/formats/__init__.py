"""Readers and writers of the formats cablesim exchanges with the outside world (SPEC section 8).

- :mod:`~cablesim.formats.mcor`: the published motion-correlation sequences (CMCor), their
  annotations and multi-grasp lists;
- :mod:`~cablesim.formats.movingcables`: MovingCables clips and flow PNGs, and the published
  flow evaluation of a clip;
- :mod:`~cablesim.formats.gripper_log`: a RealSense ``.db3`` recording paired with a gripper log;
- cablesim's own recordings are :mod:`cablesim.recording`.

``detect_layout(path)`` names the layout of a path and ``read_any(path)`` reads any
interaction layout as a :class:`~cablesim.frames.Stream`.  NumPy/OpenCV only: this
package never imports the simulator.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from cablesim.errors import RecordingError
from cablesim.formats.gripper_log import read_realsense
from cablesim.formats.mcor import read_mcor
from cablesim.formats.movingcables import RGB_FOLDERS
from cablesim.frames import Stream
from cablesim.recording import FORMAT, read_stream

LAYOUTS = ("cablesim-recording", "mcor", "movingcables", "realsense")


def detect_layout(path: str | os.PathLike[str]) -> str:
    """``cablesim-recording``, ``mcor``, ``movingcables`` or ``realsense`` (a ``.db3`` file)."""

    p = Path(path)
    if p.is_file():
        if p.suffix == ".db3":
            return "realsense"
        raise RecordingError(f"{p}: a file, but not a RealSense .db3 recording")
    if not p.is_dir():
        raise RecordingError(f"{p}: no such file or folder")
    meta = p / "meta.json"
    if meta.is_file():
        try:
            if json.loads(meta.read_text()).get("format") == FORMAT:
                return "cablesim-recording"
        except (OSError, ValueError, AttributeError):
            pass
    if (p / "actions_gripper.json").is_file():
        return "mcor"
    if any((p / d).is_dir() for d in RGB_FOLDERS) or p.parent.name in RGB_FOLDERS:
        return "movingcables"
    raise RecordingError(
        f"{p}: not a cablesim recording (meta.json), a motion-correlation sequence "
        "(actions_gripper.json), a MovingCables split or clip, or a RealSense .db3 file"
    )


def read_any(
    path: str | os.PathLike[str],
    gripper_log: str | os.PathLike[str] | None = None,
    annotations: str | os.PathLike[str] | None = "auto",
    time_offset: float = 0.0,
) -> Stream:
    """The interaction stream at ``path``, whatever its layout (a ``.db3`` recording needs its
    ``gripper_log``; MovingCables clips have no gripper and are not interaction streams)."""
    layout = detect_layout(path)
    if layout == "cablesim-recording":
        return read_stream(path)
    if layout == "mcor":
        return read_mcor(path, annotations).stream
    if layout == "realsense":
        if gripper_log is None:
            raise RecordingError(f"{path}: a RealSense recording needs its gripper log")

        return read_realsense(path, gripper_log, time_offset)
    raise RecordingError(
        f"{path}: a MovingCables folder holds clips without a gripper, not an interaction"
    )


__all__ = ["LAYOUTS", "detect_layout", "read_any"]
