"""FrankyPanda (franky-control) against the franka-sim server on 127.0.0.1.

franka-sim 1.1.7 needs mujoco 3.2 and numpy 1.26, which clash with this project's mujoco 4.0,
so the server runs as a subprocess from its own environment: the Python named by
``$CABLESIM_FRANKA_SIM_PYTHON``, else ``.cache/franka-sim-venv/bin/python`` in the repository
(see README "Real robot"), else this interpreter if it can import franka_sim; it is started by
:class:`cablesim.twin.franka_sim.FrankaSimServer`, as the digital twin starts it.  The server is
bound to 127.0.0.1 only (its command line binds all interfaces, so it is started from Python),
on libfranka's fixed ports 1337 (arm) and 1338 (gripper); the tests skip when those are taken.
Only loopback is ever contacted.  The server model is :func:`franka_sim_mjcf` (our Panda), with
``enforce_motion_limits`` on so that it raises reflexes like the robot does, on the lockstep
clock (a cycle ends when the client answered it), so that this host's late scheduling of the
control thread cannot abort a motion (``test_franka_sim_clock.py``).
"""

from __future__ import annotations

import gc
import math
import os
import threading
import time
from collections.abc import Iterator

import mujoco
import numpy as np
import pytest
from host_timing import LIMIT, RetryingPanda, is_host_timing

from cablesim.panda import HOME_QPOS, JOINT_LIMITS
from cablesim.panda.ik import ArmModel
from cablesim.panda.model import panda_spec
from cablesim.robot.base import MoveResult
from cablesim.robot.franky_panda import FLANGE_T_TCP, FrankyPanda
from cablesim.twin.franka_sim import (
    HOST,
    CycleViolation,
    FrankaSimServer,
    FrankaSimUnavailable,
    parse_cycle_violations,
)
from cablesim.twin.franka_sim_model import franka_sim_mjcf

OBJECT_WIDTH = 0.02  # m: the server's virtual object between the fingers
SERVER_LIFETIME = 300.0  # s: the server exits on its own after this, whatever happens here


def test_franka_sim_model_has_our_kinematics() -> None:
    """The server model's link7 frame is the flange: link7 * FLANGE_T_TCP is our TCP."""
    model = mujoco.MjModel.from_xml_string(franka_sim_mjcf())
    data = mujoco.MjData(model)
    arm = ArmModel()
    rng = np.random.default_rng(1)
    link7 = model.body("link7").id
    for _ in range(10):
        q = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        data.qpos[:7] = q
        mujoco.mj_kinematics(model, data)
        T = np.eye(4)
        T[:3, :3] = data.xmat[link7].reshape(3, 3)
        T[:3, 3] = data.xpos[link7]
        np.testing.assert_allclose(T @ FLANGE_T_TCP, arm.fk(q).matrix(), atol=1e-6)
    names = {model.geom(g).name for g in range(model.ngeom)}
    assert {f"link{n}_collision" for n in range(8)} <= names
    assert model.nq == 7


def test_flange_t_tcp_is_the_hand_tcp() -> None:
    """FLANGE_T_TCP is the grasp site seen from the flange (link7 + 107 mm) in our model."""
    model = panda_spec().compile()
    data = mujoco.MjData(model)
    data.qpos[:7] = HOME_QPOS
    mujoco.mj_kinematics(model, data)
    b, s = model.body("link7").id, model.site("grasp_site").id
    T_link7 = np.eye(4)
    T_link7[:3, :3] = data.xmat[b].reshape(3, 3)
    T_link7[:3, 3] = data.xpos[b]
    T_flange = T_link7.copy()
    T_flange[:3, 3] += T_link7[:3, 2] * 0.107
    T_site = np.eye(4)
    T_site[:3, :3] = data.site_xmat[s].reshape(3, 3)
    T_site[:3, 3] = data.site_xpos[s]
    np.testing.assert_allclose(T_flange @ FLANGE_T_TCP, T_site, atol=1e-6)


# ---- the franka-sim server -------------------------------------------------------------------
@pytest.fixture(scope="module")
def franka_sim_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FrankaSimServer]:
    """A franka-sim server on 127.0.0.1:1337/1338 serving our Panda (every motion limit and
    reflex enforced; see ``FrankaSimServer`` for the one loosened check)."""
    pytest.importorskip("franky", reason="franky-control is not installed (the 'real' extra)")
    server = FrankaSimServer(
        object_width=OBJECT_WIDTH,
        enforce_motion_limits=True,
        lifetime=SERVER_LIFETIME,
        workdir=tmp_path_factory.mktemp("franka_sim"),
    )
    try:
        server.start()
    except FrankaSimUnavailable as e:
        pytest.skip(str(e))
    try:
        # in lockstep a late client loses no cycle (test_franka_sim_clock.py)
        assert server.running_clock() == "lockstep", server.log_text()[-2000:]
        yield server
    finally:
        server.stop()


def _yaw(angle: float, translation: tuple[float, float, float]) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(angle), math.sin(angle)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = translation
    return T


#: A base that is neither at the world origin nor aligned with it.
T_WORLD_BASE = _yaw(0.5, (0.3, -0.2, 0.05))
T_WORLD_CAMERA = _yaw(0.0, (1.2, 0.0, 0.6)) @ np.array(
    [[0, 0, -1, 0], [1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float
)  # looking along -x of the world, OpenCV axes


@pytest.fixture(scope="module")
def robot(franka_sim_server: FrankaSimServer) -> Iterator[RetryingPanda]:
    """The adapter, its motions retried (bounded, counted) when this host's missed control
    cycles abort them (``host_timing.py``); ``robot.raw`` is the adapter itself."""
    panda = FrankyPanda(
        HOST,
        T_WORLD_CAMERA,
        T_WORLD_BASE,
        dynamics_factor=0.2,
        realtime=False,  # no realtime kernel here; the real robot keeps the default
        position_tolerance=0.003,
        rotation_tolerance=0.05,
        joint_tolerance=0.005,
        motion_timeout=15.0,
        settle_time=10.0,  # the simulated arm runs slower than real time on a loaded host
    )
    yield RetryingPanda(panda, franka_sim_server)
    panda.close()
    gc.collect()


@pytest.fixture
def at_home(robot: RetryingPanda) -> RetryingPanda:
    result = robot.home(0.5)
    assert result, result.reason
    return robot


def test_state_matches_our_kinematics(at_home: RetryingPanda) -> None:
    robot = at_home
    q = robot.joint_positions
    assert q.shape == (7,)
    np.testing.assert_allclose(q, HOME_QPOS, atol=0.02)
    pose = robot.ee_pose()
    fk = robot.arm.fk(q)  # arm model placed at T_world_base
    dist, angle = pose.distance_to(fk)
    assert dist < 1e-3 and angle < 1e-2
    base_local = robot.to_base(pose)
    assert 0.4 < base_local.position[0] < 0.7  # HOME: TCP about 0.55 m in front of the base
    cam = robot.ee_pose_camera()
    np.testing.assert_allclose(robot.camera_to_world(cam).position, pose.position, atol=1e-3)
    assert robot.gripper_opening == pytest.approx(0.08, abs=0.005)


def test_cartesian_move_reaches_the_pose(at_home: RetryingPanda) -> None:
    robot = at_home
    start = robot.ee_pose()
    target = start.translated([0.05, 0.03, -0.05])
    result = robot.move_to(target, speed=0.1)
    assert result, result.reason
    assert robot.ee_pose().distance_to(target)[0] < 0.003
    assert result.duration > 0.0


def test_relative_moves_in_tcp_world_and_camera_frames(at_home: RetryingPanda) -> None:
    robot = at_home
    for frame, delta in (
        ("tcp", np.array([0.0, 0.0, 0.04])),  # along the approach axis (down at home)
        ("world", np.array([0.0, -0.03, 0.0])),
        ("camera", np.array([0.02, 0.0, 0.0])),  # camera x is world +y here
    ):
        start = robot.ee_pose()
        if frame == "tcp":
            expected = start.rotation @ delta
        elif frame == "camera":
            expected = T_WORLD_CAMERA[:3, :3] @ delta
        else:
            expected = delta
        result = robot.move_relative(delta, frame=frame, speed=0.1)
        assert result, f"{frame}: {result.reason}"
        moved = robot.ee_pose().position - start.position
        np.testing.assert_allclose(moved, expected, atol=0.003, err_msg=frame)


def test_joint_move(at_home: RetryingPanda) -> None:
    robot = at_home
    q = HOME_QPOS + np.array([0.2, -0.1, 0.1, 0.15, 0.0, -0.1, 0.3])
    result = robot.move_joints(q, speed_factor=0.3)
    assert result, result.reason
    np.testing.assert_allclose(robot.joint_positions, q, atol=0.005)


def test_gripper_open_and_grasp(robot: RetryingPanda) -> None:
    assert robot.open(0.08)
    assert robot.gripper_opening == pytest.approx(0.08, abs=0.003)
    # The server holds a virtual 2 cm object between the fingers.
    assert robot.grasp(width=OBJECT_WIDTH, force=40.0, speed=0.1)
    assert robot.gripper_opening == pytest.approx(OBJECT_WIDTH, abs=0.003)
    assert robot.open(0.08)
    assert not robot.grasp(width=0.05, force=40.0, speed=0.1, epsilon_inner=0.005)
    assert robot.open(0.08)


def test_unreachable_target_is_refused_without_moving(at_home: RetryingPanda) -> None:
    robot = at_home
    q0 = robot.joint_positions
    far = robot.ee_pose().translated(robot.T_world_base[:3, 0] * 0.8)
    ok, reason = robot.check_reachable(far)
    assert not ok and reason
    assert robot.solve_ik(far) is None
    result = robot.move_to(far, speed=0.1)
    assert not result and result.reason.startswith("unreachable")
    np.testing.assert_allclose(robot.joint_positions, q0, atol=0.002)  # nothing moved


def test_colliding_joint_target_is_refused(at_home: RetryingPanda) -> None:
    robot = at_home
    q0 = robot.joint_positions
    folded = np.array([0.0, 1.5, 0.0, -3.0, 0.0, 1.5, 0.785])  # hand into the base
    result = robot.move_joints(folded)
    assert not result and "collision" in result.reason
    np.testing.assert_allclose(robot.joint_positions, q0, atol=0.002)  # nothing moved


def test_reflex_is_reported_and_recovered(
    at_home: RetryingPanda, franka_sim_server: FrankaSimServer
) -> None:
    """Unchecked, an out-of-reach target makes the robot abort with a reflex; the adapter
    recovers, and the robot moves again.  The provoked motion itself is never retried, and the
    server's cycle monitor logged the reflex the client reports."""
    robot = at_home
    seen = len(franka_sim_server.cycle_violations())
    far = robot.ee_pose().translated(robot.T_world_base[:3, 0] * 0.6)
    result = robot.raw.move_to(far, speed=0.2, check=False)
    assert not result
    assert "reflex" in result.reason and result.reason.endswith("; recovered"), result.reason
    assert not robot.robot.has_errors
    deadline = time.monotonic() + 2.0
    while len(franka_sim_server.cycle_violations()) == seen and time.monotonic() < deadline:
        time.sleep(0.05)
    logged = franka_sim_server.cycle_violations()[seen:]
    assert logged and any(v.violation in result.reason for v in logged), (result.reason, logged)
    home = robot.home(0.5)
    assert home, home.reason
    start = robot.ee_pose()
    again = robot.move_to(start.translated([0.0, 0.0, 0.03]), speed=0.1)
    assert again, again.reason


def test_a_motion_starts_only_from_rest(
    at_home: RetryingPanda, franka_sim_server: FrankaSimServer
) -> None:
    """While the arm still moves (a slow motion started behind the adapter's back), a motion
    is refused with the named failure and nothing is sent; once it rests, motions run."""
    robot, raw = at_home, at_home.raw
    fr = raw._franky
    q = np.asarray(HOME_QPOS) + np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    timeout, raw.rest_timeout = raw.rest_timeout, 0.3
    try:
        for _ in range(LIMIT + 1):
            seen = len(franka_sim_server.cycle_violations())
            slow = fr.JointMotion(
                q, fr.ReferenceType.Absolute, fr.RelativeDynamicsFactor(0.1, 0.2, 0.2)
            )
            raw.robot.move(slow, asynchronous=True)
            # under way: joint 1 has left home (a fixed 0.3 s sleep was not enough on a loaded
            # host, where the lockstep robot's clock runs slow: the arm had not started, and
            # the motion that should be refused ran; CI clone run beside tests/robot)
            deadline = time.monotonic() + 10.0
            while abs(raw.joint_positions[0] - HOME_QPOS[0]) < 0.01:
                assert time.monotonic() < deadline, "the slow motion did not start in 10 s"
                time.sleep(0.01)
            refused = raw.move_joints(np.asarray(HOME_QPOS), speed_factor=0.3)
            q_refused = raw.joint_positions
            try:
                if "reflex" not in refused.reason:
                    raw.robot.join_motion(15.0)
            except fr.ControlException:  # aborted after the refusal: what it showed stands
                raw.recover()
            if "reflex" not in refused.reason:
                break
            # the slow motion was aborted by a reflex before the refusal: it has to be the
            # host's timing, and the test starts over
            raw.recover()
            violations = franka_sim_server.cycle_violations()[seen:]
            assert is_host_timing(refused, violations), (refused.reason, violations)
            assert robot.home(0.5)
    finally:
        raw.rest_timeout = timeout
    assert not refused and refused.reason.startswith("arm not at rest"), refused.reason
    assert raw.wait_for_rest() == ""
    # the refused motion (to HOME, 0.3 rad back in joint 1) never ran: joint 1 went on or
    # stopped, it never turned back
    assert raw.joint_positions[0] >= q_refused[0] - 0.01, (raw.joint_positions, q_refused)
    back = robot.home(0.5)
    assert back, back.reason


def test_the_calling_thread_keeps_its_scheduling(at_home: RetryingPanda) -> None:
    """libfranka raises the thread that connects to its realtime policy; the adapter gives the
    caller's policy back and lends libfranka's only to the control thread it starts."""
    robot = at_home
    caller = os.sched_getscheduler(0)
    assert (caller, os.sched_getparam(0)) == robot.raw._scheduling.caller
    control_policy = robot.raw._scheduling.control[0]
    main = threading.get_native_id()
    seen: dict[str, set[int]] = {"main": set(), "others": set()}
    moving = threading.Event()

    def watch() -> None:  # the policies of this process's threads while the motion runs
        while not moving.is_set():
            time.sleep(0.02)
            for tid in (int(t) for t in os.listdir("/proc/self/task")):
                try:
                    policy = os.sched_getscheduler(tid)
                except OSError:  # the thread ended meanwhile
                    continue
                seen["main" if tid == main else "others"].add(policy)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        q = np.asarray(HOME_QPOS) + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3])
        result = robot.move_joints(q, speed_factor=0.2)
    finally:
        moving.set()
        watcher.join()
    assert result, result.reason
    assert seen["main"] == {caller}  # the calling thread kept its policy throughout
    assert control_policy in seen["others"]  # the control thread ran with libfranka's


def test_ik_solution_is_consistent(at_home: RetryingPanda) -> None:
    robot = at_home
    target = robot.ee_pose().translated([0.03, 0.0, -0.04])
    q = robot.solve_ik(target)
    assert q is not None
    dist, angle = robot.arm.fk(q).distance_to(target)
    assert dist < 1e-3 and angle < 1e-2
    ok, reason = robot.check_reachable(target)
    assert ok, reason


def _violation(name: str, lost: int = 0, span_ms: float = 3.0) -> CycleViolation:
    return CycleViolation(name, True, lost, span_ms, 3, 0.0)


def test_host_timing_is_a_discontinuity_after_lost_cycles_or_a_stall() -> None:
    """The rule the retry rests on (``CycleViolation.host_timing``)."""
    jump = "joint_motion_generator_velocity_discontinuity"
    assert _violation(jump, lost=1).host_timing
    assert _violation(jump, lost=0, span_ms=12.0).host_timing  # the server stalled
    assert not _violation(jump, lost=0, span_ms=3.0).host_timing  # in time: the motion's own
    assert not _violation("joint_position_limits_violation", lost=2).host_timing
    assert not _violation("cartesian_reflex", lost=2).host_timing


def test_retry_only_for_a_recovered_reflex_that_is_all_host_timing() -> None:
    reflex = (
        "robot aborted the motion: ControlException: libfranka: Move command aborted: motion "
        'aborted by reflex! ["joint_motion_generator_velocity_discontinuity"]\n'
        "control_command_success_rate: 0.96"
    )
    timing = [_violation("joint_motion_generator_velocity_discontinuity", lost=1)]
    genuine = [_violation("joint_motion_generator_velocity_discontinuity", lost=0)]
    assert is_host_timing(MoveResult(False, reflex + "; recovered"), timing)
    assert not is_host_timing(MoveResult(False, reflex + "; recovery FAILED"), timing)
    assert not is_host_timing(MoveResult(False, reflex + "; recovered"), genuine)
    assert not is_host_timing(MoveResult(False, reflex + "; recovered"), timing + genuine)
    assert not is_host_timing(MoveResult(False, reflex + "; recovered"), [])  # no evidence
    assert not is_host_timing(MoveResult(False, "joint target not reached (error 0.1 rad)"), timing)
    assert not is_host_timing(MoveResult(True, ""), timing)


def test_cycle_monitor_records_parse() -> None:
    log = (
        "2026-12-01 20:30:22,661 WARNING franka_sim.motion_limits: motion limit violated\n"
        '2026-12-01 20:30:22,661 INFO cablesim.cycles: cablesim-cycles: {"violation": '
        '"cartesian_motion_generator_velocity_discontinuity", "enforced": true, '
        '"lost_cycles": 2, "span_ms": 4.5, "cycles": 3, "time": 12.5}\n'
    )
    (v,) = parse_cycle_violations(log)
    assert v == CycleViolation(
        "cartesian_motion_generator_velocity_discontinuity", True, 2, 4.5, 3, 12.5
    )
    assert v.host_timing
