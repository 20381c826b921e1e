"""The settle cache trusts nothing it has not verified (issue 12, item 3): each reproduction ends
in a warning naming the file (and a correct, freshly settled state) or in the project's own
error.  A slow settle is named for what it is, not a divergence."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from cablesim.errors import PhysicsDivergedError, SceneUnsettledError
from cablesim.sim import settle
from cablesim.sim.config import CameraConfig, HoseConfig, PhysicsConfig, RobotConfig, SceneConfig
from cablesim.sim.settle import SettleCacheWarning, cache_path, read_entry, write_entry
from cablesim.sim.world import World

CFG = SceneConfig(
    seed=1,
    hoses=HoseConfig(count=2),
    camera=CameraConfig(width=160, height=120),
    robot=RobotConfig(enabled=False),
)


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CABLESIM_CACHE", str(tmp_path))
    return tmp_path / "settled"


@pytest.fixture(scope="module")
def fresh():
    """The scene settled without any cache: what every rebuilt entry must give."""
    return World.build(CFG.replace(physics=PhysicsConfig(cache=False)))


def _rewrite(path, state=None, meta_change=None, keep_checksum=True):
    """Rewrite an entry: a new state and/or meta; with ``keep_checksum`` the stored checksum is
    left as it was (a tampered file), else recomputed (a writer that wrote bad data)."""
    with np.load(path) as z:
        old_state = np.array(z["state"])
        meta = json.loads(bytes(z["meta"]).decode())
    state = old_state if state is None else state
    if meta_change:
        meta_change(meta)
    if not keep_checksum:
        meta["sha256"] = settle._checksum(state, meta)
    payload = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    with open(path, "wb") as f:
        np.savez(f, state=state, meta=payload)


def _build_quietly() -> World:
    with warnings.catch_warnings():
        warnings.simplefilter("error", SettleCacheWarning)
        return World.build(CFG)


def test_entry_carries_checksum_and_key_and_loads_bit_for_bit(cache, fresh) -> None:
    first = World.build(CFG)
    assert not first.settle_report.cached
    path = cache_path(first)
    with np.load(path) as z:
        meta = json.loads(bytes(z["meta"]).decode())
    assert meta["status"] == "settled" and len(meta["sha256"]) == 64
    assert meta["key"] == settle.cache_key_description(first)  # config, versions, code digest
    assert len(meta["key"]["code"]) == 64 and meta["key"]["cfg"]["seed"] == CFG.seed
    again = _build_quietly()
    assert again.settle_report.cached and again.settle_report.path == str(path)
    np.testing.assert_array_equal(again.get_state(), fresh.get_state())
    assert list(cache.glob("*.tmp")) == [], "a temporary file was left behind"


def test_nan_state_is_rebuilt_with_a_warning_naming_the_file(cache, fresh) -> None:
    world = World.build(CFG)
    path = cache_path(world)
    state = world.get_state()
    state[5] = np.nan  # as a faulty writer would have stored it, checksum and all
    _rewrite(path, state, keep_checksum=False)
    with pytest.warns(SettleCacheWarning, match="non-finite") as w:
        rebuilt = World.build(CFG)
    assert str(path) in str(w[0].message)
    np.testing.assert_array_equal(rebuilt.get_state(), fresh.get_state())
    _build_quietly()  # the entry was rewritten and verifies again


def test_finite_but_altered_state_is_caught_by_the_checksum(cache, fresh) -> None:
    world = World.build(CFG)
    path = cache_path(world)
    state = world.get_state()
    qpos = slice(1, 1 + world.model.nq)  # mjSTATE_INTEGRATION: time, then qpos
    state[qpos][world.model.nq // 2 :] += 0.26  # a plausible, finite, wrong hose shape
    _rewrite(path, state, keep_checksum=True)
    with pytest.warns(SettleCacheWarning, match="checksum") as w:
        rebuilt = World.build(CFG)
    assert str(path) in str(w[0].message)
    np.testing.assert_array_equal(rebuilt.get_state(), fresh.get_state())


def test_entry_from_other_code_is_rebuilt(cache, fresh) -> None:
    world = World.build(CFG)
    path = cache_path(world)

    def other_code(meta):
        meta["key"]["code"] = "0" * 64

    _rewrite(path, meta_change=other_code, keep_checksum=False)
    with pytest.warns(SettleCacheWarning, match="other code") as w:
        rebuilt = World.build(CFG)
    assert str(path) in str(w[0].message)
    np.testing.assert_array_equal(rebuilt.get_state(), fresh.get_state())


def test_truncated_entry_is_rebuilt(cache, fresh) -> None:
    world = World.build(CFG)
    path = cache_path(world)
    path.write_bytes(path.read_bytes()[:200])
    with pytest.warns(SettleCacheWarning, match="unreadable") as w:
        rebuilt = World.build(CFG)
    assert str(path) in str(w[0].message)
    np.testing.assert_array_equal(rebuilt.get_state(), fresh.get_state())


def test_directory_at_the_entry_path(cache, fresh) -> None:
    world = World.build(CFG.replace(physics=PhysicsConfig(cache=False)))
    path = cache_path(world)
    path.mkdir(parents=True)
    with pytest.warns(SettleCacheWarning) as w:
        rebuilt = World.build(CFG)
    messages = [str(x.message) for x in w if issubclass(x.category, SettleCacheWarning)]
    assert any("is a directory" in m and str(path) in m for m in messages), messages
    assert any("could not write" in m and str(path) in m for m in messages), messages
    np.testing.assert_array_equal(rebuilt.get_state(), fresh.get_state())
    assert path.is_dir(), "the directory someone put there is left alone"
    assert list(path.parent.glob("*.tmp")) == []


def test_concurrent_writers_use_unique_temporary_files(cache, fresh, monkeypatch) -> None:
    """Writer A is preempted between writing its temporary file and renaming it; writer B
    writes the whole entry meanwhile.  With one shared temporary name B renamed A's file away
    and A died with FileNotFoundError; with unique names both succeed."""
    world = World.build(CFG.replace(physics=PhysicsConfig(cache=False)))
    path = cache_path(world)
    state = world.get_state()
    real_replace = settle.os.replace
    sources = []

    def preempted_replace(src, dst):
        sources.append(str(src))
        if len(sources) == 1:  # A is preempted here: B runs to the end first
            write_entry(path, world, state, "settled", 0.0)
        real_replace(src, dst)

    monkeypatch.setattr(settle.os, "replace", preempted_replace)
    write_entry(path, world, state, "settled", 0.0)  # A
    assert len(sources) == 2 and sources[0] != sources[1]
    entry = read_entry(path, world)
    np.testing.assert_array_equal(entry.state, state)
    assert list(path.parent.glob("*.tmp")) == []


def test_a_killed_writers_leftover_does_not_matter(cache, fresh) -> None:
    world = World.build(CFG)
    path = cache_path(world)
    (path.parent / f".{path.stem}.abc123.tmp").write_bytes(b"half an entry")
    again = _build_quietly()
    assert again.settle_report.cached
    np.testing.assert_array_equal(again.get_state(), fresh.get_state())


def test_a_slow_settle_is_named_not_called_a_divergence(cache) -> None:
    cfg = CFG.replace(physics=PhysicsConfig(settle_max_time=0.2))
    with pytest.raises(SceneUnsettledError) as e:
        World.build(cfg)
    assert not isinstance(e.value, PhysicsDivergedError)
    assert e.value.outcome == "scene_unsettled"
    assert e.value.speed > e.value.limit == cfg.physics.settle_speed
    assert "did not settle" in str(e.value) and "nothing diverged" in str(e.value)
    # the outcome is cached: the next build says so at once, without simulating again
    with pytest.raises(SceneUnsettledError, match="cached outcome") as again:
        World.build(cfg)
    assert again.value.speed == e.value.speed
