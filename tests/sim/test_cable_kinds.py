"""The catalogue of cable kinds: each preset builds, settles and is grasped; a rope bends under
its own weight more than a cable; kinds mix per cable and survive config.json."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from cablesim.cables import CABLE_KINDS, DEFAULT_KIND, GARDEN_HOSE, cable_kind
from cablesim.cli import main
from cablesim.config import to_dict
from cablesim.dataset.randomize import Randomization, randomize_scene
from cablesim.episode.config import GraspConfig
from cablesim.errors import ConfigError
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.sim.layout import sample_hoses

OTHER_KINDS = [k for k in CABLE_KINDS if k != DEFAULT_KIND]
GRASPED_KINDS = [
    "electrical_cable",
    "rope",
    "thin_wire",
]  # the default hose: tests/sim, tests/episode


def test_the_default_kind_is_the_hose_the_scenes_always_had() -> None:
    """The default scene's cables are today's 15 mm hose: same numbers, same draws."""
    h = HoseConfig()
    assert h.kind == DEFAULT_KIND == "garden_hose" and h.kinds == ()
    assert h.cable(0) is GARDEN_HOSE
    c = GARDEN_HOSE
    assert (c.radius, c.segment_length, c.young, c.poisson) == (0.0075, 0.03, (2e6, 8e6), 0.3)
    assert (c.mass_per_metre, c.damping, c.friction, len(c.colors)) == (0.15, 0.02, 0.9, 8)
    assert GraspConfig().fitted() == GraspConfig(width=0.015, epsilon=0.012, surface_offset=0.0075)


def test_every_kind_is_documented_and_listed(capsys) -> None:
    assert {"garden_hose", "electrical_cable", "thin_wire", "rope"} <= set(CABLE_KINDS)
    for kind in CABLE_KINDS.values():
        assert kind.sources and kind.summary
        assert kind.segment_length > 2 * kind.radius and kind.young[0] <= kind.young[1]
    assert main(["cables"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(CABLE_KINDS)
    assert "diameter 2.0 mm" in lines[list(CABLE_KINDS).index("thin_wire")]


def test_kinds_are_told_apart_by_diameter_and_stiffness() -> None:
    hose, cable, wire, rope = (cable_kind(k) for k in CABLE_KINDS)
    assert 0.005 <= 2 * cable.radius <= 0.010 and 0.0015 <= 2 * wire.radius <= 0.003
    assert 0.008 <= 2 * rope.radius <= 0.012
    # electrical cable: stiffer per diameter than the hose; rope: the softest in bending
    assert cable.young[0] > hose.young[1] and rope.young[1] < hose.young[1]
    assert rope.bending_stiffness()[1] < cable.bending_stiffness()[0]


def test_an_unknown_kind_is_refused_by_name() -> None:
    with pytest.raises(ConfigError, match=r"hoses\.kind.*'wire'.*thin_wire"):
        HoseConfig(kind="wire")
    with pytest.raises(ConfigError, match=r"hoses\.kinds\[1\].*'cord'"):
        HoseConfig(kinds=("rope", "cord"))
    # an override is checked against every kind it applies to, and named as the override
    with pytest.raises(ConfigError, match=r"hoses\.segment_length.*diameter"):
        HoseConfig(kind="rope", segment_length=0.005)
    with pytest.raises(ConfigError, match=r"scene\.cable.*'hose'"):
        from cablesim.thesis.config import SceneSize

        SceneSize(cable="hose")


def test_overrides_apply_to_every_kind() -> None:
    h = HoseConfig(kinds=("rope", "thin_wire"), friction=0.7, count=3)
    assert [h.kind_of(i) for i in range(3)] == ["rope", "thin_wire", "rope"]
    assert all(h.cable(i).friction == 0.7 for i in range(3))
    assert h.cable(1).radius == CABLE_KINDS["thin_wire"].radius
    assert h.max_diameter() == 2 * CABLE_KINDS["rope"].radius


def test_mixed_kinds_round_trip_through_config_json_and_build_their_own_cables() -> None:
    cfg = EpisodeConfig(
        scene=SceneConfig(
            seed=5, hoses=HoseConfig(count=4, kinds=("rope", "thin_wire", "electrical_cable"))
        )
    )
    back = EpisodeConfig.from_dict(json.loads(json.dumps(to_dict(cfg))))
    assert back == cfg
    specs = sample_hoses(back.scene)
    assert [s.kind for s in specs] == ["rope", "thin_wire", "electrical_cable", "rope"]
    assert [s.radius for s in specs] == [CABLE_KINDS[s.kind].radius for s in specs]
    # each cable's palette and its own vertex spacing
    for s in specs:
        palette = np.array(CABLE_KINDS[s.kind].colors)
        jitter = CABLE_KINDS[s.kind].color_jitter
        assert np.abs(palette - np.array(s.rgb)).max(axis=1).min() <= jitter + 1e-12
        assert s.length / (s.n_vertices - 1) == pytest.approx(
            CABLE_KINDS[s.kind].segment_length, rel=0.35
        )


def test_a_rope_sags_under_its_own_weight_more_than_a_cable_of_its_diameter() -> None:
    from cablesim.sim.cantilever import cantilever_sag

    rope = CABLE_KINDS["rope"]
    cable = dataclasses.replace(CABLE_KINDS["electrical_cable"], radius=rope.radius)
    rope_sag, cable_sag = cantilever_sag(rope), cantilever_sag(cable)
    assert rope_sag > 2 * cable_sag, (rope_sag, cable_sag)
    # and a stiffer rod of one kind sags less (the measurement follows the stiffness)
    assert cantilever_sag(rope, rope.young[1]) < cantilever_sag(rope, rope.young[0])


def test_inertia_scale_moves_a_cable_as_if_heavier_and_keeps_its_weight() -> None:
    from cablesim.sim.cantilever import cantilever_sag

    light = CABLE_KINDS["electrical_cable"]
    cable = dataclasses.replace(light, inertia_scale=2.8)
    assert all(k.inertia_scale == 1 for k in CABLE_KINDS.values())  # as built, every kind
    # settled, the same sag: the weight and the stiffness are the kind's
    assert cantilever_sag(cable) == pytest.approx(cantilever_sag(light), rel=2e-3)
    # 0.2 s after the release, the cable that moves as if heavier has fallen less far
    assert cantilever_sag(cable, time=0.2) < 0.6 * cantilever_sag(light, time=0.2)
    # lighter than built is not offered (a gravity compensation above 1 would lift it)
    with pytest.raises(ConfigError, match=r"hoses\.inertia_scale.*0\.5"):
        HoseConfig(kind="electrical_cable", inertia_scale=0.5)


def _lying_on_the_table(kind: str, scale: float):
    """Table seed 21's settled world of ``kind`` cables built with ``inertia_scale`` ``scale``
    (uncached), checked to carry ``1 - 1/scale`` of each vertex's weight by compensation."""
    from cablesim.sim.world import World

    hoses = HoseConfig(kind=kind, inertia_scale=scale)
    cfg = SceneConfig(
        seed=21, surface="table", hoses=hoses, camera=CameraConfig(width=64, height=48)
    ).with_values({"physics.cache": False})
    world = World.build(cfg)
    bodies = world.hoses[0].vertex_bodies
    gravcomp = world.model.body_gravcomp[bodies[bodies > 0]]
    assert gravcomp == pytest.approx(np.full(len(gravcomp), 1 - 1 / scale))
    return world


def test_inertia_scale_keeps_a_lying_cable_out_of_the_mat() -> None:
    """A soft contact gives way in proportion to force over mass: the settled electrical
    cables sink less into the table's mat with the kind's inertia than without."""
    from cablesim.sim.table import MAT_TOP

    radius = CABLE_KINDS["electrical_cable"].radius

    def deepest(scale: float) -> float:
        world = _lying_on_the_table("electrical_cable", scale)
        return max(MAT_TOP + radius - world.hose_vertices(i)[:, 2].min() for i in range(4))

    light, heavy = deepest(1.0), deepest(2.8)
    assert light > 0 and heavy < 0.7 * light, (light, heavy)


def test_inertia_scale_keeps_a_pressed_wire_on_the_mat() -> None:
    """A thin wire lying on the table's mat, pressed down at one vertex by 0.3 N (a finger or
    a crossing cable), has sunk by more than its radius after 0.3 s when built as light as it
    weighs, and by less than half its radius moving as if 10 times heavier (a soft contact
    gives way in proportion to force over mass)."""
    from cablesim.sim.table import MAT_TOP

    wire = CABLE_KINDS["thin_wire"]

    def pressed_depth(scale: float) -> float:
        world = _lying_on_the_table("thin_wire", scale)
        k = len(world.hoses[0].vertex_bodies) // 2
        body = world.hoses[0].vertex_bodies[k]
        world.data.xfrc_applied[body, 2] = -0.3
        world.step(round(0.3 / world.model.opt.timestep))
        return MAT_TOP + wire.radius - world.hose_vertices(0)[k, 2]

    light, heavy = pressed_depth(1.0), pressed_depth(10.0)
    assert light > wire.radius and heavy < wire.radius / 2, (light, heavy)


def test_the_dataset_randomiser_draws_kinds_from_its_own_stream() -> None:
    base = SceneConfig()
    every = Randomization(cable_kinds=tuple(CABLE_KINDS))
    scenes = [randomize_scene(s, base, every) for s in range(30)]
    drawn = {k for c in scenes for k in c.hoses.kinds}
    assert drawn == set(CABLE_KINDS)
    assert all(len(c.hoses.kinds) == c.hoses.count for c in scenes)
    # the other draws are those of a dataset made before kinds existed
    plain = [randomize_scene(s, base) for s in range(30)]
    for a, b in zip(scenes, plain, strict=True):
        assert b.hoses.kinds == () and b.hoses.kind == DEFAULT_KIND
        assert a.replace(hoses=a.hoses.replace(kinds=())) == b
    one = randomize_scene(3, base, Randomization(cable_kinds=("rope",)))
    assert one.hoses.kind == "rope" and one.hoses.kinds == ()


def test_the_cable_flag_makes_every_cable_one_kind(tmp_path, capsys) -> None:
    path = tmp_path / "config.json"
    mixed = EpisodeConfig(scene=SceneConfig(hoses=HoseConfig(kinds=("rope", "thin_wire"))))
    path.write_text(json.dumps(to_dict(mixed)))
    assert main(["episode", "--config", str(path), "--cable", "thin_wire", "--show-config"]) == 0
    out = capsys.readouterr().out
    assert 'scene.hoses.kind = "thin_wire"' in out and "scene.hoses.kinds = []" in out


def test_a_grasp_fits_the_cable_it_closes_on() -> None:
    g = GraspConfig().fitted(0.002)
    assert (g.width, g.epsilon, g.surface_offset) == (0.002, pytest.approx(0.0016), 0.001)
    assert GraspConfig(width=0.004).fitted(0.002).width == 0.004  # a given value stays


@pytest.mark.parametrize("kind", OTHER_KINDS)
def test_each_kind_settles_within_its_stretch_limit(kind: str) -> None:
    """Four cables of the kind, at the extremes of its stiffness range, settle and do not
    stretch (the default timestep; the settle check is the scenes' own)."""
    from cablesim.sim.world import World

    for young in CABLE_KINDS[kind].young:
        cfg = SceneConfig(
            seed=21,
            hoses=HoseConfig(kind=kind, young=(young, young)),
            camera=CameraConfig(width=64, height=48),
        ).with_values({"physics.cache": False})
        world = World.build(cfg)
        assert {h.spec.kind for h in world.hoses} == {kind}
        assert world.hose_stretch().max() < 0.01  # World.build raises when it does not settle


@pytest.mark.parametrize("kind", GRASPED_KINDS)
def test_each_kind_is_grasped_and_follows_the_gripper(kind: str) -> None:
    """A whole simulated interaction on a scene of one kind: the grasp holds and the grasped
    cable follows both actions."""
    from cablesim.sim.session import SimSession

    seed, width, height = KIND_SCENES[kind]
    scene = SceneConfig(
        seed=seed,
        hoses=HoseConfig(count=2, kind=kind),
        camera=CameraConfig(width=width, height=height),
    )
    cfg = EpisodeConfig(scene=scene).with_values({"interaction.actions.periods": 1})
    session = SimSession.build(cfg)
    try:
        assert {h.spec.kind for h in session.world.hoses} == {kind}
        assert session.interaction_config().grasp.width == 2 * CABLE_KINDS[kind].radius
        result = session.interact(session.pick_start().mask)
        assert result.success, (result.outcome, result.reason)
        assert result.details["grasp"]["hold_error"] < 0.005
        assert all(a.gain > 0.5 for a in result.actions), [a.gain for a in result.actions]
    finally:
        session.close()


#: The scene per kind of the grasp test (seed, image size): a thin cable needs pixels to be
#: picked at all (a 7 mm cable is 1.5 px wide at 160x120 from the default camera, under the
#: picker's 10 px segments; a 2 mm wire about 1 px at 640x480).
KIND_SCENES = {
    "electrical_cable": (3, 320, 240),
    "rope": (3, 160, 120),
    "thin_wire": (3, 640, 480),
}


def test_the_scene_command_pulls_a_rope_without_tearing_it(tmp_path) -> None:
    """``cablesim scene --cable rope``: its pull is scaled to the rope's lighter vertices (the
    hose's 6 N spring tore a rope's edge to 79 % stretch)."""
    args = ["scene", "--cable", "rope", "--seed", "4", "--width", "160", "--height", "120"]
    assert main([*args, "--out", str(tmp_path)]) == 0
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["hoses"]["kind"] == "rope"
    assert np.load(tmp_path / "flow_valid.npy").any()


def test_the_neighbour_perturbation_moves_a_thin_wire_without_tearing_it() -> None:
    """The perturbation's springs are tuned for the hose's 4.3 g vertices; unscaled, their
    damping over a 4 ms step made a 0.2 g thin-wire vertex overshoot until the wire tore.
    Scaled by the vertex's mass, the pull moves the wire by centimetres and stretches it
    no more than the settled scene."""
    from cablesim.seeding import stream
    from cablesim.sim.config import PerturbConfig
    from cablesim.sim.perturb import REFERENCE_MASS, NeighbourPerturbation
    from cablesim.sim.world import World

    cfg = SceneConfig(
        seed=21,
        hoses=HoseConfig(kind="thin_wire", count=2),
        camera=CameraConfig(width=64, height=48),
    ).with_values({"physics.cache": False})
    world = World.build(cfg)
    body = world.hoses[1].vertex_bodies
    assert world.model.body_mass[body[body > 0]].max() < 0.1 * REFERENCE_MASS
    p = NeighbourPerturbation(PerturbConfig(enabled=True), stream(21, "perturb"), 0)
    p.start(world)
    start = world.hose_vertices(1).copy()
    moved, strain = 0.0, 0.0
    with world.hooks(before=[p.before_step]):
        for _ in range(int(2.0 / world.model.opt.timestep)):
            world.step()
            strain = max(strain, float(world.hose_stretch().max()))
            moved = max(moved, float(np.linalg.norm(world.hose_vertices(1) - start, axis=1).max()))
    p.stop(world)
    assert strain < 0.05, strain
    assert moved > 0.005, moved  # pulled 1-3 cm towards its targets
