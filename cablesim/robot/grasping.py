"""Grasp and release sequences built from the :class:`Robot` primitives.

``approach_and_grasp``: open, joint-space move to ``RETRACT_QPOS`` and from there to a pre-grasp
pose ``pregrasp_distance`` behind the grasp along the hand's approach axis, straight line in,
close.  ``release_and_retreat``: open, straight line out, retract.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from cablesim.outcomes import Outcome, worst
from cablesim.panda.description import MAX_OPENING, RETRACT_QPOS
from cablesim.pose import Pose
from cablesim.robot.base import MoveResult, Robot


def pregrasp_pose(grasp: Pose, distance: float) -> Pose:
    """``grasp`` moved back by ``distance`` along its approach (hand z) axis."""
    return grasp.translated(-distance * grasp.rotation[:, 2])


@contextmanager
def avoiding_hoses(robot: Robot) -> Iterator[None]:
    """Inside the block the robot plans its arm links around the hoses, where its arm model
    knows them (the simulated Panda hands them over: ``SimPandaConfig.avoid_hoses``; a real
    arm's model has none, so nothing changes there).  The approach to a grasp or a push runs
    inside it: planned against the board alone, a joint motion swept link6 through a hose and
    crushed it (seeds 6062, 6077).  Retreats and parking stay outside: after the perception a
    link brushing a hose does no harm, and a retreat that refused to would end the run."""
    arm = getattr(robot, "arm", None)
    if arm is None or not hasattr(arm, "avoid_hoses"):
        yield
        return
    before = arm.avoid_hoses
    arm.avoid_hoses = True
    try:
        yield
    finally:
        arm.avoid_hoses = before


def move_joints_safely(robot: Robot, q, speed_factor: float = 0.3) -> MoveResult:
    """Joint move; if the direct path is blocked, go through the retract configuration.  When
    the way round fails too, the result names the worse of the two outcomes."""
    res = robot.move_joints(q, speed_factor)
    if res or not res.reason.startswith("collision"):
        return res
    via = robot.move_joints(RETRACT_QPOS, speed_factor)
    if not via:
        return MoveResult(
            False,
            f"direct path blocked ({res.reason}); via retract: {via.reason}",
            outcome=worst(res.outcome, via.outcome),
        )
    return robot.move_joints(q, speed_factor)


def approach_and_grasp(
    robot: Robot,
    grasp: Pose,
    pregrasp_distance: float = 0.08,
    width: float = 0.015,
    force: float = 70.0,
    speed: float = 0.05,
) -> tuple[MoveResult, bool]:
    """Move to ``grasp`` from behind and close the gripper; returns (motion result, held)."""
    pre = pregrasp_pose(grasp, pregrasp_distance)
    for pose, what in ((grasp, "grasp"), (pre, "pre-grasp")):
        ok, reason = robot.check_reachable(pose)
        if not ok:
            return MoveResult(
                False, f"{what} pose unreachable: {reason}", outcome=Outcome.UNREACHABLE
            ), False
    q_pre = robot.solve_ik(pre)
    if q_pre is None:
        return MoveResult(False, "pre-grasp pose unreachable", outcome=Outcome.UNREACHABLE), False
    if robot.gripper_opening < MAX_OPENING - 0.005:
        robot.open()
    # Through the retract configuration (hand down, pulled back): a direct joint move from
    # wherever the arm is may sweep through hoses, which the arm-only checks cannot see.
    res = move_joints_safely(robot, RETRACT_QPOS)
    if not res:
        why = f"could not retract before the approach: {res.reason}"
        return MoveResult(False, why, outcome=res.outcome), False
    res = robot.move_joints(q_pre)
    if not res:
        return res, False
    res = robot.move_to(grasp, speed=speed)
    if not res:
        return res, False
    return res, robot.grasp(width=width, force=force)


def release_and_retreat(robot: Robot, distance: float = 0.08, speed: float = 0.1) -> MoveResult:
    """Open, back off along the approach axis, then go to the retract configuration."""
    robot.open()
    pose = robot.ee_pose()
    res = robot.move_to(pregrasp_pose(pose, distance), speed=speed)
    if not res:
        return res
    return move_joints_safely(robot, RETRACT_QPOS)
