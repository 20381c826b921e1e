"""Transit sleep (``physics.transit_sleep``, issue 21): while the arm is in transit holding
nothing (``Robot.transit``: the approach to a grasp or push and the retreat) the hoses it does
not touch rest; the hand touching a resting hose wakes it and moves it as it moves an awake one;
every hose wakes at the first step after a transit motion, so the grasp, the hold check and the
actions run with everything awake; a closed hand never lets anything rest; a file written
before the field reruns with every hose awake."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cablesim.config import from_dict, to_dict
from cablesim.episode import primitives as prim
from cablesim.episode.config import GraspConfig
from cablesim.errors import ConfigError
from cablesim.robot.grasping import RETRACT_QPOS
from cablesim.sim.config import (
    CameraConfig,
    EpisodeConfig,
    HoseConfig,
    PhysicsConfig,
    SceneConfig,
)
from cablesim.sim.session import SimSession
from cablesim.sim.settle import cache_key
from cablesim.sim.world import World

SCENE = SceneConfig(seed=2, hoses=HoseConfig(count=3), camera=CameraConfig(width=160, height=120))
SLEEP = int(mujoco.mjtEnableBit.mjENBL_SLEEP)


def _physics(transit_sleep: float) -> SceneConfig:
    return SCENE.replace(physics=PhysicsConfig(transit_sleep=transit_sleep))


def test_on_by_default_and_a_file_without_it_reruns_awake() -> None:
    assert PhysicsConfig().transit_sleep == 1e-3
    old = to_dict(PhysicsConfig())
    del old["transit_sleep"]
    assert from_dict(PhysicsConfig, old).transit_sleep == 0.0


@pytest.mark.parametrize("bad", [-1e-3, 2.0, float("nan"), "fast", True])
def test_a_bad_transit_sleep_is_refused_naming_the_field(bad) -> None:
    with pytest.raises(ConfigError, match="physics.transit_sleep"):
        PhysicsConfig(transit_sleep=bad)


def test_the_settled_state_does_not_depend_on_it() -> None:
    on, off = World.build(SCENE, settle=False), World.build(_physics(0.0), settle=False)
    assert cache_key(on) == cache_key(off)


@pytest.fixture(scope="module")
def sessions():
    out = {t: SimSession.build(EpisodeConfig(scene=_physics(t))) for t in (1e-3, 0.0)}
    yield out
    for s in out.values():
        s.close()


class _Watch:
    """After every step: whether sleep was on, how many trees were awake, and whether each
    hose had a tree awake."""

    def __init__(self, world: World) -> None:
        self.flags: list[bool] = []
        self.awake: list[int] = []
        self.hose_awake: list[list[bool]] = []
        m = world.model
        self.trees = [
            np.unique(m.body_treeid[h.vertex_bodies[h.vertex_bodies > 0]]) for h in world.hoses
        ]

    def __call__(self, world: World) -> None:
        d = world.data
        self.flags.append(bool(world.model.opt.enableflags & SLEEP))
        self.awake.append(int(d.ntree_awake))
        self.hose_awake.append([bool(d.tree_awake[t].any()) for t in self.trees])


def test_a_transit_rests_the_untouched_hoses_and_every_tree_wakes_after(sessions) -> None:
    s = sessions[1e-3]
    w, robot, m = s.world, s.robot, s.world.model
    w.reset()
    before = w.all_hose_vertices().copy()
    tolerance = m.opt.sleep_tolerance = 5e-4  # not transit_sleep's: it must come back
    watch = _Watch(w)
    with robot.transit(), w.hooks(after=[watch]):
        assert robot.move_joints(RETRACT_QPOS, 0.5)  # through free space: no hose touched
    assert all(watch.flags)
    assert not any(watch.hose_awake[-1]), "resting hoses the hand never touched should sleep"
    assert watch.awake[-1] < m.ntree
    assert not m.opt.enableflags & SLEEP  # off again after the transit
    assert m.opt.sleep_tolerance == tolerance  # and the model's tolerance as it was
    w.step(1)
    assert w.data.ntree_awake == m.ntree  # and every tree awake at the next step
    moved = np.linalg.norm(w.all_hose_vertices() - before, axis=1).max()
    assert moved < 1e-3, f"a hose moved {moved * 1000:.2f} mm while the arm moved in free space"


def test_outside_a_transit_or_with_a_closed_hand_everything_stays_awake(sessions) -> None:
    s = sessions[1e-3]
    w, robot, m = s.world, s.robot, s.world.model
    w.reset()
    watch = _Watch(w)
    with w.hooks(after=[watch]):
        assert robot.move_joints(RETRACT_QPOS, 0.5)  # no transit: an action's motion
        robot.grasp(width=0.015)  # closes on nothing: the hand counts as closed until open()
        with robot.transit():
            assert robot.move_joints(np.asarray(SCENE.robot.park_qpos), 0.5)
    assert not any(watch.flags)
    assert min(watch.awake) == m.ntree
    robot.open()


def test_the_hand_touching_a_resting_hose_wakes_it_and_moves_it_as_an_awake_one(sessions) -> None:
    """The closed, empty hand comes down beside hose 1 in a transit and then sweeps through
    where the hose hangs, still in the transit: the hose wakes at the touch and is pushed as
    far as with every hose awake throughout."""
    pushed = {}
    for tol, s in sessions.items():
        w, robot = s.world, s.robot
        w.reset()
        v = w.hose_vertices(1)
        i = len(v) // 2
        centre, axis = v[i], v[i + 1] - v[i - 1]
        approach = np.asarray(prim.DEFAULT_APPROACH, float)
        side = np.cross(axis, approach)
        side /= np.linalg.norm(side)
        before = v.copy()
        g = prim.approach_for_push(
            robot, centre + 0.03 * side, axis, GraspConfig(), approach, standoff=0.0
        )
        assert g, g.reason
        watch = _Watch(w)
        with robot.transit(), w.hooks(after=[watch]):
            robot.move_to(g.pose.translated(-0.05 * side), speed=0.05)
        moved = np.linalg.norm(w.hose_vertices(1) - before, axis=1)
        pushed[tol] = float(moved.max())
        if tol > 0:
            assert all(watch.flags)
            assert not watch.hose_awake[0][1], "hose 1 should rest until the hand reaches it"
            assert any(a[1] for a in watch.hose_awake), "the hand's touch should wake hose 1"
    assert pushed[0.0] > 0.005, f"the sweep moved hose 1 only {pushed[0.0] * 1000:.1f} mm"
    assert abs(pushed[1e-3] - pushed[0.0]) < 0.002, pushed  # measured: 51.0 mm both, 7 um apart
