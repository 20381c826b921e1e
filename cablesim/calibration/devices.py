"""Driving the devices: move any :class:`~cablesim.robot.base.Robot` to the planned poses,
detect the board in any :class:`~cablesim.camera.base.Camera`'s image, and calibrate.

:func:`collect_samples` moves the robot there (``move_to``; a joint-space move to the IK
solution where the straight line is blocked) and detects the board in the camera's image;
:func:`calibrate_devices` plans, collects, returns home and calibrates.  The same code runs the
simulated Panda with a board in its hand (``RobotConfig.hand_board``) and the real one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from cablesim.calibration.board import BoardSpec, board_pose, detect_board
from cablesim.calibration.plan import PlanConfig, PlannedPose, Say, as_pose, plan_poses, quiet
from cablesim.calibration.solve import CalibrationResult, Sample, calibrate
from cablesim.errors import ConfigError
from cablesim.panda.description import RETRACT_QPOS
from cablesim.robot.grasping import move_joints_safely

if TYPE_CHECKING:  # pragma: no cover
    from cablesim.camera.base import Camera
    from cablesim.robot.base import Robot


def _move(robot: Robot, T: np.ndarray, speed: float) -> tuple[bool, str]:
    """Straight line to the TCP pose; where that is blocked (from the park pose, or an IK
    branch switch on the way), a joint-space move to its IK solution; where that path collides,
    through the retract configuration (then the line, else the joint move again)."""
    pose = as_pose(T)
    res = robot.move_to(pose, speed=speed)
    if res:
        return True, "line"
    q = robot.solve_ik(pose)
    if q is None:
        return False, f"line: {res.reason}; no IK solution"
    res = robot.move_joints(q)
    if res:
        return True, "joints"
    if not res.reason.startswith("collision"):
        return False, f"joints: {res.reason}"
    via = robot.move_joints(RETRACT_QPOS)
    if not via:
        return False, f"joints: {res.reason}; to retract: {via.reason}"
    res = robot.move_to(pose, speed=speed)
    if res:
        return True, "retract, line"
    res = robot.move_joints(q)
    return (True, "retract, joints") if res else (False, f"from retract: {res.reason}")


def collect_samples(
    robot: Robot,
    camera: Camera,
    board: BoardSpec,
    poses: Sequence[PlannedPose],
    speed: float = 0.1,
    flush_frames: int = 0,
    say: Say = quiet,
) -> tuple[list[Sample], list[dict[str, Any]]]:
    """Move to each pose, grab an image (after ``flush_frames`` older frames of a streaming
    camera), detect the board and estimate its pose.  A pose the robot cannot get to is tried
    again after the others.  Returns the usable samples and a log entry per pose (moved how,
    corners, or why it was skipped)."""
    samples: list[Sample] = []
    log: list[dict[str, Any]] = []
    intr = camera.intrinsics
    # a pose the robot could not get to is tried once more at the end, from another view
    order = list(range(len(poses)))
    tried: set[int] = set()
    for i in order:
        p = poses[i]
        ok, how = _move(robot, p.T_world_tcp, speed)
        if not ok and i not in tried:
            tried.add(i)
            order.append(i)
            say(f"pose {i + 1}/{len(poses)}: the robot could not get there ({how}); later again")
            continue
        entry: dict[str, Any] = {"index": i, "moved": ok, "motion": how}
        log.append(entry)
        if not ok:
            say(f"pose {i + 1}/{len(poses)}: skipped, the robot could not get there ({how})")
            continue
        for _ in range(flush_frames):
            camera.capture()
        image = camera.capture()
        T_tcp = robot.ee_pose().matrix()
        joints = robot.joint_positions
        det = detect_board(image.rgb, board)
        if det is None:
            entry["corners"] = 0
            say(f"pose {i + 1}/{len(poses)}: skipped, board not detected")
            continue
        T_cb, rms = board_pose(det, intr)
        entry.update(corners=len(det), reprojection_px=rms)
        samples.append(Sample(i, T_tcp, joints, det, T_cb, rms))
        say(f"pose {i + 1}/{len(poses)}: {len(det)} corners, PnP {rms:.3f} px ({how})")
    return samples, log


@dataclass
class Session:
    """What :func:`calibrate_devices` did: the plan (chosen poses, every candidate), the motion
    log, the samples and the result (None on a dry run)."""

    poses: list[PlannedPose]
    candidates: list[PlannedPose]
    log: list[dict[str, Any]] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)
    result: CalibrationResult | None = None


def calibrate_devices(
    robot: Robot,
    camera: Camera,
    board: BoardSpec,
    n: int,
    plan: PlanConfig,
    rng: np.random.Generator,
    T_world_base: np.ndarray | None = None,
    dry_run: bool = False,
    speed: float = 0.1,
    flush_frames: int = 0,
    return_home: bool = True,
    say: Say = quiet,
) -> Session:
    """Plan ``n`` reachable board poses, show each to the camera, calibrate (module docstring).

    ``dry_run``: plan and check the poses without moving.  ``return_home``: move back to the
    joint configuration the robot started in."""
    board.validate()
    if not speed > 0:
        raise ConfigError("speed", f"must be > 0 m/s, got {speed}")
    if flush_frames < 0:
        raise ConfigError("flush_frames", f"must be >= 0, got {flush_frames}")
    poses, candidates = plan_poses(robot, board, n, plan, rng, say)
    session = Session(poses, candidates)
    if dry_run:
        return session
    start = robot.joint_positions
    try:
        session.samples, session.log = collect_samples(
            robot, camera, board, poses, speed, flush_frames, say
        )
    finally:
        if return_home:
            res = move_joints_safely(robot, start)
            reached = [e["index"] for e in session.log if e["moved"]]
            if not res and reached:  # back through the first view reached, then home
                _move(robot, poses[reached[0]].T_world_tcp, speed)
                res = move_joints_safely(robot, start)
            if not res:
                say(f"could not return to the start configuration: {res.reason}")
    session.result = calibrate(session.samples, camera.intrinsics, board, T_world_base)
    session.result.meta.update(
        poses_planned=len(poses),
        poses_used=len(session.samples),
        plan=dataclasses.asdict(plan),
        motion_log=session.log,
    )
    return session
