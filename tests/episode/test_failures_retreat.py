"""Unreachable targets fail quickly with a reason (before any motion); the retreat configuration
is out of the default camera's view; a push runs without grasping."""

from __future__ import annotations

import time

import mujoco
import numpy as np
import pytest

from cablesim.episode import primitives as prim
from cablesim.episode.config import RetreatConfig
from cablesim.frames import LABEL_ROBOT
from cablesim.panda import PARK_QPOS
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.sim.session import SimSession

SEED, N_HOSES = 2, 3
#: The retract configuration turned away about joint 1: zero robot pixels in the default
#: camera for joint 1 in [-2.10, -1.70]
TURNED_AWAY_QPOS = (-1.9, -0.6, 0.0, -2.3, 0.0, 1.7, 0.785398)


@pytest.fixture(scope="module")
def small_world():
    from cablesim.sim.world import World

    cfg = EpisodeConfig(
        scene=SceneConfig(
            seed=SEED, hoses=HoseConfig(count=N_HOSES), camera=CameraConfig(width=160, height=120)
        ),
    )
    session = SimSession.build(cfg, world=World.build(cfg.scene))
    yield cfg, session.world, session.camera
    session.close()


@pytest.fixture()
def scene(small_world):
    """A fresh session on the settled small scene (world and camera reused)."""
    cfg, world, camera = small_world
    session = SimSession.build(cfg, world=world, camera=camera)
    return cfg, session


def test_unreachable_grasp_fails_before_moving(scene):
    _, session = scene
    world, robot = session.world, session.robot
    t_sim, t0 = world.time, time.perf_counter()
    res = prim.grasp_at(robot, np.array([1.6, 0.9, 1.4]), np.array([0.0, 0.0, 1.0]))
    wall = time.perf_counter() - t0
    print(f"unreachable grasp: {res.reason!r} after {wall:.2f} s")
    assert not res and "unreachable" in res.reason
    assert world.time == t_sim  # nothing was simulated: the IK check refused it


def test_unreachable_segment_episode_fails_with_reason(scene):
    cfg, session = scene
    world, cam = session.world, session.camera
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
    res = session.interact(mask)
    print(res.summary())
    assert not res.success and "unreachable" in res.reason
    assert res.stream is None
    assert world.time == t_sim


def test_the_simulated_panda_names_what_its_arm_model_refuses(scene):
    """A refused plan is ``unreachable`` where it is detected, before anything moves; a refused
    argument names no outcome (the step that asked for the motion names it)."""
    from cablesim.outcomes import Outcome

    _, session = scene
    world, robot = session.world, session.robot
    t_sim = world.time
    far = robot.ee_pose().translated(np.array([0.0, 0.0, 1.5]))  # far above the arm's reach
    r = robot.move_to(far)
    assert not r and r.outcome is Outcome.UNREACHABLE, r.reason
    q = robot.joint_positions
    q[0] = 5.0  # past joint 1's limit
    r = robot.move_joints(q)
    assert not r and r.outcome is Outcome.UNREACHABLE and r.reason.startswith("joint limit")
    r = robot.move_to(far, speed=0.0)
    assert not r and r.outcome is None
    assert world.time == t_sim


def test_segment_input_errors_come_back_as_failures(scene):
    _, session = scene
    res = session.interact(np.zeros((120, 160), bool))
    assert not res.success and "segment" in res.reason and "empty" in res.reason


@pytest.mark.parametrize("qpos", ["scene", "turned away"])
def test_retreat_configuration_is_out_of_the_default_view(qpos):
    """Zero robot pixels in the default camera (640x480) with the arm at the retreat target."""
    from cablesim.panda.model import joint_qpos_addresses
    from cablesim.sim.camera import SimCamera
    from cablesim.sim.world import World

    world = World.build(SceneConfig(seed=SEED, hoses=HoseConfig(count=1)))
    park = tuple(world.cfg.robot.park_qpos)
    q = RetreatConfig().joint_target(park) if qpos == "scene" else TURNED_AWAY_QPOS
    assert qpos != "scene" or q == tuple(PARK_QPOS)
    world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = q
    mujoco.mj_forward(world.model, world.data)
    with SimCamera(world) as cam:
        assert cam.intrinsics.width == 640
        n = int((cam.render_labels() == LABEL_ROBOT).sum())
    print(f"retreat {qpos} {np.round(q, 2)}: {n} robot pixels")
    assert n == 0


@pytest.mark.slow
def test_push_episode(scene):
    cfg, session = scene
    seg = session.pick_start(1)
    push = cfg.interaction.with_values(kind="push", **{"actions.periods": 1})
    res = session.interact(seg.mask, push)
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
    ],
)
def test_bad_episode_config_names_the_field(change, field) -> None:
    from cablesim.errors import ConfigError

    with pytest.raises(ConfigError) as e:
        EpisodeConfig(**change)
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
    from cablesim.errors import ConfigError

    with pytest.raises(ConfigError) as e:  # through the config: its full path
        EpisodeConfig().with_values({f"interaction.{section}.{name}": value})
    assert e.value.field == f"interaction.{section}.{name}"
    part = type(getattr(EpisodeConfig().interaction, section))
    with pytest.raises(ConfigError) as e:  # the section made on its own: its own name
        part(**{name: value})
    assert e.value.field == f"{section}.{name}"
