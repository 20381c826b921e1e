"""Safety limits (workspace box, speed caps) and the dry run, around the simulated arm: the
same wrappers the real robot gets."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.episode.clock import PlanningClock
from cablesim.episode.runner import InteractionOptions, run_interaction
from cablesim.errors import ConfigError
from cablesim.robot.dry_run import DryRunRobot
from cablesim.robot.guard import GuardedRobot, SafetyConfig
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.sim.session import SimSession

CFG = EpisodeConfig(
    scene=SceneConfig(
        seed=2, hoses=HoseConfig(count=3), camera=CameraConfig(width=160, height=120)
    ),
)


@pytest.fixture(scope="module")
def built():
    session = SimSession.build(CFG)
    yield session.world, session.camera
    session.close()


@pytest.fixture()
def session(built):
    world, camera = built
    return SimSession.build(CFG, world=world, camera=camera)


def test_target_outside_the_workspace_is_refused_before_moving(session):
    robot = GuardedRobot(session.robot, SafetyConfig(workspace_max=(0.9, 1.0, 0.5)))
    t = session.world.time
    high = session.robot.ee_pose().translated([0.0, 0.0, 0.6])
    r = robot.move_to(high)
    assert not r and "outside the workspace" in r.reason
    assert not robot.check_reachable(high)[0]
    assert session.world.time == t  # nothing was simulated


def test_speed_is_capped(session):
    robot = GuardedRobot(session.robot, SafetyConfig(max_speed=0.05))
    start = robot.ee_pose()
    target = start.translated([0.0, 0.05, 0.05])
    r = robot.move_to(target, speed=5.0)
    assert r, r.reason
    dist = float(np.linalg.norm(target.position - start.position))
    # minimum-jerk profile: duration = 1.875 * distance / peak speed, at the capped speed
    assert r.duration >= 1.875 * dist / 0.05 - 0.01


def test_joint_path_leaving_the_box_is_refused(session):
    low_box = SafetyConfig(workspace_min=(-0.2, -1.0, 0.3))  # the park pose is below z 0.3
    robot = GuardedRobot(session.robot, low_box)
    q = session.robot.joint_positions
    r = robot.move_joints(q + np.array([0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0]))
    assert not r and "outside the workspace" in r.reason


def test_bad_safety_config_names_the_field():
    with pytest.raises(ConfigError, match="workspace_min"):
        SafetyConfig(workspace_min=(1.0, 0.0, 0.0), workspace_max=(0.5, 1.0, 1.0)).validate()
    with pytest.raises(ConfigError, match="max_speed"):
        SafetyConfig(max_speed=0.0).validate()


def test_dry_run_plans_a_whole_interaction_without_moving(session):
    segment = session.pick_start()
    plan = DryRunRobot(GuardedRobot(session.robot))
    t, q = session.world.time, session.robot.joint_positions
    result = run_interaction(
        plan,
        session.camera,
        PlanningClock(session.camera),
        segment.mask,
        CFG.interaction,
        options=InteractionOptions(park=session.park),
    )
    assert result.success, result.reason
    assert session.world.time == t and np.array_equal(session.robot.joint_positions, q)
    kinds = [m.kind for m in plan.log]
    assert kinds.count("move_to") >= 2 + 2 * 4 * CFG.interaction.actions.periods
    assert "grasp" in kinds and "move_joints" in kinds
    # a refused motion is logged with its reason and left unmoved; the runner then takes its
    # fallback (e.g. a joint motion to the stand-off that would touch the board: straight in)
    refused = [m for m in plan.log if not m.ok]
    assert all(m.reason for m in refused)
    assert len(refused) < len(plan.log) // 4
    # the planned grasp lies at the estimated segment centre
    assert np.linalg.norm(result.grasp.position - result.centre) < 1e-6
