"""The digital twin's parts on their own, without its thread: the replay of measurements onto
the Panda's actuators, the sample tracks, the sampler threads' error path, the published state
and the kept frames."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from cablesim.sim.config import CameraConfig, HoseConfig, SceneConfig
from cablesim.sim.world import World
from cablesim.twin.replay import KV_OVER_KP, Replay
from cablesim.twin.sampling import Samplers, Track
from cablesim.twin.sources import ReplaySource
from cablesim.twin.state import FrameHistory, StateBoard, TwinFrame


@pytest.fixture(scope="module")
def world() -> World:
    return World.build(SceneConfig(hoses=HoseConfig(count=1), camera=CameraConfig(64, 48)))


def _replay(world: World, **kw) -> tuple[Replay, Track, Track]:
    joints, gripper = Track(), Track()
    n = world.panda
    assert n is not None
    options = dict(
        extrapolate=0.05,
        hose_diameter=0.015,
        gripper_speed=(0.05, 0.1),
        settle_time=0.1,
        finger_rest_speed=0.002,
        q=np.zeros(7),
        opening=0.08,
    )
    options.update(kw)
    return Replay(world, joints, gripper, **options), joints, gripper


def _arm_ctrl(world: World) -> np.ndarray:
    m = world.model
    return np.array([world.data.ctrl[m.actuator(a).id] for a in world.panda.actuators])


def _gripper_ctrl(world: World) -> float:
    return float(world.data.ctrl[world.model.actuator(world.panda.gripper_actuator).id])


def test_joints_are_interpolated_and_extrapolated_a_little(world: World) -> None:
    replay, joints, _ = _replay(world)
    # the positions advance as the measured velocities say (the robot's clock is the wall's)
    q0, q1 = np.full(7, 0.1), np.full(7, 1.6)
    dq0, dq1 = np.full(7, 1.0), np.full(7, 2.0)
    # no sample yet: the arm is held where it is
    replay.command(5.0)
    np.testing.assert_array_equal(_arm_ctrl(world), np.zeros(7))
    assert replay.joint_at == -math.inf
    joints.add(10.0, (q0, dq0))
    joints.add(11.0, (q1, dq1))
    # before the first sample: that sample, standing still
    q, dq = replay.joint_target(9.0)
    np.testing.assert_array_equal(q, q0)
    np.testing.assert_array_equal(dq, np.zeros(7))
    replay.command(10.25)
    np.testing.assert_allclose(replay.q_target, q0 + 0.25 * (q1 - q0))
    np.testing.assert_allclose(_arm_ctrl(world), replay.q_target + KV_OVER_KP * 1.25)
    assert replay.joint_at == 10.0
    # past the newest sample: its velocity for at most ``extrapolate`` s
    q, dq = replay.joint_target(13.0)
    np.testing.assert_allclose(q, q1 + dq1 * 0.05)
    np.testing.assert_array_equal(dq, dq1)
    assert replay.joint_at == 11.0


def test_velocities_are_replayed_at_the_rate_the_robots_clock_ran(world: World) -> None:
    """Against a lockstep simulator on a busy host the robot's time runs slower than the wall
    clock: its measured velocities (per second of its time) are scaled to the wall time the
    replay runs in, for the feed-forward and the extrapolation."""
    dq = np.linspace(0.1, 0.4, 7)
    for rate in (0.5, 1.0):
        replay, joints, _ = _replay(world)
        times = 20.0 + 0.004 * np.arange(20)
        for t in times:  # the arm moves at ``rate`` times its measured velocity
            joints.add(float(t), (0.3 + rate * dq * (t - times[0]), dq))
        q_last = 0.3 + rate * dq * (times[-1] - times[0])
        q, v = replay.joint_target(float(times[-1]) + 0.01)
        assert replay.rate == pytest.approx(rate)
        np.testing.assert_allclose(v, rate * dq)
        np.testing.assert_allclose(q, q_last + rate * dq * 0.01)
        replay.command(float(times[-1]) + 0.01)
        np.testing.assert_allclose(_arm_ctrl(world), q + KV_OVER_KP * rate * dq)
    # an arm at rest says nothing about the clock: the rate is 1
    replay, joints, _ = _replay(world)
    for t in (1.0, 1.004, 1.008, 1.03, 1.034):
        joints.add(t, (np.full(7, 0.2), np.zeros(7)))
    replay.joint_target(1.04)
    assert replay.rate == 1.0


def test_the_gripper_follows_the_opening_at_the_hands_speed_and_squeezes_a_grasp(
    world: World,
) -> None:
    replay, _, gripper = _replay(world)
    start = _gripper_ctrl(world)
    assert replay.gripper_ctrl == start
    gripper.add(1.0, (0.04, False))
    # nothing measured yet: the opening the twin started with
    assert replay.gripper_target(0.5) == pytest.approx(0.08)
    replay.command(1.0)
    assert replay.gripper_ctrl == pytest.approx(0.04)
    assert not replay.fingers_settled
    assert replay.gripper_in_effect == (0.04, False, 1.0)
    # the command moves towards the goal by the closing speed times a physics step
    step = 0.05 * float(world.model.opt.timestep)
    assert _gripper_ctrl(world) == pytest.approx(max(0.04, start - step))
    # a grasp no wider than the hose: close on it; a wider one: the measured opening
    gripper.add(2.0, (0.015, True))
    assert replay.gripper_target(2.0) == 0.0
    gripper.add(3.0, (0.05, True))
    assert replay.gripper_target(3.0) == pytest.approx(0.05)
    gripper.add(4.0, (0.5, False))
    assert replay.gripper_target(4.0) == pytest.approx(0.08)  # never wider than the hand
    gripper.add(5.0, (math.nan, False))  # an unknown opening keeps the goal
    replay.gripper_ctrl = 0.03
    assert replay.gripper_target(5.0) == 0.03


def test_tracks_find_samples_around_a_time_and_forget_old_ones() -> None:
    track = Track()
    assert track.newest_time() == -math.inf
    assert track.around(1.0) == (None, None)
    for t in (1.0, 2.0, 3.0):
        track.add(t, f"v{t}")
    assert track.around(2.5) == ((2.0, "v2.0"), (3.0, "v3.0"))
    assert track.around(0.5) == (None, (1.0, "v1.0"))
    assert track.around(3.0) == ((3.0, "v3.0"), None)
    track.forget_before(2.5)  # keeps the newest sample at or before 2.5
    assert track.times == [2.0, 3.0]
    assert track.newest_time() == 3.0


def test_a_failing_read_is_handed_on_and_ends_the_samplers() -> None:
    class Broken(ReplaySource):
        def gripper_state(self) -> tuple[float, bool]:
            raise OSError("gripper gone")

    errors: list[BaseException] = []
    failed = threading.Event()

    def on_error(e: BaseException) -> None:
        errors.append(e)
        failed.set()

    samplers = Samplers(0.004, threading.Event(), on_error)
    samplers.start(Broken([(0.0, np.zeros(7))]))
    assert failed.wait(30.0)
    samplers.stop()
    assert len(errors) == 1 and isinstance(errors[0], OSError)
    assert samplers.gripper.newest_time() == -math.inf  # nothing kept of the failed read


def test_the_state_board_hands_out_the_latest_and_waits_for_a_condition() -> None:
    board = StateBoard("first")  # type: ignore[arg-type]
    board.publish("second")  # type: ignore[arg-type]
    assert board.latest() == "second"
    assert board.wait(lambda s: s == "second", 10.0, give_up=lambda: False) == "second"
    # a condition that never holds: given up at once, the latest state returned
    assert board.wait(lambda s: False, 10.0, give_up=lambda: True) == "second"


def test_frames_are_kept_for_their_history_and_found_by_stamp() -> None:
    def frame(i: int, wall: float) -> TwinFrame:
        return TwinFrame(i, stamp=0.1 * i, twin_time=wall, wall=wall, snapshot=None, state=None)  # type: ignore[arg-type]

    history = FrameHistory(seconds=1.0)
    assert history.latest() is None
    frames = [frame(i, 100.0 + 0.4 * i) for i in range(5)]
    for f in frames:
        history.add(f)
    assert history.latest() is frames[-1]
    assert history.at(0.4) is frames[4] and history.at(0.3) is frames[3]
    assert history.at(0.1) is None  # rendered more than 1 s before the newest: forgotten
    assert history.at(0.3004) is frames[3] and history.at(0.301) is None
