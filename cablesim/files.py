"""Files that survive an interrupted run, and output folders that refuse a second writer.

- :func:`write_bytes`, :func:`write_text`, :func:`write_image`: a file is written whole under
  a hidden temporary name beside it and renamed into place, so a killed process leaves the old
  file or none, never half of one (no ``fsync``: this guards against a killed process, not a
  power cut).  A full disk or quota (``ENOSPC``, ``EDQUOT``) raises
  :class:`~cablesim.errors.DiskFullError` naming the file; the temporary file is removed.
- :func:`staged` / :func:`commit`: the files of one unit of work (a dataset sequence, a clip)
  are written into a hidden folder ``PARENT/.partial/<name>.<pid>.<token>`` and moved to their
  places (``os.replace``, after removing what an unfinished earlier run left there) only when
  all are written.  Leftovers of a killed writer are removed when the same name is written
  again.  The unit is finished only when its job's result file exists (:mod:`cablesim.jobs`):
  a rerun redoes every unit without one, so a kill between two moves costs nothing.
- :class:`OutputLock`: ``fcntl.flock`` on ``<folder>/.lock``, held while a command writes
  there; a second process is refused at once with :class:`~cablesim.errors.OutputBusyError`
  naming the lock file and the holder (process id and command, written into the lock file).
  The kernel drops the lock when the holder exits or is killed, so a stale ``.lock`` never
  blocks a rerun; the file itself stays (emptied on a clean exit).  Locks are re-entrant within
  a process.
"""

from __future__ import annotations

import errno
import fcntl
import glob
import os
import secrets
import shlex
import shutil
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np

from cablesim.errors import DiskFullError, OutputBusyError, RecordingError

LOCK_NAME = ".lock"
PARTIAL = ".partial"
DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})


def is_disk_full(e: BaseException) -> bool:
    """Whether ``e`` says that a file system or quota is full."""
    return isinstance(e, OSError) and e.errno in DISK_FULL


def disk_full_error(e: OSError, path: str | os.PathLike[str]) -> OSError:
    """``e`` as the error to raise: a :class:`DiskFullError` naming ``path`` (or the file the
    error names) when the disk is full, else ``e`` itself."""
    if isinstance(e, DiskFullError) or not is_disk_full(e):
        return e
    return DiskFullError(e.filename or path, e.strerror or "")


@contextmanager
def disk_full_as_error(path: str | os.PathLike[str]) -> Iterator[None]:
    """Turn a full disk inside the block into :class:`DiskFullError` naming ``path``."""
    try:
        yield
    except OSError as e:
        err = disk_full_error(e, path)
        if err is e:
            raise
        raise err from e


def _tmp_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (module docstring)."""
    path = Path(path)
    tmp = _tmp_name(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        err = disk_full_error(e, path)
        if err is not e:
            raise err from e
        if e.filename is None:  # a failed write names no file: name it
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_bytes(path, text.encode("utf-8"))


def write_image(path: str | os.PathLike[str], img: np.ndarray) -> Path:
    """Encode ``img`` (OpenCV's channel order) by the file's suffix and write it atomically:
    the same bytes ``cv2.imwrite`` writes, with a named error when the disk is full."""

    path = Path(path)
    ok, buf = cv2.imencode(path.suffix or ".png", img)
    if not ok:
        raise RecordingError(f"could not encode {path} ({img.dtype} {img.shape})")
    return write_bytes(path, buf.tobytes())


def append_line(path: str | os.PathLike[str], line: str) -> None:
    """Append one line with a single ``write`` (``O_APPEND``); a full disk is a
    :class:`DiskFullError`, and a line cut short by it is taken back."""
    path = Path(path)
    data = (line.rstrip("\n") + "\n").encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        start = os.fstat(fd).st_size
        try:
            n = os.write(fd, data)
            if n != len(data):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        except OSError as e:
            try:
                os.ftruncate(fd, start)
            except OSError:
                pass
            raise disk_full_error(e, path) from e
    finally:
        os.close(fd)


def drop_partial_last_line(path: str | os.PathLike[str]) -> bool:
    """Cut a last line without its newline (a write interrupted by a kill) off a JSON-lines
    file; True if something was cut."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return False
    if not data or data.endswith(b"\n"):
        return False
    keep = data.rfind(b"\n") + 1
    with open(path, "r+b") as f:
        f.truncate(keep)
    return True


def remove_tmp_files(folder: str | os.PathLike[str]) -> int:
    """Remove the temporary files of :func:`write_bytes` that killed writers left in
    ``folder`` (call it while holding the folder's lock); the number removed."""
    n = 0
    for p in Path(folder).glob(".*.tmp"):
        try:
            p.unlink()
            n += 1
        except OSError:
            pass
    return n


# --------------------------------------------------------------------------- staged folders
def _remove(path: Path) -> None:
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)


def discard_partial(parent: str | os.PathLike[str], name: str) -> None:
    """Remove what unfinished writers of ``name`` left in ``parent/.partial``."""
    base = Path(parent) / PARTIAL
    for p in base.glob(f"{glob.escape(name)}.*"):
        shutil.rmtree(p, ignore_errors=True)
    try:
        base.rmdir()
    except OSError:
        pass


@contextmanager
def staged(parent: str | os.PathLike[str], name: str) -> Iterator[Path]:
    """A fresh hidden folder in ``parent/.partial`` for the files of ``name`` (module
    docstring); removed with whatever is left in it when the block ends."""
    discard_partial(parent, name)
    d = Path(parent) / PARTIAL / f"{name}.{os.getpid()}.{secrets.token_hex(4)}"
    with disk_full_as_error(d):
        d.mkdir(parents=True)
    try:
        with disk_full_as_error(d):
            yield d
    finally:
        shutil.rmtree(d, ignore_errors=True)
        try:
            d.parent.rmdir()
        except OSError:
            pass


def commit(staged_path: str | os.PathLike[str], final: str | os.PathLike[str]) -> Path:
    """Move a finished folder (or file) from its staging place to ``final``, replacing what was
    there."""
    final = Path(final)
    with disk_full_as_error(final):
        _remove(final)
        final.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staged_path, final)
    return final


# --------------------------------------------------------------------------- locks
_HELD: dict[str, list[int]] = {}  # real path of a lock file -> [fd, depth]


def _command_line() -> str:
    """This process's command line, as a person would type it (``cablesim dataset ...``)."""
    argv0 = sys.argv[0] if sys.argv else ""
    first = Path(argv0).name or "python"
    if Path(argv0).parts[-2:] == ("cablesim", "cli.py"):  # python -m cablesim.cli
        first = "cablesim"
    return shlex.join([first, *sys.argv[1:]])


class OutputLock:
    """The lock of an output folder (module docstring); a context manager.

    ``OutputLock(out, "cablesim dataset ...")`` refuses with ``OutputBusyError`` when another
    process holds ``out/.lock``; ``name`` picks another lock file in the folder (e.g. one per
    results file)."""

    def __init__(
        self, folder: str | os.PathLike[str], command: str | None = None, name: str = LOCK_NAME
    ):
        self.folder = Path(folder)
        self.path = self.folder / name
        self.command = command or _command_line()
        self._key: str | None = None

    @property
    def held(self) -> bool:
        return self._key is not None

    def acquire(self) -> OutputLock:
        if self._key is not None:
            return self
        self.folder.mkdir(parents=True, exist_ok=True)
        key = os.path.realpath(self.path)
        if key in _HELD:  # this process holds it already
            _HELD[key][1] += 1
            self._key = key
            return self
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            raise OutputBusyError(self.path, holder) from None
        except OSError as e:  # a file system without locks: go on unguarded, say so
            os.close(fd)
            warnings.warn(
                f"{self.path}: cannot lock ({e.strerror or e}); another process could write "
                "into this folder at the same time",
                stacklevel=2,
            )
            return self
        try:  # who holds it, for the message of the one refused (best effort: disk may be full)
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()}: {self.command}\n".encode(), 0)
        except OSError:
            pass
        _HELD[key] = [fd, 1]
        self._key = key
        return self

    def release(self) -> None:
        key, self._key = self._key, None
        if key is None or key not in _HELD:
            return
        entry = _HELD[key]
        entry[1] -= 1
        if entry[1] > 0:
            return
        del _HELD[key]
        fd = entry[0]
        try:
            os.ftruncate(fd, 0)
        except OSError:
            pass
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


def _read_holder(fd: int) -> str:
    try:
        return os.pread(fd, 4096, 0).decode("utf-8", "replace").strip()
    except OSError:
        return ""


@contextmanager
def waiting_lock(path: str | os.PathLike[str]) -> Iterator[None]:
    """An exclusive ``flock`` on the file ``path``, waiting for it (a shared cache entry that
    two processes may fill at once: the second waits, then finds it filled)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # no locks on this file system: unguarded, as before
            pass
        yield
    finally:
        os.close(fd)
