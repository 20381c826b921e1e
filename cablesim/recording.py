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

Every file is written to a unique temporary name, flushed, fsynced and renamed, then its
index line is appended and fsynced; ``meta.json`` is rewritten (atomically) with
``complete: true`` by :meth:`RecordingWriter.close`.  An interrupted recording therefore keeps
every frame whose index line was written (a partial last index line is ignored); the reader
then reports ``complete = False``.  A missing, truncated, corrupt or inconsistent file (an
index entry that names another file than its frame's, values that differ from the index,
labels or flow of the wrong size) raises :class:`RecordingError` naming the file and the
frame.  Ground truth (labels, flow) is stored only when the frames carry it; a real or
replayed recording has none.  ``arm_mask`` (the kinematic arm mask, not ground truth) is
stored when the frame has one; recordings written before it existed read back with
``arm_mask = None``.

Overwriting (``overwrite=True`` over an existing recording) writes the new recording into a
hidden sibling directory (``.NAME.new-*``) and swaps it with the old one when the writer is
closed (one atomic ``renameat2(RENAME_EXCHANGE)`` where the platform has it), then deletes the
old one; an interruption before the swap leaves the old recording whole (an exception removes
the partial new one; a killed process leaves it in its hidden directory).  A directory that is
not a cablesim recording is never overwritten.

A full disk (``ENOSPC``, ``EDQUOT``) while writing raises
:class:`~cablesim.errors.DiskFullError` naming the file; an index line cut short by it is
taken back, so the recording stays readable with every frame written before (``meta.json``
keeps ``complete: false`` when it cannot be rewritten).
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import io
import json
import os
import secrets
import shutil
import zipfile
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from cablesim.errors import DiskFullError, InputError, RecordingError
from cablesim.files import disk_full_error
from cablesim.frames import Frame, FrameTruth, Intrinsics, Stream
from cablesim.jsonutil import json_default

FORMAT = "cablesim-recording"
VERSION = 1
#: zlib level of the ``.npz`` members.  Level 1 writes a 640x480 frame with its labels and
#: its flow file in about a third of the CPU time of NumPy's ``savez_compressed`` (level 6:
#: 54 against 23 ms per frame, 11 s of a 38 s ``cablesim episode`` on seed 12345) for files
#: about 16 % larger; any zip reader (``np.load``) reads both.
COMPRESS_LEVEL = 1


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


def _unique_name(path: Path, tag: str) -> Path:
    """A hidden sibling of ``path`` no other process or writer will pick."""
    return path.with_name(f".{path.name}.{tag}-{os.getpid()}-{secrets.token_hex(4)}")


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = _unique_name(path, "tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two directories in one atomic step (Linux ``renameat2``); False if unsupported."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False
    at_fdcwd, rename_exchange = -100, 2
    return renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def _swap_in(new: Path, final: Path) -> None:
    """Put the recording in ``new`` at ``final`` and delete the one that was there."""
    if _exchange(new, final):
        old = new
    else:  # two renames: a crash between them leaves both whole, the old one hidden
        old = _unique_name(final, "old")
        os.rename(final, old)
        os.rename(new, final)
    _fsync_dir(final.parent)
    shutil.rmtree(old, ignore_errors=True)


def is_recording(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a directory holding a cablesim recording's ``meta.json``."""
    meta = Path(path) / "meta.json"
    try:
        doc = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False
    return isinstance(doc, dict) and doc.get("format") == FORMAT


def _file_name(kind: str, i: int) -> str:
    return f"{'frames' if kind == 'frame' else 'flow'}/{int(i):06d}.npz"


def _npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """The ``.npz`` archive of ``arrays`` (what ``np.savez_compressed`` writes, at
    :data:`COMPRESS_LEVEL`)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=COMPRESS_LEVEL) as z:
        for name, value in arrays.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(value), allow_pickle=False)
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
        self.path = Path(path)  # where the recording is (after close, when overwriting)
        self.dir = self.path  # where its files are written now
        # writing beside an old recording, swapped in on close
        self.replaces = self.check_target(path, overwrite)
        try:
            if self.replaces:
                self.dir = _unique_name(self.path, "new")
            (self.dir / "frames").mkdir(parents=True, exist_ok=True)
            (self.dir / "flow").mkdir(exist_ok=True)
            self._index = open(self.dir / "index.jsonl", "a", encoding="utf-8")  # noqa: SIM115
        except OSError as e:
            _raise_disk_full(e, self.dir)
            raise RecordingError(f"{self.path}: cannot write a recording there ({e})") from e
        self.meta = dict(meta or {})
        self.intrinsics: Intrinsics | None = None
        self.frames = 0
        self.closed = False
        self.failed = False  # a write failed (a full disk): no meta.json that says more
        self._write_meta(complete=False)

    @staticmethod
    def check_target(
        path: str | os.PathLike[str], overwrite: bool = False, flag: str = "overwrite"
    ) -> bool:
        """``RecordingError`` unless a recording can be written at ``path`` (checked before
        any expensive step); True when it would replace an existing recording."""
        if str(path).strip() == "":
            raise RecordingError("the recording path is empty")
        p = Path(path)
        if p.exists() and not p.is_dir():
            raise RecordingError(f"{p} exists and is not a directory")
        try:
            occupied = p.is_dir() and any(p.iterdir())
        except OSError as e:
            raise RecordingError(f"{p}: cannot be read ({e.strerror or e})") from e
        if not occupied:
            return False
        if not overwrite:
            raise RecordingError(f"{p} exists and is not empty (use {flag})")
        if not is_recording(p):
            raise RecordingError(
                f"{p} is not a cablesim recording (no readable meta.json); refusing to overwrite it"
            )
        return True

    def _write_meta(self, complete: bool) -> None:
        doc = {
            "format": FORMAT,
            "version": VERSION,
            "intrinsics": None if self.intrinsics is None else self.intrinsics.to_dict(),
            "complete": complete,
            "frames": self.frames,
            "meta": self.meta,
        }
        data = json.dumps(doc, indent=2, default=json_default).encode()
        try:
            _write_atomic(self.dir / "meta.json", data)
        except OSError as e:
            self.failed = True
            _raise_disk_full(e, self.path / "meta.json")
            raise RecordingError(f"{self.path / 'meta.json'}: cannot be written ({e})") from e

    def _append_index(self, entry: dict[str, Any]) -> None:
        """One line with one ``write`` past the file's buffer; a line cut short (a full disk)
        is taken back, so the index never ends in a torn line that later lines follow."""
        data = (json.dumps(entry) + "\n").encode()
        fd = self._index.fileno()
        start = os.fstat(fd).st_size
        try:
            if os.write(fd, data) != len(data):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            os.fsync(fd)
        except OSError:
            try:
                os.ftruncate(fd, start)
            except OSError:
                pass
            raise

    def _write_file(
        self, kind: str, i: int, arrays: dict[str, np.ndarray], extra: dict[str, Any]
    ) -> None:
        if self.closed:
            raise RecordingError(f"{self.path}: the recording is closed")
        rel = _file_name(kind, i)
        data = _npz_bytes(arrays)
        try:
            _write_atomic(self.dir / rel, data)
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
        except OSError as e:
            self.failed = True
            _raise_disk_full(e, self.path / rel)
            raise RecordingError(f"{self.path / rel}: cannot be written ({e})") from e

    def add_frame(self, index: int, frame: Frame) -> None:
        if not isinstance(frame, Frame):
            raise InputError(f"frame {index} is a {type(frame).__name__}, not a Frame")
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
        """Finish the recording (``complete`` says whether the interaction finished); when
        overwriting, swap it in for the old one."""
        if self.closed:
            return
        if meta:
            self.meta.update(meta)
        self._index.close()
        failed = self.failed
        try:
            self._write_meta(complete=complete and not failed)
        except RecordingError:
            if not failed:
                raise
            # after a failed write (a full disk) the meta.json written before stays: it says
            # complete: false, and the index lists exactly the frames on disk
        self.closed = True
        if self.replaces:
            try:
                _swap_in(self.dir, self.path)
            except OSError as e:
                raise RecordingError(
                    f"{self.path}: cannot replace the old recording with the new one in "
                    f"{self.dir} ({e})"
                ) from e
            self.dir = self.path

    def abort(self) -> None:
        """Stop after an error: a new recording stays (incomplete but readable); one that was
        to replace an old recording is deleted and the old one stays as it was."""
        if self.closed:
            return
        if not self.replaces:
            self.close(complete=False)
            return
        self._index.close()
        self.closed = True
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # an exception leaves an incomplete (but readable) recording, or the old one
        if exc_type is None:
            self.close(complete=True)
        else:
            self.abort()


def _raise_disk_full(e: OSError, path: Path) -> None:
    err = disk_full_error(e, path)
    if isinstance(err, DiskFullError):
        raise err from e


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
        self.complete = doc.get("complete") is True
        meta = doc.get("meta")
        if meta is not None and not isinstance(meta, dict):
            raise RecordingError(f"{meta_path}: 'meta' must be a mapping, got {_short(meta)}")
        self.meta: dict[str, Any] = meta or {}
        try:
            self.intrinsics = (
                None if doc.get("intrinsics") is None else Intrinsics.from_dict(doc["intrinsics"])
            )
        except InputError as e:
            raise RecordingError(f"{meta_path}: bad intrinsics ({e})") from e
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
        try:
            lines = index.read_bytes().split(b"\n")
        except OSError as e:
            raise RecordingError(f"{index}: unreadable ({e})") from e
        for ln, raw in enumerate(lines, 1):
            if not raw.strip():
                continue
            try:
                e = _index_entry(raw)
            except (ValueError, UnicodeDecodeError) as err:
                last = all(not x.strip() for x in lines[ln:])
                if last and not self.complete:  # a write interrupted mid-line
                    break
                raise RecordingError(f"{index}: line {ln} is corrupt ({err})") from err
            table = self._frames if e["kind"] == "frame" else self._flows
            if e["i"] in table:
                raise RecordingError(f"{index}: line {ln} lists {e['kind']} {e['i']} again")
            table[e["i"]] = e

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
                gh = _scalar(a, "grasped_hose", int) if "grasped_hose" in a else -1
                truth = FrameTruth(labels=a["labels"], grasped_hose=None if gh < 0 else gh)
                if i in self._flows:
                    fl = self._load(self._flows[i], f"flow of frame {i}")
                    truth.flow_to_target = fl["flow_to_target"]
                    truth.flow_valid = fl["flow_valid"]
            intr = self.intrinsics
            if intr is None:
                raise RecordingError(f"{self.path / 'meta.json'}: no intrinsics")
            opening = a.get("gripper_opening")
            frame = Frame(
                rgb=a["rgb"],
                depth=a["depth"],
                intrinsics=intr,
                gripper=a["gripper"],
                action=_scalar(a, "action", int),
                sample=_scalar(a, "sample", int),
                timestamp=_scalar(a, "timestamp", float),
                gripper_quat=a.get("gripper_quat"),
                gripper_opening=None if opening is None else _scalar(a, "gripper_opening", float),
                truth=truth,
                arm_mask=a.get("arm_mask"),
            )
        except KeyError as e:
            raise RecordingError(f"{where}: frame {i} lacks {e}") from e
        except InputError as e:
            raise RecordingError(f"{where}: frame {i} is invalid ({e})") from e
        for key in ("action", "sample", "timestamp"):  # the index must tell the same
            if key in entry and entry[key] != getattr(frame, key):
                raise RecordingError(
                    f"{where}: frame {i} has {key} {getattr(frame, key)!r} but index.jsonl "
                    f"lists {entry[key]!r} (entries swapped or edited?)"
                )
        return frame

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self.frame(i)

    def to_stream(self) -> Stream:
        if len(self) == 0:
            raise RecordingError(f"{self.path}: the recording has no frames")
        return Stream([self.frame(i) for i in range(len(self))], dict(self.meta))


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _scalar(arrays: dict[str, np.ndarray], key: str, kind: type) -> Any:
    """A stored scalar as ``int`` or ``float``; ``InputError`` naming it otherwise."""
    v = arrays[key]
    ok = (
        np.issubdtype(v.dtype, np.integer)
        if kind is int
        else np.issubdtype(v.dtype, np.integer) or np.issubdtype(v.dtype, np.floating)
    )
    if v.shape != () or not ok:
        raise InputError(f"{key} must be a single {kind.__name__}, got {v.dtype} {v.shape}")
    return kind(v)


def _index_entry(raw: bytes) -> dict[str, Any]:
    """One parsed, checked index line; ``ValueError`` naming what is wrong."""
    e = json.loads(raw)
    if not isinstance(e, dict):
        raise ValueError(f"expected an object, got {_short(e)}")
    kind, i = e.get("kind"), e.get("i")
    if kind not in ("frame", "flow"):
        raise ValueError(f"unknown kind {_short(kind)}")
    if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < 10**6:
        raise ValueError(f"bad frame number {_short(i)}")
    if e.get("file") != _file_name(kind, i):
        raise ValueError(f"{kind} {i} names the file {_short(e.get('file'))}")
    size, digest = e.get("bytes"), e.get("sha256")
    if isinstance(size, bool) or not isinstance(size, int) or size < 0:
        raise ValueError(f"bad byte count {_short(size)}")
    if not isinstance(digest, str):
        raise ValueError(f"bad checksum {_short(digest)}")
    for key, types in (("action", int), ("sample", int), ("timestamp", int | float)):
        if key in e and (isinstance(e[key], bool) or not isinstance(e[key], types)):
            raise ValueError(f"bad {key} {_short(e[key])}")
    return e


def read_stream(path: str | os.PathLike[str]) -> Stream:
    """The whole recording at ``path`` as a :class:`Stream` (ground truth included)."""
    return Recording(path).to_stream()
