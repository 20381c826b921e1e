"""The hoses as obstacles for the arm links (issue 9): a joint motion planned against the board
alone swept link6 through a hose and crushed it until the physics tore it apart (seeds 6062,
6077).  The arm model takes the hoses as chains of capsules that the links see and the hand
and fingers do not (they reach in among the hoses to grasp)."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.panda import HOME_QPOS
from cablesim.panda.ik import ArmModel

RADIUS = 0.0125  # a 7.5 mm hose with 5 mm clearance


@pytest.fixture(scope="module")
def arm() -> ArmModel:
    model = ArmModel(hose_capsules=[0.02] * 20, hose_radius=RADIUS)
    model.avoid_hoses = True
    return model


def _geom_centre(arm: ArmModel, q: np.ndarray, name: str) -> np.ndarray:
    arm.set_q(q, 0.08)
    return arm.data.geom_xpos[arm.model.geom(name).id].copy()


def _line_through(point: np.ndarray, direction=(0.0, 1.0, 0.0), n: int = 6) -> np.ndarray:
    """A straight hose of n vertices, 4 cm apart, centred on ``point``."""
    u = np.asarray(direction, float) / np.linalg.norm(direction)
    return point + np.outer((np.arange(n) - (n - 1) / 2) * 0.04, u)


def test_a_hose_through_link6_is_a_collision_and_removing_it_clears_it(arm: ArmModel) -> None:
    q = np.asarray(HOME_QPOS, float)
    assert arm.check(q, hoses=True) == ""
    arm.set_hoses([_line_through(_geom_centre(arm, q, "arm/link6_g1"))])
    reason = arm.check(q, hoses=True)
    assert "link6" in reason and "hose/" in reason
    assert arm.check(q) == ""  # a configuration alone (a waypoint of a line) does not see them
    arm.set_hoses()
    assert arm.check(q, hoses=True) == ""


def test_a_hose_beside_the_link_is_not_a_collision(arm: ArmModel) -> None:
    q = np.asarray(HOME_QPOS, float)
    centre = _geom_centre(arm, q, "arm/link6_g1")
    arm.set_hoses([_line_through(centre + np.array([0.0, 0.0, 0.3]))])
    assert arm.check(q, hoses=True) == ""
    arm.set_hoses()


def test_the_hand_and_fingers_do_not_see_the_hoses(arm: ArmModel) -> None:
    """A hose between the open fingers (where a grasp puts it) is no collision."""
    q = np.asarray(HOME_QPOS, float)
    tcp = arm.fk(q).position
    arm.set_hoses([_line_through(tcp)])
    assert arm.check(q, hoses=True) == ""
    arm.set_hoses()


def test_capsules_follow_the_polyline(arm: ArmModel) -> None:
    """Each segment takes one capsule, centred on it and along it."""
    line = np.array([[0.5, 0.0, 0.5], [0.5, 0.0, 0.46], [0.5, 0.04, 0.46], [0.53, 0.04, 0.5]])
    arm.set_hoses([line])
    arm.set_q(np.asarray(HOME_QPOS, float))
    d, m = arm.data, arm.model
    for k in range(3):
        g = m.geom(f"hose/{k}").id
        np.testing.assert_allclose(d.geom_xpos[g], 0.5 * (line[k] + line[k + 1]), atol=1e-12)
        axis = d.geom_xmat[g].reshape(3, 3)[:, 2]
        u = (line[k + 1] - line[k]) / np.linalg.norm(line[k + 1] - line[k])
        assert abs(abs(axis @ u) - 1.0) < 1e-9
    assert d.geom_xpos[m.geom("hose/3").id][2] < -5  # unused capsules wait far below
    arm.set_hoses()


def test_too_many_segments_is_an_error(arm: ArmModel) -> None:
    with pytest.raises(ValueError, match="21 hose segments"):
        arm.set_hoses([np.zeros((22, 3))])


def test_a_path_that_starts_touching_a_hose_may_leave_it_but_not_hit_another(
    arm: ArmModel,
) -> None:
    """A link touching a hose at the start of a motion (after a grasp, say) may move away
    from it; a contact with another hose along the way still fails the motion."""
    q0 = np.asarray(HOME_QPOS, float)
    q1 = q0.copy()
    q1[0] += 0.6  # turn the arm about its base
    start = _geom_centre(arm, q0, "arm/link6_g1")
    arm.set_hoses([_line_through(start)])
    assert arm.check(q0, hoses=True) != ""
    assert arm.check_joint_path(q0, q1, 0.08) == ""
    mid = _geom_centre(arm, q0 + 0.5 * (q1 - q0), "arm/link6_g1")
    arm.set_hoses([_line_through(start), _line_through(mid, direction=(0.0, 0.0, 1.0))])
    reason = arm.check_joint_path(q0, q1, 0.08)
    assert "link6" in reason and "joint path" in reason
    arm.set_hoses()


def test_hoses_count_only_while_avoiding_them(arm: ArmModel) -> None:
    """``avoiding_hoses`` (the approach to a grasp or push) switches the hose check on for the
    block; outside it (retreat, parking) a link may brush a hose."""
    from cablesim.robot.grasping import avoiding_hoses

    class Holder:  # anything with an arm model, as SimPanda and DryRunRobot
        pass

    robot = Holder()
    robot.arm = arm
    q = np.asarray(HOME_QPOS, float)
    arm.set_hoses([_line_through(_geom_centre(arm, q, "arm/link6_g1"))])
    arm.avoid_hoses = False
    assert arm.check(q, hoses=True) == ""
    with avoiding_hoses(robot):
        assert "hose/" in arm.check(q, hoses=True)
    assert arm.check(q, hoses=True) == "" and arm.avoid_hoses is False
    arm.avoid_hoses = True
    arm.set_hoses()
