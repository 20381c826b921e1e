"""Unreachable targets fail quickly with a reason (before any motion); the retreat configuration
is out of the default camera's view; a push runs without grasping."""

from __future__ import annotations

import time

import mujoco
import numpy as np
import pytest

from cablesim.episode import primitives as prim
from cablesim.episode.config import FALLBACK_RETREAT_QPOS, EpisodeConfig, RetreatConfig
from cablesim.episode.runner import run_episode
from cablesim.perception.frames import LABEL_ROBOT
from cablesim.sim.config import CameraConfig, HoseConfig, SceneConfig

SEED, N_HOSES = 2, 3


@pytest.fixture(scope="module")
def scene():
    from cablesim.robot.sim_panda import SimPanda
    from cablesim.sim.camera import SimCamera
    from cablesim.sim.world import World

    cfg = EpisodeConfig(
        seed=SEED,
        scene=SceneConfig(
            hoses=HoseConfig(count=N_HOSES), camera=CameraConfig(width=160, height=120)
        ),
    )
    world = World.build(cfg.scene_config())
    cam = SimCamera(world)
    yield cfg, world, SimPanda(world), cam
    cam.close()


def test_unreachable_grasp_fails_before_moving(scene):
    _, world, robot, _ = scene
    world.reset()
    t_sim, t0 = world.time, time.perf_counter()
    res = prim.grasp_at(robot, np.array([1.6, 0.9, 1.4]), np.array([0.0, 0.0, 1.0]))
    wall = time.perf_counter() - t0
    print(f"unreachable grasp: {res.reason!r} after {wall:.2f} s")
    assert not res and "unreachable" in res.reason
    assert world.time == t_sim  # nothing was simulated: the IK check refused it


def test_unreachable_segment_episode_fails_with_reason(scene):
    cfg, world, robot, cam = scene
    world.reset()
    # a segment on the far top corner of the board, away from the robot (base at y = -0.62)
    mask = np.zeros((120, 160), bool)
    img = cam.capture()
    labels = cam.render_labels()
    board = (labels == -1) & (img.depth > 0) & (img.depth < 2.0)
    v, u = np.nonzero(board)
    corner = np.argmin(u + v)  # top left of the image: +y, high
    mask[v[corner] : v[corner] + 3, u[corner] : u[corner] + 12] = True
    mask &= board
    t_sim = world.time
    res = run_episode(world, robot, cam, mask, cfg)
    print(res.summary())
    assert not res.success and "unreachable" in res.reason
    assert res.stream is None
    assert world.time == t_sim


def test_segment_input_errors_come_back_as_failures(scene):
    cfg, world, robot, cam = scene
    res = run_episode(world, robot, cam, np.zeros((120, 160), bool), cfg)
    assert not res.success and "segment" in res.reason and "empty" in res.reason


@pytest.mark.parametrize("qpos", ["scene", "fallback"])
def test_retreat_configuration_is_out_of_the_default_view(qpos):
    """Zero robot pixels in the default camera (640x480) with the arm at the retreat target."""
    from cablesim.sim.camera import SimCamera
    from cablesim.sim.panda import joint_qpos_addresses
    from cablesim.sim.world import World

    world = World.build(SceneConfig(seed=SEED, hoses=HoseConfig(count=1)))
    q = RetreatConfig().joint_target(world.cfg) if qpos == "scene" else FALLBACK_RETREAT_QPOS
    world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = q
    mujoco.mj_forward(world.model, world.data)
    with SimCamera(world) as cam:
        assert cam.intrinsics.width == 640
        n = int((cam.render_labels() == LABEL_ROBOT).sum())
    print(f"retreat {qpos} {np.round(q, 2)}: {n} robot pixels")
    assert n == 0


@pytest.mark.slow
def test_push_episode(scene):
    from cablesim.episode.picker import pick_segment
    from cablesim.sim.layout import rng_streams

    cfg, world, robot, cam = scene
    world.reset()
    cfg = cfg.replace(kind="push", hose=1)
    cfg.actions.periods = 1
    seg = pick_segment(world, robot, cam, 1, rng_streams(SEED)["episode"], cfg)
    res = run_episode(world, robot, cam, seg.mask, cfg)
    print(res.summary())
    assert res.success, res.reason
    assert res.stream.actions == [0]
    assert res.target_robot_pixels == 0
    moved = res.actions[0].hose_displacement
    print(f"push: hose displacement (mm) {np.round(np.array(moved) * 1000, 1)}")
    assert moved[1] > 0.005  # the pushed hose moved
    assert all(f.gripper_opening < 0.005 for f in res.stream if not f.is_target)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"hose": "1"}, "hose"),
        ({"hose": 9}, "hose"),
        ({"kind": "pull"}, "kind"),
    ],
)
def test_bad_episode_config_names_the_field(change, field) -> None:
    from cablesim.episode.config import EpisodeConfig
    from cablesim.errors import ConfigError

    with pytest.raises(ConfigError) as e:
        EpisodeConfig(**change).validate()
    assert e.value.field == field


@pytest.mark.parametrize(
    ("section", "name", "value"),
    [
        ("grasp", "epsilon", -0.01),
        ("grasp", "force", "strong"),
        ("actions", "stroke_tolerance", -1.0),
        ("retreat", "speed_factor", 2.0),
    ],
)
def test_bad_episode_section_values_name_the_field(section, name, value) -> None:
    from cablesim.episode.config import EpisodeConfig
    from cablesim.errors import ConfigError

    cfg = EpisodeConfig()
    setattr(getattr(cfg, section), name, value)
    with pytest.raises(ConfigError) as e:
        cfg.validate()
    assert e.value.field == f"{section}.{name}"
