"""FrankyPanda (franky-control) against the franka-sim server on 127.0.0.1.

franka-sim 1.1.7 needs mujoco 3.2 and numpy 1.26, which clash with this project's mujoco 4.0,
so the server runs as a subprocess from its own environment: the Python named by
``$CABLESIM_FRANKA_SIM_PYTHON``, else ``.cache/franka-sim-venv/bin/python`` in the repository
(see README "Real robot"), else this interpreter if it can import franka_sim; it is started by
:class:`cablesim.twin.franka_sim.FrankaSimServer`, as the digital twin starts it.  The server is
bound to 127.0.0.1 only (its command line binds all interfaces, so it is started from Python),
on libfranka's fixed ports 1337 (arm) and 1338 (gripper); the tests skip when those are taken.
Only loopback is ever contacted.  The server model is :func:`franka_sim_mjcf` (our Panda), with
``enforce_motion_limits`` on so that it raises reflexes like the robot does.
"""

from __future__ import annotations

import gc
import math
import re
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np
import pytest

from cablesim.panda import HOME_QPOS, JOINT_LIMITS
from cablesim.panda.ik import ArmModel
from cablesim.panda.model import panda_spec
from cablesim.robot.base import MoveResult
from cablesim.robot.franky_panda import FLANGE_T_TCP, FrankyPanda, franka_sim_mjcf
from cablesim.twin.franka_sim import HOST, FrankaSimServer, FrankaSimUnavailable

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
def franka_sim_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A franka-sim server on 127.0.0.1:1337/1338 serving our Panda (every motion limit and
    reflex enforced; see ``FrankaSimServer`` for the one loosened check); yields its log."""
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
        assert server.log is not None
        yield server.log
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
def robot(franka_sim_server: Path) -> Iterator[FrankyPanda]:
    panda = FrankyPanda(
        HOST,
        T_WORLD_CAMERA,
        T_WORLD_BASE,
        dynamics_factor=0.2,
        realtime=False,  # no realtime kernel here; the real robot keeps the default
        position_tolerance=0.01,  # the simulator's Cartesian tracking lags a few mm
        rotation_tolerance=0.05,
        joint_tolerance=0.02,
        motion_timeout=15.0,
    )
    yield panda
    panda.close()
    gc.collect()


def _host_missed_cycles(reason: str) -> bool:
    """Whether a reflex came with libfranka reporting that this host missed >= 5 % of the
    1 kHz command cycles (``control_command_success_rate`` below 0.95).  libfranka documents
    that as the host's timing (no realtime kernel here, a shared CI machine), not the motion:
    the server extrapolates the missed cycles and the late commands then jump."""
    match = re.search(r"control_command_success_rate: ([0-9.]+)", reason)
    return match is not None and float(match.group(1)) < 0.95 and reason.endswith("; recovered")


def _home(robot: FrankyPanda, speed: float = 0.5) -> MoveResult:
    """Home; once more if the first try was aborted only because this host missed cycles."""
    result = robot.home(speed)
    if not result and _host_missed_cycles(result.reason):
        result = robot.home(speed)
    return result


@pytest.fixture
def at_home(robot: FrankyPanda) -> FrankyPanda:
    result = _home(robot)
    assert result, result.reason
    return robot


def test_state_matches_our_kinematics(at_home: FrankyPanda) -> None:
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


def test_cartesian_move_reaches_the_pose(at_home: FrankyPanda) -> None:
    robot = at_home
    start = robot.ee_pose()
    target = start.translated([0.05, 0.03, -0.05])
    result = robot.move_to(target, speed=0.1)
    assert result, result.reason
    assert robot.ee_pose().distance_to(target)[0] < 0.01
    assert result.duration > 0.0


def test_relative_moves_in_tcp_world_and_camera_frames(at_home: FrankyPanda) -> None:
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
        np.testing.assert_allclose(moved, expected, atol=0.01, err_msg=frame)


def test_joint_move(at_home: FrankyPanda) -> None:
    robot = at_home
    q = HOME_QPOS + np.array([0.2, -0.1, 0.1, 0.15, 0.0, -0.1, 0.3])
    result = robot.move_joints(q, speed_factor=0.3)
    assert result, result.reason
    np.testing.assert_allclose(robot.joint_positions, q, atol=0.02)


def test_gripper_open_and_grasp(robot: FrankyPanda) -> None:
    assert robot.open(0.08)
    assert robot.gripper_opening == pytest.approx(0.08, abs=0.003)
    # The server holds a virtual 2 cm object between the fingers.
    assert robot.grasp(width=OBJECT_WIDTH, force=40.0, speed=0.1)
    assert robot.gripper_opening == pytest.approx(OBJECT_WIDTH, abs=0.003)
    assert robot.open(0.08)
    assert not robot.grasp(width=0.05, force=40.0, speed=0.1, epsilon_inner=0.005)
    assert robot.open(0.08)


def test_unreachable_target_is_refused_without_moving(at_home: FrankyPanda) -> None:
    robot = at_home
    q0 = robot.joint_positions
    far = robot.ee_pose().translated(robot.T_world_base[:3, 0] * 0.8)
    ok, reason = robot.check_reachable(far)
    assert not ok and reason
    assert robot.solve_ik(far) is None
    result = robot.move_to(far, speed=0.1)
    assert not result and result.reason.startswith("unreachable")
    # the simulated arm still settles by up to ~0.01 rad after homing; a motion towards
    # the refused target would move it by far more
    np.testing.assert_allclose(robot.joint_positions, q0, atol=0.03)


def test_colliding_joint_target_is_refused(at_home: FrankyPanda) -> None:
    robot = at_home
    q0 = robot.joint_positions
    folded = np.array([0.0, 1.5, 0.0, -3.0, 0.0, 1.5, 0.785])  # hand into the base
    result = robot.move_joints(folded)
    assert not result and "collision" in result.reason
    # the simulated arm still settles by up to ~0.01 rad after homing; a motion towards
    # the refused target would move it by far more
    np.testing.assert_allclose(robot.joint_positions, q0, atol=0.03)


def test_reflex_is_reported_and_recovered(at_home: FrankyPanda) -> None:
    """Unchecked, an out-of-reach target makes the robot abort with a reflex; the adapter
    recovers, and the robot moves again."""
    robot = at_home
    far = robot.ee_pose().translated(robot.T_world_base[:3, 0] * 0.6)
    result = robot.move_to(far, speed=0.2, check=False)
    assert not result
    assert "reflex" in result.reason and result.reason.endswith("; recovered"), result.reason
    assert not robot.robot.has_errors
    home = _home(robot)
    assert home, home.reason
    start = robot.ee_pose()
    again = robot.move_to(start.translated([0.0, 0.0, 0.03]), speed=0.1)
    assert again, again.reason


def test_ik_solution_is_consistent(at_home: FrankyPanda) -> None:
    robot = at_home
    target = robot.ee_pose().translated([0.03, 0.0, -0.04])
    q = robot.solve_ik(target)
    assert q is not None
    dist, angle = robot.arm.fk(q).distance_to(target)
    assert dist < 1e-3 and angle < 1e-2
    ok, reason = robot.check_reachable(target)
    assert ok, reason


def test_host_timing_retry_is_narrow() -> None:
    """The one retry above is for cycles this host missed, never for a motion that broke a
    limit on its own or for a reflex the adapter could not recover from."""
    timing = (
        "robot aborted the motion: ControlException: libfranka: Move command aborted: motion "
        'aborted by reflex! ["joint_velocity_violation"]\\ncontrol_command_success_rate: 0.85'
    )
    assert _host_missed_cycles(timing + "; recovered")
    assert not _host_missed_cycles(timing.replace("0.85", "0.99") + "; recovered")
    assert not _host_missed_cycles(timing + "; recovery FAILED")
    assert not _host_missed_cycles("joint target not reached (error 0.100 rad)")
