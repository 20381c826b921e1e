"""Sleeping islands (``physics.sleep_tolerance`` > 0, issue 21): hoses at rest go to sleep, a
force on a sleeping hose wakes it, the hose the hand grasps wakes and follows the hand, and sleep
never makes a run depend on its past: a reset, a cached settle and a fresh settle step alike."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cablesim.errors import ConfigError
from cablesim.sim.config import (
    CameraConfig,
    EpisodeConfig,
    HoseConfig,
    PhysicsConfig,
    RobotConfig,
    SceneConfig,
)
from cablesim.sim.session import simulate_episode
from cablesim.sim.world import World

TOL = 1e-3
BARE = SceneConfig(
    seed=1,
    hoses=HoseConfig(count=3),
    camera=CameraConfig(width=160, height=120),
    robot=RobotConfig(enabled=False),
    physics=PhysicsConfig(sleep_tolerance=TOL, cache=False),
)


def _hose_trees(world: World, hose: int) -> np.ndarray:
    bodies = world.hoses[hose].vertex_bodies
    return np.unique(world.model.body_treeid[bodies[bodies > 0]])


@pytest.mark.parametrize("bad", [-1e-3, 2.0, float("nan"), "fast", True])
def test_a_bad_sleep_tolerance_is_refused_naming_the_field(bad) -> None:
    with pytest.raises(ConfigError, match="physics.sleep_tolerance"):
        PhysicsConfig(sleep_tolerance=bad)


def test_off_by_default_and_on_in_the_model() -> None:
    assert PhysicsConfig().sleep_tolerance == 0.0
    off = World.build(BARE.replace(physics=PhysicsConfig(cache=False)), settle=False)
    assert not off.model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP
    on = World.build(BARE, settle=False)
    assert on.model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP
    assert on.model.opt.sleep_tolerance == TOL


@pytest.fixture(scope="module")
def settled() -> World:
    return World.build(BARE)


def test_resting_hoses_sleep_and_a_force_wakes_one(settled: World) -> None:
    w = settled
    w.reset()
    d = w.data
    assert d.ntree_awake == w.model.ntree  # a reset starts with everything awake
    w.step(50)
    assert d.ntree_awake == 0, "settled hoses without a robot should all sleep"
    before = [w.hose_vertices(h).copy() for h in range(3)]
    # a push on hose 0's middle vertex (the neighbour perturbation applies forces like this)
    body = int(w.hoses[0].vertex_bodies[len(w.hoses[0].vertex_bodies) // 2])
    d.xfrc_applied[body, :3] = (0.3, 0.0, 0.0)
    w.step(25)
    d.xfrc_applied[body] = 0.0
    awake = [bool(d.tree_awake[_hose_trees(w, h)].any()) for h in range(3)]
    moved = [float(np.abs(w.hose_vertices(h) - before[h]).max()) for h in range(3)]
    assert awake[0] and moved[0] > 1e-3, f"the pushed hose moved {moved[0] * 1000:.3f} mm"
    # hoses it touches wake with it (one island); the others sleep on and do not move a bit
    # (seed 1: hoses 1 and 2 do not touch hose 0)
    assert not any(awake[1:]), awake
    assert moved[1:] == [0.0, 0.0], moved


def test_a_reset_gives_the_same_steps_whatever_slept_before(settled: World) -> None:
    w = settled
    runs = []
    for _ in range(2):
        w.reset()
        w.step(40)  # everything asleep by now: the next reset must wake it all
        runs.append(w.get_state())
    assert np.array_equal(runs[0], runs[1])


def test_a_cached_settle_steps_like_a_fresh_one(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("CABLESIM_CACHE", str(tmp_path))
    cfg = BARE.replace(physics=PhysicsConfig(sleep_tolerance=TOL, cache=True))
    states = []
    for expect_cached in (False, True):
        w = World.build(cfg)
        assert w.settle_report.cached == expect_cached
        w.step(30)
        states.append(w.get_state())
    assert np.array_equal(states[0], states[1])


def test_the_grasped_hose_wakes_and_follows_the_hand() -> None:
    scene = SceneConfig(
        seed=2,
        hoses=HoseConfig(count=3),
        camera=CameraConfig(width=160, height=120),
        physics=PhysicsConfig(sleep_tolerance=TOL),
    )
    ep = simulate_episode(EpisodeConfig(hose=1, scene=scene))
    try:
        res = ep.result
        assert res.success, res.reason
        for a in res.actions:
            assert a.gain >= 0.9, f"{a.label}: gain {a.gain:.3f}"
    finally:
        ep.close()
