"""Interaction and episode configs (round trip, validation); the simulated clock's frame
timing and hooks; action directions and waypoints."""

from __future__ import annotations

import contextlib
import json

import numpy as np
import pytest

from cablesim.episode.clock import Tick
from cablesim.episode.primitives import action_direction, periodic_waypoints
from cablesim.errors import ConfigError
from cablesim.pose import Pose
from cablesim.sim.clock import SimClock
from cablesim.sim.config import EpisodeConfig


def test_config_round_trip_and_print():
    cfg = EpisodeConfig.of(seed=4, hose=1).with_values(
        {
            "interaction.actions.extra_directions": ((0.0, 0.0, 1.0),),
            "interaction.retreat.qpos": (-1.9, -0.6, 0.0, -2.3, 0.0, 1.7, 0.78),
            "perturb.enabled": True,
        }
    )
    again = EpisodeConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg
    assert '"seed": 4' in str(cfg) and str(cfg).count('"seed"') == 1
    assert cfg.seed == cfg.scene.seed == 4


@pytest.mark.parametrize(
    "change, field",
    [
        ({"hose": 9}, "hose"),
        ({"seed": -1}, "scene.seed"),
    ],
)
def test_config_rejects(change, field):
    with pytest.raises(ConfigError, match=field):
        EpisodeConfig.of(**change)


@pytest.mark.parametrize(
    "path, value, field",
    [
        ("interaction.kind", "pull", "interaction.kind"),
        ("interaction.actions.directions", ("sideways",), "interaction.actions.directions"),
        ("interaction.actions.periods", 0, "interaction.actions.periods"),
    ],
)
def test_config_rejects_nested(path, value, field):
    with pytest.raises(ConfigError) as err:
        EpisodeConfig().with_values({path: value})
    assert err.value.field == field


class FakeWorld:
    """Just enough world for the clock: time, a step and its hooks."""

    class model:  # noqa: N801 - mimics MjModel.opt.timestep
        class opt:  # noqa: N801
            timestep = 0.004

    def __init__(self) -> None:
        self.t = 0.0
        self.steps = 0
        self.before_step: list = []
        self.after_step: list = []

    @property
    def time(self) -> float:
        return self.t

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            for h in tuple(self.before_step):
                h(self)
            self.steps += 1
            self.t = self.steps * 0.004
            for h in tuple(self.after_step):
                h(self)

    @contextlib.contextmanager
    def hooks(self, before=(), after=()):
        self.before_step.extend(before)
        self.after_step.extend(after)
        try:
            yield self
        finally:
            for h in before:
                self.before_step.remove(h)
            for h in after:
                self.after_step.remove(h)


class FakeRobot:
    joint_positions = np.zeros(7)
    gripper_opening = 0.08

    def __init__(self, world: FakeWorld) -> None:
        self.world = world

    def ee_pose(self) -> Pose:
        return Pose(np.array([self.world.t, 0.0, 0.0]))


class CountingHook:
    def __init__(self) -> None:
        self.started = self.stopped = self.steps = 0

    def start(self, world) -> None:
        self.started += 1

    def before_step(self, world) -> None:
        self.steps += 1

    def stop(self, world) -> None:
        self.stopped += 1


def test_sim_clock_ticks_at_the_frame_rate_of_simulated_time():
    w = FakeWorld()
    w.step(10)
    hook = CountingHook()
    clock = SimClock(w, FakeRobot(w), grab=lambda: None, rate=15.0, action_hooks=[hook])
    ticks: list[Tick] = []
    with clock.streaming(ticks.append):
        w.step(750)  # 3 s
        w.step(1)
    w.step(100)  # no hooks any more
    assert not w.before_step and not w.after_step
    assert (hook.started, hook.stopped, hook.steps) == (1, 1, 751)
    times = [t.time for t in ticks]
    assert len(times) == 1 + 45
    dt = np.diff(times)
    assert np.all(np.abs(dt - 1 / 15) <= 0.004 + 1e-9)
    # ticks stay locked to t0 + i/15 (no drift)
    assert abs(times[-1] - times[0] - 45 / 15) <= 0.0021
    # the gripper pose is read at the tick's own physics step: no skew
    assert all(t.skew == 0.0 and t.gripper.position[0] == t.time for t in ticks)


def test_sim_clock_rejects_a_bad_rate():
    w = FakeWorld()
    with pytest.raises(ConfigError, match="frame_rate"):
        SimClock(w, FakeRobot(w), grab=lambda: None, rate=0.0)


def test_action_directions_and_waypoints():
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # looks along +x
    axis = np.array([0.3, 0.2, -0.9])  # a hose leaning towards the board
    along = action_direction("along", axis, T)
    across = action_direction("across", axis, T)
    assert abs(along[0]) < 1e-9  # image plane of this camera is the board plane (y, z)
    assert abs(np.dot(along, across)) < 1e-9 and abs(across[0]) < 1e-9
    g1 = Pose(np.array([0.5, 0.0, 0.5]))
    way = periodic_waypoints(g1, along, 0.02, 3)
    assert len(way) == 12
    d = np.array([w.position - g1.position for w in way]) @ along
    assert np.allclose(d, [0.02, 0, -0.02, 0] * 3)


class FlakyGripperRobot:
    """A robot whose gripper reads fail ``fail`` times in a row once ``after`` reads went
    well (``fail`` None: for good)."""

    joint_positions = np.zeros(7)

    def __init__(self, after: int, fail: int | None) -> None:
        self.after, self.fail, self.reads = after, fail, 0

    def ee_pose(self) -> Pose:
        return Pose(np.zeros(3))

    @property
    def gripper_opening(self) -> float:
        self.reads += 1
        bad = self.reads > self.after and (
            self.fail is None or self.reads <= self.after + self.fail
        )
        if bad:
            raise RuntimeError("Net Exception")
        return 0.04


class PacedCamera:
    """A camera whose capture blocks 5 ms, as a stream's next frame does."""

    def capture(self):
        import time

        from cablesim.camera.base import CameraImage
        from cablesim.frames import Intrinsics

        time.sleep(0.005)
        return CameraImage(
            np.zeros((4, 4, 3), np.uint8),
            np.ones((4, 4), np.float32),
            time.monotonic(),
            Intrinsics(4.0, 4.0, 2.0, 2.0, 4, 4),
        )


def test_stream_clock_rides_out_failed_gripper_reads_and_stops_on_a_lasting_failure():
    """A few failed reads of the gripper's opening (a starved gripper server) keep the last
    opening and are counted; reads failing for longer than ``opening_patience`` end the block
    with the robot's own error."""
    import time

    from cablesim.episode.clock import StreamClock

    robot = FlakyGripperRobot(after=3, fail=5)
    clock = StreamClock(robot, PacedCamera(), pose_rate=200.0)
    ticks: list[Tick] = []
    with clock.streaming(ticks.append):
        time.sleep(0.3)
    assert robot.reads > 10 and clock.stats.opening_read_failures == 5
    assert ticks and all(t.opening == 0.04 for t in ticks)
    assert clock.stats.summary()["opening_read_failures"] == 5

    clock = StreamClock(FlakyGripperRobot(after=3, fail=None), PacedCamera(), opening_patience=0.1)
    with pytest.raises(RuntimeError, match="Net Exception"):  # noqa: PT012
        with clock.streaming(ticks.append):
            time.sleep(2.0)
