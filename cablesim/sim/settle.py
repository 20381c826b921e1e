"""Settling: step until every hose vertex is slower than ``physics.settle_speed``.

The settled state is cached per config (the physics-relevant parts, the library versions and
the code of the modules that build and settle the scene)
in ``$CABLESIM_CACHE`` (default ``~/.cache/cablesim``) so that later builds of the same scene
skip the settling; loading the cache gives the very state a fresh settle computes.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

import cablesim
from cablesim.config import to_dict
from cablesim.errors import PhysicsDivergedError

if TYPE_CHECKING:
    from cablesim.sim.world import World


def cache_dir() -> Path:
    return Path(os.environ.get("CABLESIM_CACHE", Path.home() / ".cache" / "cablesim")) / "settled"


# the modules whose code decides the settled state: a change to any of them makes a new key
_PHYSICS_SOURCES = (
    "sim/config.py",
    "sim/layout.py",
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


def cache_key(world: World) -> str:
    cfg = to_dict(world.cfg)
    cfg.pop("camera")  # the camera does not touch the physics
    cfg["robot"].pop("visual")  # nor does the arm's look (visual-only geoms, same physics)
    cfg["physics"].pop("cache")
    blob = json.dumps(
        {
            "cfg": cfg,
            "mujoco": mujoco.__version__,
            "cablesim": cablesim.__version__,
            "code": _source_digest(),
            "nq": world.model.nq,
            "nv": world.model.nv,
        },
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


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


def settle_world(world: World, progress: bool = False) -> float:
    """Settle ``world`` in place (or load its cached settled state); returns the final speed."""
    p = world.cfg.physics
    path = cache_dir() / f"{cache_key(world)}.npz"
    if p.cache and path.exists():
        try:
            with np.load(path) as z:
                state, speed = z["state"], float(z["speed"])
            world.set_state(state)
            world._settled_state = world.get_state()
            world.reset()
            return speed
        except Exception as e:  # corrupt cache entry: settle again and overwrite it
            warnings.warn(f"ignoring unreadable settle cache {path}: {e}", stacklevel=2)
    chunk = max(1, int(round(p.settle_check_every / world.model.opt.timestep)))
    speed = float("inf")
    calm = 0  # consecutive checks below the threshold (one could be a passing minimum)
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
    if speed >= p.settle_speed:
        raise PhysicsDivergedError(
            f"the scene did not settle within {p.settle_max_time}s of simulated time "
            f"(fastest hose vertex {speed * 1000:.2f} mm/s > {p.settle_speed * 1000:.2f} mm/s)"
        )
    world._settled_state = world.get_state()
    if p.cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, state=world._settled_state, speed=speed)
        os.replace(tmp, path)
    world.reset()
    return speed
