"""SimPanda on the real World (seed 0): a reachable hose point is grasped and follows the hand."""

import numpy as np
import pytest

from cablesim.pose import grasp_pose
from cablesim.robot.grasping import approach_and_grasp
from cablesim.sim.sim_panda import SimPanda


@pytest.fixture(scope="module")
def world():
    world_mod = pytest.importorskip("cablesim.sim.world")
    from cablesim.sim.config import SceneConfig

    return world_mod.World.build(SceneConfig(seed=0))


def test_grasp_and_move_in_world(world):
    robot = SimPanda(world)
    target = None
    for h in range(len(world.hoses)):
        v = world.hose_vertices(h)
        for i in range(3, len(v) - 3):
            pose = grasp_pose(v[i], v[i + 1] - v[i - 1])
            margin = [pose.translated(d) for d in ([0, 0.04, 0], [0, -0.04, 0], [0, 0, 0.04])]
            if all(robot.check_reachable(p)[0] for p in [pose, *margin]):
                target = (h, i, pose)
                break
        if target:
            break
    assert target is not None, "no reachable hose point in scene seed 0"
    h, i, pose = target
    res, held = approach_and_grasp(robot, pose)
    assert res.success, res.reason
    assert held
    v0 = world.hose_vertices(h)[i].copy()
    p0 = robot.ee_pose().position
    res = robot.move_relative(np.array([0.0, 0.02, 0.0]), speed=0.05)
    assert res.success, res.reason
    d = robot.ee_pose().position - p0
    gain = float((world.hose_vertices(h)[i] - v0) @ d / (d @ d))
    print(f"world grasp gain {gain:.3f}")
    assert gain >= 0.9
