"""Draws turned down for want of a graspable segment, remembered beside the settle cache.

A simulated session re-draws its scene when no hose of the draw shows a graspable start
segment (:class:`~cablesim.sim.session.SimSession`, rule 2).  Deciding that is the slowest part
of building such a scene: every hose's candidates are screened and up to 40 of each are planned
(about 5 s of CPU per draw of the default scene, on top of loading its settled state), and a
seed whose first draws are turned down pays it again on every run.  The verdict depends only on
the settled scene, the episode config and the code, so it is remembered: one small JSON entry
per turned-down draw in ``$CABLESIM_CACHE/draws`` (beside ``settled``), read back instead of
planning again.  Only the verdict "no graspable segment" is kept (a draw that serves is built
as before), with the very message and reason counts the planning gave, so a run served from
the cache records the same outcomes, bit for bit, as one that planned.

The key hashes the settle cache's key description of the draw's world (its physics config,
versions, model sizes and code), the whole episode config, and the code of every module of the
``cablesim`` package; an entry whose stored key differs, or that cannot be read, is ignored
and rewritten.  Entries are written to a temporary file and renamed, as the settle cache's.
``physics.cache = False`` turns both caches off.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cablesim.config import to_dict
from cablesim.sim.settle import cache_dir as settle_cache_dir
from cablesim.sim.settle import cache_key_description

if TYPE_CHECKING:
    from cablesim.sim.config import EpisodeConfig
    from cablesim.sim.world import World

#: Version of the entry layout; entries of another version are planned again.
FORMAT = 1


def cache_dir() -> Path:
    return settle_cache_dir().parent / "draws"


@lru_cache(maxsize=1)
def package_digest() -> str:
    """SHA-256 of every module of the ``cablesim`` package (path and bytes, in path order)."""
    package = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for p in sorted(package.rglob("*.py")):
        h.update(p.relative_to(package).as_posix().encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def key_description(world: World, cfg: EpisodeConfig) -> dict[str, Any]:
    """Everything a draw's verdict depends on (what :func:`entry_path` hashes)."""
    return {
        "format": FORMAT,
        "scene": cache_key_description(world),
        "episode": to_dict(cfg),
        "code": package_digest(),
    }


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def entry_path(key: dict[str, Any]) -> Path:
    return cache_dir() / f"{hashlib.sha256(_canonical(key).encode()).hexdigest()[:24]}.json"


def read_turned_down(key: dict[str, Any]) -> tuple[str, dict[str, int]] | None:
    """(message, reason counts) of a draw remembered as turned down; None when it is not (or
    its entry is unreadable or of another key: it is planned again and rewritten)."""
    path = entry_path(key)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or _canonical(doc.get("key")) != _canonical(key):
        return None
    message, reasons = doc.get("message"), doc.get("reasons")
    if not isinstance(message, str) or not isinstance(reasons, dict):
        return None
    if not all(isinstance(k, str) and isinstance(v, int) for k, v in reasons.items()):
        return None
    return message, dict(reasons)


def write_turned_down(key: dict[str, Any], message: str, reasons: dict[str, int]) -> None:
    """Remember a turned-down draw; a cache that cannot be written costs only the next plan."""
    path = entry_path(key)
    doc = {"key": key, "message": message, "reasons": {k: int(v) for k, v in reasons.items()}}
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".draw-", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w") as f:
            f.write(_canonical(doc))
        os.replace(tmp, path)
    except OSError:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
