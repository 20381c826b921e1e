"""Scene building: config validation, seeded layout, settling, hoses hanging without stretch."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import ConfigError
from cablesim.sim.config import (
    BoardConfig,
    CameraConfig,
    HoseConfig,
    PhysicsConfig,
    RobotConfig,
    SceneConfig,
)
from cablesim.sim.layout import sample_hoses, start_shape


def _cfg(**kw) -> SceneConfig:
    kw.setdefault("robot", RobotConfig(enabled=False))
    return SceneConfig(**kw)


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: SceneConfig(hoses=HoseConfig(length=(-0.5, 1.0))), "hoses.length"),
        (lambda: SceneConfig(hoses=HoseConfig(length=(1.2, 0.8))), "hoses.length"),
        (lambda: SceneConfig(hoses=HoseConfig(count=9)), "hoses.count"),
        (lambda: SceneConfig(hoses=HoseConfig(count=0)), "hoses.count"),
        (lambda: SceneConfig(board=BoardConfig(background="marble")), "board.background"),
        (
            lambda: SceneConfig(
                hoses=HoseConfig(count=3), board=BoardConfig(connectors=((0, 0.8), (0.1, 0.8)))
            ),
            "hoses.count",
        ),
        (lambda: SceneConfig(board=BoardConfig(connectors=((2.0, 0.5),))), "board.connectors[0]"),
        (lambda: SceneConfig(camera=CameraConfig(width=1920, height=1080)), "camera.width/height"),
        (lambda: SceneConfig(physics=PhysicsConfig(timestep=0.05)), "physics.timestep"),
        (lambda: SceneConfig(physics=PhysicsConfig(solver="PGS")), "physics.solver"),
        (lambda: SceneConfig(camera=CameraConfig(sphere_stacks=1)), "camera.sphere_stacks"),
        (lambda: SceneConfig(physics=PhysicsConfig(fallback_time=-1.0)), "physics.fallback_time"),
        (
            lambda: SceneConfig(physics=PhysicsConfig(run_fallback_time=-1.0)),
            "physics.run_fallback_time",
        ),
        (lambda: SceneConfig(physics=PhysicsConfig(rescue_depth=-0.001)), "physics.rescue_depth"),
        (
            lambda: SceneConfig(physics=PhysicsConfig(rescue_residual=-1.0)),
            "physics.rescue_residual",
        ),
        (lambda: SceneConfig(seed=-1), "seed"),
        (lambda: SceneConfig(hoses=HoseConfig(grip_dmax=1.0)), "hoses.grip_dmax"),
    ],
)
def test_impossible_config_names_the_field(make, field: str) -> None:
    with pytest.raises(ConfigError) as e:  # when the config is made
        make()
    assert e.value.field == field
    assert field in str(e.value)


def test_the_fingers_contact_hardness_is_the_kinds_and_reaches_only_the_fingers() -> None:
    """A kind's ``grip_dmax`` (the rope's 0.999) sets the solimp dmax of the four finger geoms
    (pads and bodies) and nothing else; a scene that mixes kinds takes the largest, and
    ``hoses.grip_dmax`` overrides every kind; the hand's default is the model as built."""
    from cablesim.panda.model import finger_contact_geoms
    from cablesim.sim.world import World

    def model(hoses: HoseConfig):  # type: ignore[no-untyped-def]
        return World.build(SceneConfig(hoses=hoses), settle=False).model

    built = model(HoseConfig(count=1))
    rope = model(HoseConfig(count=1, kind="rope"))
    fingers = finger_contact_geoms(built)
    assert len(fingers) == 4
    np.testing.assert_array_equal(built.geom_solimp[fingers, 1], 0.99)
    np.testing.assert_array_equal(rope.geom_solimp[fingers, 1], 0.999)
    others = np.setdiff1d(np.arange(built.ngeom), fingers)
    np.testing.assert_array_equal(rope.geom_solimp[others], built.geom_solimp[others])
    np.testing.assert_array_equal(rope.geom_solimp[fingers, [0]], built.geom_solimp[fingers, [0]])
    assert HoseConfig(kinds=("garden_hose", "rope")).finger_contact_dmax() == 0.999
    assert HoseConfig(count=1, kinds=("garden_hose", "rope")).finger_contact_dmax() == 0.99
    soft_rope = model(HoseConfig(count=1, kind="rope", grip_dmax=0.99))
    np.testing.assert_array_equal(soft_rope.geom_solimp[fingers, 1], 0.99)


def test_a_config_of_the_robots_finger_hardness_loads_as_the_cables() -> None:
    """``robot.finger_contact_dmax`` (2026-12-05's layout) loads as ``hoses.grip_dmax``, with
    a migration warning, so the run grips every cable as it did; both given and different is
    the project's error naming the old field."""
    from cablesim.config import ConfigMigrationWarning

    data = SceneConfig(hoses=HoseConfig(kind="rope")).to_dict()
    data["robot"]["finger_contact_dmax"] = 0.99
    with pytest.warns(ConfigMigrationWarning, match="robot.finger_contact_dmax moved"):
        old = SceneConfig.from_dict(data)
    assert old.hoses.grip_dmax == 0.99 and old.hoses.finger_contact_dmax() == 0.99
    data["hoses"]["grip_dmax"] = 0.995
    with pytest.raises(ConfigError) as e:
        SceneConfig.from_dict(data)
    assert e.value.field == "robot.finger_contact_dmax"


def test_config_round_trips_and_prints() -> None:
    cfg = SceneConfig(seed=7, hoses=HoseConfig(count=3), board=BoardConfig(background="bushes"))
    again = SceneConfig.from_dict(cfg.to_dict())
    assert again == cfg
    assert '"background": "bushes"' in str(cfg)
    with pytest.raises(ConfigError, match="unknown field"):
        SceneConfig.from_dict({"seed": 1, "hosez": {}})


@pytest.mark.parametrize("seed", range(6))
def test_layout_is_seeded_and_within_ranges(seed: int) -> None:
    cfg = _cfg(seed=seed)
    a, b = sample_hoses(cfg), sample_hoses(cfg)
    assert a == b
    used = [c for s in a for c in s.ends]
    assert len(used) == len(set(used)), "two hose ends on one connector"
    for s in a:
        assert cfg.hoses.length[0] <= s.length <= cfg.hoses.length[1]
        pts = start_shape(cfg, s)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        assert seg.sum() == pytest.approx(s.length, rel=0.02)
        assert pts[:, 2].min() >= cfg.hoses.cable(0).radius  # nothing starts inside the table
    assert sample_hoses(_cfg(seed=seed + 100)) != a


def test_start_shapes_do_not_intersect() -> None:
    for seed in range(5):
        cfg = _cfg(seed=seed)
        shapes = [start_shape(cfg, s) for s in sample_hoses(cfg)]
        for i in range(len(shapes)):
            for j in range(i + 1, len(shapes)):
                d = np.linalg.norm(shapes[i][:, None] - shapes[j][None], axis=2)
                # at most a shallow overlap (where one hose passes right in front of another's
                # coupling) that contacts push apart; never one rod through another
                assert d[1:-1, 1:-1].min() > 1.3 * cfg.hoses.cable(0).radius, (seed, i, j)


@pytest.fixture(scope="module")
def settled(tmp_path_factory):
    import os

    os.environ["CABLESIM_CACHE"] = str(tmp_path_factory.mktemp("cache"))
    from cablesim.sim.world import World

    cfg = _cfg(seed=1, camera=CameraConfig(width=160, height=120))
    return World.build(cfg)


def test_settled_scene_is_slow_and_unstretched(settled) -> None:
    from cablesim.sim.settle import max_vertex_speed

    world = settled
    assert max_vertex_speed(world) < world.cfg.physics.settle_speed
    for i, hose in enumerate(world.hoses):
        v = world.hose_vertices(i)
        length = np.linalg.norm(np.diff(v, axis=0), axis=1).sum()
        assert length == pytest.approx(hose.spec.length, rel=0.002), "hose stretched"
        assert v[:, 2].min() > 0, "hose fell through the table"
        assert v[:, 0].max() < world.cfg.board.x, "hose went through the board"


def test_settle_cache_gives_the_same_state(settled) -> None:
    from cablesim.sim.world import World

    again = World.build(settled.cfg)  # loads the cache written by the fixture
    np.testing.assert_array_equal(again.get_state(), settled.get_state())
    fresh = World.build(settled.cfg.replace(physics=PhysicsConfig(cache=False)))
    np.testing.assert_array_equal(fresh.get_state(), settled.get_state())


def test_far_ends_stay_on_their_connectors(settled) -> None:
    from cablesim.sim.layout import attach_point

    world = settled
    world.step(100)
    for i, hose in enumerate(world.hoses):
        v = world.hose_vertices(i)
        # both ends are held by connect equalities (soft constraints): within a millimetre
        np.testing.assert_allclose(v[0], attach_point(world.cfg, hose.spec.ends[0]), atol=1e-3)
        if hose.spec.both_ends:
            np.testing.assert_allclose(v[-1], attach_point(world.cfg, hose.spec.ends[1]), atol=1e-3)
    world.reset()


def test_diverged_physics_raises_a_named_error(settled) -> None:
    from cablesim.errors import PhysicsDivergedError

    world = settled
    world.data.qvel[:] = np.nan
    with pytest.raises(PhysicsDivergedError, match="diverged"):
        world.step(1)
    world.reset()
    world.step(1)  # usable again after reset


def test_the_settle_and_the_run_fall_back_to_cg_for_their_own_times(settled) -> None:
    """CG stands in for ``physics.fallback_time`` (1 s) while a scene settles and for
    ``physics.run_fallback_time`` (0.25 s) in every step after; a file without the latter
    (written before it existed) reruns with 1 s throughout."""
    import contextlib

    import mujoco

    from cablesim.config import from_dict, to_dict

    world = settled
    m = world.model
    newton, cg = int(mujoco.mjtSolver.mjSOL_NEWTON), int(mujoco.mjtSolver.mjSOL_CG)
    p = world.cfg.physics
    assert (p.fallback_time, p.run_fallback_time) == (1.0, 0.25)
    iterations = m.opt.iterations
    for settling, seconds in ((True, 1.0), (False, 0.25)):
        world.reset()
        with world.settling() if settling else contextlib.nullcontext():
            assert world.fallback_time == seconds
            m.opt.iterations = 1  # every Newton step ends at the limit: CG stands in
            try:
                world.step(1)
            finally:
                m.opt.iterations = iterations
        assert world.solver_fallbacks == 1
        world.step(round(seconds / m.opt.timestep) - 2)
        assert m.opt.solver == cg, f"CG should stand in for {seconds} s"
        world.step(1)
        assert m.opt.solver == newton, f"Newton should resume after {seconds} s"
    world.reset()
    old = to_dict(PhysicsConfig())
    del old["run_fallback_time"]
    assert from_dict(PhysicsConfig, old).run_fallback_time is None
    from cablesim.sim.world import World

    before = World.build(world.cfg.replace(physics=PhysicsConfig(run_fallback_time=None)), False)
    assert before.fallback_time == 1.0


def test_cg_stands_in_where_newton_does_not_converge(settled) -> None:
    """A Newton step that hits the iteration limit is redone from the same state with CG (the
    committed step is CG's), CG goes on for fallback_time, then Newton resumes; reset restores
    Newton and the same pull gives the same state again."""
    import mujoco

    world = settled
    m, d = world.model, world.data
    newton, cg = int(mujoco.mjtSolver.mjSOL_NEWTON), int(mujoco.mjtSolver.mjSOL_CG)
    assert m.opt.solver == newton
    body = int(world.hoses[0].vertex_bodies[len(world.hoses[0].vertex_bodies) // 2])
    iterations = m.opt.iterations

    def pulled_state() -> np.ndarray:
        world.reset()
        d.xfrc_applied[body, :3] = [0.0, 0.5, 0.3]
        world.step(3)
        return world.get_state()

    state = pulled_state()
    m.opt.iterations = 1  # Newton cannot converge in one iteration on a pulled hose
    try:
        world.step(1)
        assert world.solver_fallbacks == 1
        assert m.opt.solver == cg  # CG goes on ...
        after_one = world.get_state()
        # ... and the committed step is exactly a CG step from the same state
        world.set_state(state)
        m.opt.solver = cg
        mujoco.mj_step(m, d)
        np.testing.assert_array_equal(world.get_state(), after_one)
    finally:
        m.opt.iterations = iterations
    world.set_state(after_one)
    m.opt.solver = cg
    world.step(round(world.fallback_time / m.opt.timestep) - 1)
    assert m.opt.solver == newton  # Newton resumes after fallback_time
    assert world.solver_fallbacks == 1
    end = world.get_state()
    assert not np.array_equal(end, state)
    np.testing.assert_array_equal(pulled_state(), state)
    world.reset()
    assert m.opt.solver == newton and world.solver_fallbacks == 0
    d.xfrc_applied[body, :] = 0.0
