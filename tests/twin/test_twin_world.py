"""The digital twin's world without a robot server: a replayed joint/gripper log drives it."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.panda.ik import ArmModel
from cablesim.pose import Pose
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.twin.world import ReplaySource, TwinWorld

CONFIG = EpisodeConfig(
    scene=SceneConfig(seed=0, hoses=HoseConfig(count=3), camera=CameraConfig(160, 120))
)
#: a wrist turn and a small turn of the base joint, away from the board (park is out of view)
DELTA = np.array([0.15, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5])


@pytest.fixture(scope="module")
def twin():
    with TwinWorld(CONFIG, fps=15) as t:
        yield t


def test_frames_and_poses_are_those_of_the_scene(twin: TwinWorld) -> None:
    w = twin.world
    np.testing.assert_allclose(twin.T_world_camera, w.T_world_camera)
    pos, quat = w.panda_base
    np.testing.assert_allclose(twin.T_world_base, Pose(pos, quat).matrix())
    assert twin.park == tuple(w.cfg.robot.park_qpos)
    np.testing.assert_allclose(twin.state().q, twin.park, atol=1e-6)
    assert (twin.intrinsics.width, twin.intrinsics.height) == (160, 120)
    assert twin.obstacles and any("board" in o.name for o in twin.obstacles)


def test_calls_run_on_the_twin_thread_and_raise_there(twin: TwinWorld) -> None:
    labels = twin.call(lambda t: t.camera.render_labels())
    assert labels.shape == (120, 160)

    def broken(_t: TwinWorld) -> None:
        raise ValueError("from the twin thread")

    with pytest.raises(ValueError, match="from the twin thread"):
        twin.call(broken)


def test_it_refuses_to_follow_a_robot_elsewhere(twin: TwinWorld) -> None:
    twin.source = None
    with pytest.raises(InputError, match="attach a robot source"):
        twin.follow()
    far = ReplaySource([(0.0, np.asarray(twin.park) + 0.2)])
    twin.attach(far)
    with pytest.raises(InputError, match="rad from the twin's arm"):
        twin.follow()


def test_it_replays_the_robot_and_renders_stamped_frames(twin: TwinWorld) -> None:
    park = np.asarray(twin.park)
    target = park + DELTA
    source = ReplaySource(
        [(0.0, park), (0.3, park), (1.3, target)],
        gripper=[(0.0, 0.08, False), (0.5, 0.04, False)],
    )
    frames = []
    twin.outputs.append(frames.append)
    twin.attach(source)
    source.start()
    twin.follow()
    try:
        state = twin.wait_state(lambda s: s.twin_time > source.t0 + 1.6, timeout=60.0)
        state, ok = twin.synced(timeout=30.0)
        assert ok, f"the twin did not catch up (lag {state.lag:.2f} s)"
    finally:
        twin.pause()
        twin.outputs.remove(frames.append)
    np.testing.assert_allclose(state.q_target, target, atol=1e-9)
    np.testing.assert_allclose(state.q, target, atol=0.003)
    assert state.opening == pytest.approx(0.04, abs=0.002)
    assert state.gripper_measured == (0.04, False)
    # the twin's TCP is where our arm model puts it for the replayed joints at the twin's base
    pos, quat = twin.world.panda_base
    tcp = ArmModel(pos, quat).fk(target).position
    np.testing.assert_allclose(state.tcp, tcp, atol=0.003)
    # frames: on the twin's frame clock from ~0, on its 1/15 s grid (a loaded machine drops
    # some, never shifts them: each shows the state at its stamp), findable by their stamp
    assert len(frames) >= 10
    stamps = np.array([f.stamp for f in frames])
    assert stamps[0] < 0.1
    periods = np.diff(stamps) * 15
    assert np.all(periods > 0.9) and np.all(np.abs(periods - np.rint(periods)) < 0.07)
    assert all(f.wall >= f.twin_time - 0.005 for f in frames)  # never ahead of the clock
    last = frames[-1]
    assert twin.frame_at(last.stamp) is last
    assert twin.frame_at(last.stamp + 0.5) is None
    assert last.rgb.shape == (120, 160, 3) and last.depth.shape == (120, 160)
    assert last.snapshot.labels.shape == (120, 160)
    summary = twin.stats.summary()
    assert summary["frames"] == twin.stats.frames >= len(frames)
    assert summary["tracking_mm_median"] < 5.0
