"""Recording a frame stream to disk, frame by frame, and reading it back.

Format (``FORMAT = "cablesim-recording"``, ``VERSION = 1``), one directory::

    meta.json            {"format", "version", "intrinsics", "complete", "frames", "meta"}
    index.jsonl          one JSON line per file written, appended after the file is on disk:
                         {"kind": "frame"|"flow", "i", "file", "bytes", "sha256",
                          "action", "sample", "timestamp"}
    frames/000012.npz    compressed: rgb (HxWx3 uint8), depth (HxW float32 m), gripper (3,),
                         action, sample, timestamp, [gripper_quat (4,), gripper_opening,
                         labels (HxW int16), grasped_hose (-1 = none), arm_mask (HxW bool)]
    flow/000012.npz      compressed: flow_to_target (HxWx2 float32), flow_valid (HxW bool)

Every file is written to a temporary name, flushed, fsynced and renamed, then its index line
is appended and fsynced; ``meta.json`` is rewritten (atomically) with ``complete: true`` by
:meth:`RecordingWriter.close`.  An interrupted recording therefore keeps every frame whose
index line was written (a partial last index line is ignored); the reader then reports
``complete = False``.  A missing, truncated or corrupt file raises :class:`RecordingError`
naming the file and the frame.  Ground truth (labels, flow) is stored only when the frames
carry it; a real or replayed recording has none.  ``arm_mask`` (the kinematic arm mask, not
ground truth) is stored when the frame has one; recordings written before it existed read back
with ``arm_mask = None``.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from cablesim.errors import InputError, RecordingError
from cablesim.jsonutil import json_default
from cablesim.perception.frames import Frame, FrameTruth, Intrinsics, Stream

FORMAT = "cablesim-recording"
VERSION = 1


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def _npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def _frame_arrays(frame: Frame) -> dict[str, np.ndarray]:
    a: dict[str, np.ndarray] = {
        "rgb": np.ascontiguousarray(frame.rgb, np.uint8),
        "depth": np.ascontiguousarray(frame.depth, np.float32),
        "gripper": np.asarray(frame.gripper, np.float64),
        "action": np.int64(frame.action),
        "sample": np.int64(frame.sample),
        "timestamp": np.float64(frame.timestamp),
    }
    if frame.gripper_quat is not None:
        a["gripper_quat"] = np.asarray(frame.gripper_quat, np.float64)
    if frame.gripper_opening is not None:
        a["gripper_opening"] = np.float64(frame.gripper_opening)
    if frame.truth is not None:
        a["labels"] = np.asarray(frame.truth.labels, np.int16)
        gh = frame.truth.grasped_hose
        a["grasped_hose"] = np.int64(-1 if gh is None else gh)
    if frame.arm_mask is not None:
        a["arm_mask"] = np.asarray(frame.arm_mask, bool)
    return a


class RecordingWriter:
    """Writes frames (and later their ground-truth flow) as they come; usable as a
    :class:`~cablesim.episode.truth.FrameSink`."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        meta: dict[str, Any] | None = None,
        overwrite: bool = False,
    ):
        self.path = Path(path)
        if self.path.exists() and any(self.path.iterdir()):
            if not overwrite:
                raise RecordingError(f"{self.path} exists and is not empty (use overwrite)")
            for sub in ("frames", "flow"):
                for f in (self.path / sub).glob("*"):
                    f.unlink()
            for f in ("meta.json", "index.jsonl"):
                (self.path / f).unlink(missing_ok=True)
        (self.path / "frames").mkdir(parents=True, exist_ok=True)
        (self.path / "flow").mkdir(exist_ok=True)
        self.meta = dict(meta or {})
        self.intrinsics: Intrinsics | None = None
        self.frames = 0
        self.closed = False
        self._index = open(self.path / "index.jsonl", "a", encoding="utf-8")  # noqa: SIM115
        self._write_meta(complete=False)

    def _write_meta(self, complete: bool) -> None:
        doc = {
            "format": FORMAT,
            "version": VERSION,
            "intrinsics": None if self.intrinsics is None else self.intrinsics.to_dict(),
            "complete": complete,
            "frames": self.frames,
            "meta": self.meta,
        }
        _write_atomic(
            self.path / "meta.json", json.dumps(doc, indent=2, default=json_default).encode()
        )

    def _append_index(self, entry: dict[str, Any]) -> None:
        self._index.write(json.dumps(entry) + "\n")
        self._index.flush()
        os.fsync(self._index.fileno())

    def _write_file(
        self, kind: str, i: int, arrays: dict[str, np.ndarray], extra: dict[str, Any]
    ) -> None:
        if self.closed:
            raise RecordingError(f"{self.path}: the recording is closed")
        rel = f"{'frames' if kind == 'frame' else 'flow'}/{i:06d}.npz"
        data = _npz_bytes(arrays)
        _write_atomic(self.path / rel, data)
        self._append_index(
            {
                "kind": kind,
                "i": int(i),
                "file": rel,
                "bytes": len(data),
                "sha256": hashlib.sha256(data).hexdigest(),
                **extra,
            }
        )

    def add_frame(self, index: int, frame: Frame) -> None:
        if self.intrinsics is None:
            self.intrinsics = frame.intrinsics
            self._write_meta(complete=False)
        elif frame.intrinsics != self.intrinsics:
            raise InputError(f"frame {index} has other intrinsics than the recording")
        if index != self.frames:
            raise InputError(f"frames must be added in order: expected {self.frames}, got {index}")
        self._write_file(
            "frame",
            index,
            _frame_arrays(frame),
            {
                "action": int(frame.action),
                "sample": int(frame.sample),
                "timestamp": float(frame.timestamp),
            },
        )
        self.frames += 1

    def add_flow(self, index: int, flow: np.ndarray, valid: np.ndarray) -> None:
        if not 0 <= index < self.frames:
            raise InputError(f"flow for frame {index}, but {self.frames} frames were written")
        self._write_file(
            "flow",
            index,
            {"flow_to_target": np.asarray(flow, np.float32), "flow_valid": np.asarray(valid, bool)},
            {},
        )

    def close(self, meta: dict[str, Any] | None = None, complete: bool = True) -> None:
        if self.closed:
            return
        if meta:
            self.meta.update(meta)
        self._index.close()
        self._write_meta(complete=complete)
        self.closed = True

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # an exception leaves an incomplete (but readable) recording
        self.close(complete=exc_type is None)


def write_stream(stream: Stream, path: str | os.PathLike[str], overwrite: bool = False) -> Path:
    """Write a whole stream (with its ground truth, if any)."""
    with RecordingWriter(path, meta=stream.meta, overwrite=overwrite) as w:
        for i, f in enumerate(stream.frames):
            w.add_frame(i, f)
        for i, f in enumerate(stream.frames):
            if f.truth is not None and f.truth.flow_to_target is not None:
                valid = f.truth.flow_valid
                if valid is None:
                    valid = np.ones(f.shape, bool)
                w.add_flow(i, f.truth.flow_to_target, valid)
    return Path(path)


class Recording:
    """A recording on disk, read lazily; ``frame(i)`` loads and checks one frame."""

    def __init__(self, path: str | os.PathLike[str], verify: bool = True):
        self.path = Path(path)
        self.verify = verify
        meta_path = self.path / "meta.json"
        if not meta_path.is_file():
            raise RecordingError(f"{meta_path}: missing (not a cablesim recording)")
        try:
            doc = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise RecordingError(f"{meta_path}: unreadable ({e})") from e
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise RecordingError(f"{meta_path}: not a {FORMAT} file")
        if doc.get("version") != VERSION:
            raise RecordingError(f"{meta_path}: unknown version {doc.get('version')!r}")
        self.complete = bool(doc.get("complete"))
        self.meta: dict[str, Any] = doc.get("meta") or {}
        self.intrinsics = (
            None if doc.get("intrinsics") is None else Intrinsics.from_dict(doc["intrinsics"])
        )
        self._frames: dict[int, dict[str, Any]] = {}
        self._flows: dict[int, dict[str, Any]] = {}
        self._read_index()
        n = len(self._frames)
        if sorted(self._frames) != list(range(n)):
            raise RecordingError(f"{self.path / 'index.jsonl'}: frame numbers are not 0..{n - 1}")
        if self.complete and doc.get("frames") != n:
            raise RecordingError(
                f"{self.path / 'index.jsonl'}: lists {n} frames, meta.json says {doc.get('frames')}"
            )

    def _read_index(self) -> None:
        index = self.path / "index.jsonl"
        if not index.is_file():
            raise RecordingError(f"{index}: missing")
        lines = index.read_bytes().split(b"\n")
        for ln, raw in enumerate(lines, 1):
            if not raw.strip():
                continue
            try:
                e = json.loads(raw)
                kind, i = e["kind"], int(e["i"])
                e["file"], e["bytes"], e["sha256"]
            except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
                last = all(not x.strip() for x in lines[ln:])
                if last and not self.complete:  # a write interrupted mid-line
                    break
                raise RecordingError(f"{index}: line {ln} is corrupt ({err})") from err
            (self._frames if kind == "frame" else self._flows)[i] = e

    def __len__(self) -> int:
        return len(self._frames)

    def has_flow(self, i: int) -> bool:
        return i in self._flows

    def _load(self, entry: dict[str, Any], what: str) -> dict[str, np.ndarray]:
        path = self.path / entry["file"]
        try:
            data = path.read_bytes()
        except OSError as e:
            raise RecordingError(f"{path}: {what} is missing or unreadable ({e})") from e
        if len(data) != entry["bytes"]:
            raise RecordingError(
                f"{path}: {what} is truncated ({len(data)} of {entry['bytes']} bytes)"
            )
        if self.verify and hashlib.sha256(data).hexdigest() != entry["sha256"]:
            raise RecordingError(f"{path}: {what} is corrupt (checksum mismatch)")
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
            raise RecordingError(f"{path}: {what} is corrupt ({e})") from e

    def frame(self, i: int) -> Frame:
        if not 0 <= i < len(self):
            raise IndexError(f"frame {i} of a recording with {len(self)} frames")
        entry = self._frames[i]
        a = self._load(entry, f"frame {i}")
        where = self.path / entry["file"]
        try:
            truth = None
            if "labels" in a:
                gh = int(a["grasped_hose"]) if "grasped_hose" in a else -1
                truth = FrameTruth(labels=a["labels"], grasped_hose=None if gh < 0 else gh)
                if i in self._flows:
                    fl = self._load(self._flows[i], f"flow of frame {i}")
                    truth.flow_to_target = fl["flow_to_target"]
                    truth.flow_valid = fl["flow_valid"]
            intr = self.intrinsics
            if intr is None:
                raise RecordingError(f"{self.path / 'meta.json'}: no intrinsics")
            return Frame(
                rgb=a["rgb"],
                depth=a["depth"],
                intrinsics=intr,
                gripper=a["gripper"],
                action=int(a["action"]),
                sample=int(a["sample"]),
                timestamp=float(a["timestamp"]),
                gripper_quat=a.get("gripper_quat"),
                gripper_opening=float(a["gripper_opening"]) if "gripper_opening" in a else None,
                truth=truth,
                arm_mask=a.get("arm_mask"),
            )
        except KeyError as e:
            raise RecordingError(f"{where}: frame {i} lacks {e}") from e
        except InputError as e:
            raise RecordingError(f"{where}: frame {i} is invalid ({e})") from e

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self.frame(i)

    def to_stream(self) -> Stream:
        if len(self) == 0:
            raise RecordingError(f"{self.path}: the recording has no frames")
        return Stream([self.frame(i) for i in range(len(self))], dict(self.meta))


def read_stream(path: str | os.PathLike[str]) -> Stream:
    """The whole recording at ``path`` as a :class:`Stream` (ground truth included)."""
    return Recording(path).to_stream()
