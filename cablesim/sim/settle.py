"""Settling: step until every hose vertex is slower than ``physics.settle_speed``.

A scene that is still faster than that after ``physics.settle_max_time`` of simulated time has
not diverged (that is :class:`~cablesim.errors.PhysicsDivergedError`: NaN or a MuJoCo
instability); it raises :class:`~cablesim.errors.SceneUnsettledError` with the speed it
reached, and the simulated session (:mod:`cablesim.sim.session`) re-draws the scene.

The outcome of settling is cached per config in ``$CABLESIM_CACHE/settled`` (default
``~/.cache/cablesim/settled``), one ``<key>.npz`` per scene, so that later builds of the same
scene skip the settling; loading an entry gives the very state a fresh settle computes.  The key
hashes the physics-relevant config (all but the camera and the cache switch), the MuJoCo and
cablesim versions, the model's sizes and the code of the modules that build and settle the
scene.  An entry holds

- ``state``: the settled MuJoCo integration state (float64), or the last state of a scene that
  did not settle (then only its speed is used: loading it raises ``SceneUnsettledError`` again
  without re-simulating);
- ``meta``: JSON with the format version, the status (``settled``/``unsettled``), the final
  speed, the simulated settle time, the full key description (config, versions, code digest)
  and the SHA-256 of the state bytes and of the rest of the meta.

Loading verifies all of it (format, key, sizes, finiteness, checksum); an entry that fails any
check (truncated, altered, NaN, from other code, a directory in its place) is settled again
and rewritten, with a :class:`SettleCacheWarning` naming the file.  Entries are written to a
unique temporary file in the cache directory and renamed over the entry atomically, so
concurrent writers of one scene never see each other's partial files; a cache that cannot be
written only costs the next build its settle (a warning names the file).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

import cablesim
from cablesim.config import to_dict
from cablesim.errors import SceneUnsettledError

if TYPE_CHECKING:
    from cablesim.sim.world import World

#: Version of the cache entry layout; entries of another version are rebuilt.
CACHE_FORMAT = 2


class SettleCacheWarning(UserWarning):
    """A settle-cache entry could not be used or written; the message names the file."""


@dataclass(frozen=True)
class SettleReport:
    """How a world came to rest (``world.settle_report``)."""

    speed: float  # m/s, fastest hose vertex at the end
    time: float  # s of simulated time the settle took (also when loaded from the cache)
    cached: bool  # loaded from the cache
    path: str  # the cache entry ("" without a cache)


def cache_dir() -> Path:
    return Path(os.environ.get("CABLESIM_CACHE", Path.home() / ".cache" / "cablesim")) / "settled"


# the modules whose code decides the settled state: a change to any of them makes a new key
_PHYSICS_SOURCES = (
    "cables.py",  # the kinds' radius, stiffness, mass, friction, damping
    "sim/config.py",
    "sim/layout.py",
    "sim/table.py",  # the table's start shapes, sockets and mat
    "sim/hand_board.py",
    "sim/world.py",
    "sim/settle.py",
    "panda/model.py",
    "panda/description.py",
)


def _source_digest() -> str:
    package = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for name in _PHYSICS_SOURCES:
        h.update((package / name).read_bytes())
    return h.hexdigest()


def cache_key_description(world: World) -> dict[str, Any]:
    """Everything the settled state depends on (what :func:`cache_key` hashes)."""
    cfg = to_dict(world.cfg)
    cfg.pop("camera")  # the camera does not touch the physics
    cfg["robot"].pop("visual")  # nor does the arm's look (visual-only geoms, same physics)
    cfg["physics"].pop("cache")
    cfg["physics"].pop("transit_sleep")  # the settle does not move the arm
    cfg["physics"].pop("run_fallback_time")  # nor step outside the settle
    return {
        "cfg": cfg,
        "mujoco": mujoco.__version__,
        "cablesim": cablesim.__version__,
        "code": _source_digest(),
        "nq": world.model.nq,
        "nv": world.model.nv,
    }


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def cache_key(world: World) -> str:
    return hashlib.sha256(_canonical(cache_key_description(world)).encode()).hexdigest()[:24]


def cache_path(world: World) -> Path:
    """The cache entry of ``world``'s scene."""
    return cache_dir() / f"{cache_key(world)}.npz"


def max_vertex_speed(world: World) -> float:
    """Largest hose-vertex speed (m/s), by one physics step of finite difference."""
    before = world.all_hose_vertices()
    state = world.get_state()
    world.step(1)
    speed = (
        np.linalg.norm(world.all_hose_vertices() - before, axis=1).max() / world.model.opt.timestep
    )
    world.set_state(state)
    return float(speed)


# ---------------------------------------------------------------------- cache entries
def _checksum(state: np.ndarray, meta: dict[str, Any]) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(state, dtype="<f8").tobytes())
    h.update(_canonical({k: v for k, v in meta.items() if k != "sha256"}).encode())
    return h.hexdigest()


class _BadEntry(Exception):
    pass


@dataclass(frozen=True)
class _Entry:
    state: np.ndarray
    status: str  # settled | unsettled
    speed: float
    time: float


def read_entry(path: Path, world: World) -> _Entry:
    """The verified entry at ``path`` for ``world``; raises ``_BadEntry`` saying why not."""
    if path.is_dir():
        raise _BadEntry("it is a directory, not a file")
    try:
        with np.load(path, allow_pickle=False) as z:
            state = np.array(z["state"])
            meta_raw = bytes(np.asarray(z["meta"], dtype=np.uint8))
    except (OSError, ValueError, KeyError, EOFError) as e:
        raise _BadEntry(f"unreadable ({type(e).__name__}: {e})") from e
    except Exception as e:  # zipfile.BadZipFile and kin: any unreadable file
        raise _BadEntry(f"unreadable ({type(e).__name__}: {e})") from e
    try:
        meta = json.loads(meta_raw.decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise _BadEntry(f"its metadata is not JSON ({e})") from e
    if not isinstance(meta, dict) or meta.get("format") != CACHE_FORMAT:
        raise _BadEntry(f"unknown entry format (want {CACHE_FORMAT})")
    if meta.get("sha256") != _checksum(state, meta):
        raise _BadEntry("checksum mismatch: the state or its metadata was altered")
    if meta.get("key") != cache_key_description(world):
        raise _BadEntry("it was made by other code or another config")
    size = mujoco.mj_stateSize(world.model, mujoco.mjtState.mjSTATE_INTEGRATION)
    if state.dtype != np.float64 or state.shape != (size,):
        raise _BadEntry(f"state of shape {state.shape} {state.dtype}, the model needs ({size},)")
    status, speed, settle_time = meta.get("status"), meta.get("speed"), meta.get("time")
    if status not in ("settled", "unsettled"):
        raise _BadEntry(f"unknown status {status!r}")
    if not isinstance(speed, int | float) or not isinstance(settle_time, int | float):
        raise _BadEntry("speed or time missing")
    if status == "settled":
        if not np.isfinite(state).all():
            raise _BadEntry("non-finite values in the settled state")
        if not speed < world.cfg.physics.settle_speed:
            raise _BadEntry(f"its speed {speed} m/s is not below physics.settle_speed")
    return _Entry(state, status, float(speed), float(settle_time))


def write_entry(path: Path, world: World, state: np.ndarray, status: str, speed: float) -> None:
    """Write an entry atomically: a unique temporary file in the cache directory, renamed over
    ``path``.  Raises ``OSError`` when that is impossible (the caller warns)."""
    meta: dict[str, Any] = {
        "format": CACHE_FORMAT,
        "status": status,
        "speed": float(speed) if math.isfinite(speed) else 1e300,
        "time": world.time,
        "key": cache_key_description(world),
    }
    meta["sha256"] = _checksum(state, meta)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(
                f,
                state=np.ascontiguousarray(state, dtype="<f8"),
                meta=np.frombuffer(_canonical(meta).encode(), dtype=np.uint8),
            )
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _warn(message: str) -> None:
    warnings.warn(message, SettleCacheWarning, stacklevel=3)


# ---------------------------------------------------------------------- settling
def _unsettled(world: World, speed: float, cached: bool) -> SceneUnsettledError:
    p, cfg = world.cfg.physics, world.cfg
    return SceneUnsettledError(
        f"the scene (seed {cfg.seed}, draw {cfg.draw}) did not settle within "
        f"{p.settle_max_time} s of simulated time: its fastest hose vertex still moves at "
        f"{speed * 1000:.2f} mm/s (physics.settle_speed {p.settle_speed * 1000:.2f} mm/s)"
        f"{' (cached outcome)' if cached else ''}; nothing diverged: raise "
        f"physics.settle_max_time or draw another scene",
        speed=speed,
        limit=p.settle_speed,
    )


def settle_world(world: World, progress: bool = False) -> float:
    """Settle ``world`` in place (or load its cached settled state); returns the final speed
    and sets ``world.settle_report``.  Raises ``SceneUnsettledError`` when it does not settle."""
    p = world.cfg.physics
    path = cache_path(world) if p.cache else None
    if path is not None and (path.exists() or path.is_symlink()):
        try:
            entry = read_entry(path, world)
        except _BadEntry as e:
            _warn(f"settle cache entry {path} is unusable ({e}); settling again and rewriting it")
        else:
            if entry.status == "unsettled":
                world.settle_report = SettleReport(entry.speed, entry.time, True, str(path))
                raise _unsettled(world, entry.speed, cached=True)
            world.set_state(entry.state)
            world._settled_state = world.get_state()
            world.reset()
            world.settle_report = SettleReport(entry.speed, entry.time, True, str(path))
            return entry.speed
    chunk = max(1, int(round(p.settle_check_every / world.model.opt.timestep)))
    speed = float("inf")
    calm = 0  # consecutive checks below the threshold (one could be a passing minimum)
    with world.settling():
        while world.time < p.settle_max_time:
            world.step(chunk)
            speed = max_vertex_speed(world)
            if progress:
                print(
                    f"\r[settle] t={world.time:5.2f}s  max hose speed {speed * 1000:8.3f} mm/s",
                    end="",
                    flush=True,
                )
            calm = calm + 1 if speed < p.settle_speed else 0
            if calm >= 3:
                break
    if progress:
        print()
    settled = speed < p.settle_speed
    settle_time = world.time
    if path is not None:
        try:
            write_entry(
                path, world, world.get_state(), "settled" if settled else "unsettled", speed
            )
        except OSError as e:
            _warn(f"could not write settle cache entry {path} ({type(e).__name__}: {e})")
    world.settle_report = SettleReport(speed, settle_time, False, str(path or ""))
    if not settled:
        raise _unsettled(world, speed, cached=False)
    world._settled_state = world.get_state()
    world.reset()
    return speed
