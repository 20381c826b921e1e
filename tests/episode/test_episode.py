"""A full simulated interaction on a small scene (3 hoses, 160x120): the grasped hose follows the
gripper, the stream follows the frame contract, the target frame shows no robot, the same seed
gives the same frames, and the recording replays bit for bit."""

from __future__ import annotations

import time

import numpy as np
import pytest

from cablesim.camera.replay import ReplayCamera
from cablesim.frames import LABEL_ROBOT, Frame, Stream
from cablesim.perception.actions import subsample_by_gripper
from cablesim.recording import Recording, RecordingWriter
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.sim.session import SimSession, simulate_episode

SEED, HOSE, N_HOSES = 2, 1, 3


def small_config(**changes) -> EpisodeConfig:
    scene = SceneConfig(
        seed=SEED, hoses=HoseConfig(count=N_HOSES), camera=CameraConfig(width=160, height=120)
    )
    return EpisodeConfig(hose=HOSE, scene=scene, **changes)


def assert_identical(a: list[Frame], b: list[Frame]) -> None:
    assert len(a) == len(b)
    for i, (fa, fb) in enumerate(zip(a, b, strict=True)):
        assert np.array_equal(fa.rgb, fb.rgb), f"rgb of frame {i}"
        assert np.array_equal(fa.depth, fb.depth), f"depth of frame {i}"
        assert np.array_equal(fa.gripper, fb.gripper), f"gripper of frame {i}"
        assert (fa.action, fa.sample, fa.timestamp) == (fb.action, fb.sample, fb.timestamp)
        if fa.truth is not None and fb.truth is not None:
            assert np.array_equal(fa.truth.labels, fb.truth.labels), f"labels of frame {i}"
            if fa.truth.flow_to_target is not None and fb.truth.flow_to_target is not None:
                assert np.array_equal(fa.truth.flow_to_target, fb.truth.flow_to_target)
                assert np.array_equal(fa.truth.flow_valid, fb.truth.flow_valid)


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    path = tmp_path_factory.mktemp("episode") / "rec"
    t0 = time.perf_counter()
    ep = simulate_episode(small_config(), record_to=path)
    print(f"\nepisode wall time {time.perf_counter() - t0:.1f} s")
    print(ep.result.summary())
    yield ep, path
    ep.close()


def test_grasped_hose_follows_each_action(episode):
    ep, _ = episode
    res = ep.result
    assert res.success, res.reason
    assert res.hose == HOSE
    assert [a.label for a in res.actions] == ["along", "across"]
    for a in res.actions:
        others = {h: round(d * 1000, 1) for h, d in enumerate(a.hose_displacement) if h != HOSE}
        print(
            f"{a.label}: gain {a.gain:.3f} (R^2 {a.gain_r2:.3f}); other hoses moved (mm) {others}"
        )
        assert a.gain >= 0.9, f"{a.label}: gain {a.gain:.3f}"
        assert len(a.hose_displacement) == N_HOSES
    assert len(res.other_hose_displacement()) == N_HOSES - 1


def test_timings_split_wall_and_cpu_time(episode):
    ep, _ = episode
    t = ep.result.timings
    for kind in ("", "cpu_"):
        parts = [t[f"{kind}{k}"] for k in ("physics_control", "rendering", "ground_truth")]
        assert all(p > 0 for p in parts), t
        assert sum(parts) == pytest.approx(t[f"{kind}total"])
    assert "CPU time: total" in ep.result.summary()


def test_stream_contract(episode):
    ep, _ = episode
    s: Stream = ep.result.stream
    target = s.target
    assert target.truth is not None
    assert not (target.truth.labels == LABEL_ROBOT).any(), "robot pixels in the target frame"
    assert ep.result.target_robot_pixels == 0
    assert s.actions == [0, 1]
    assert sum(f.is_target for f in s) == 1
    period = 1.0 / 15.0
    for a in s.actions:
        frames = s.action_frames(a)
        assert [f.sample for f in frames] == list(range(len(frames)))
        assert len(frames) > 50  # 3 periods of +-2 cm with a 1 mm step
        assert subsample_by_gripper(frames, 0.001) == frames  # already subsampled
        steps = np.linalg.norm(np.diff([f.gripper for f in frames], axis=0), axis=1)
        assert steps.min() >= 0.001
        dt = np.diff([f.timestamp for f in frames])
        assert dt.min() >= period - 0.005  # triggered at 15 frames/s of simulated time
        every = small_config().interaction.capture.truth_every  # the default: every 8th
        assert every == 8
        for f in frames:
            if f.sample % every:  # an unlabelled frame: its images only
                assert f.truth is None
            else:
                assert f.truth is not None and f.truth.grasped_hose == HOSE
                assert f.truth.flow_to_target.shape == (*f.shape, 2)
                assert f.truth.flow_to_target.dtype == np.float32
                assert f.truth.flow_valid.shape == f.shape
            assert f.gripper_quat is not None and f.gripper_opening is not None
    # the gripper is in front of the camera, at the board's distance
    g = np.array([f.gripper for f in s if not f.is_target])
    assert np.all((g[:, 2] > 0.5) & (g[:, 2] < 1.5))
    assert target.timestamp > s.frames[-2].timestamp


def test_recording_replays_identically(episode):
    ep, path = episode
    rec = Recording(path)
    assert rec.complete
    assert_identical(ep.result.stream.frames, rec.to_stream().frames)
    cam = ReplayCamera(path)
    for f in ep.result.stream:
        img = cam.capture()
        assert np.array_equal(img.rgb, f.rgb) and np.array_equal(img.depth, f.depth)
    assert np.allclose(cam.T_world_camera, ep.session.world.T_world_camera)


@pytest.mark.slow
def test_same_seed_same_frames(episode):
    ep, _ = episode
    again = simulate_episode(small_config())
    try:
        assert again.result.success
        assert_identical(ep.result.stream.frames, again.result.stream.frames)
    finally:
        again.close()


def test_default_labels_every_eighth_frame_and_old_files_rerun_as_they_ran():
    """The interaction labels every 8th kept frame by default (issue 21); a config file
    written before (no ``truth_every``) labelled every frame and reruns so."""
    assert EpisodeConfig().interaction.capture.truth_every == 8
    assert EpisodeConfig.of(truth_every=1).interaction.capture.truth_every == 1
    doc = EpisodeConfig().to_dict()
    del doc["interaction"]["capture"]["truth_every"]
    assert EpisodeConfig.from_dict(doc).interaction.capture.truth_every == 1


def test_truth_every_labels_some_frames_with_the_same_images(episode):
    """The default ``capture.truth_every`` (8): the first kept frame of each action, every
    eighth after it and the target frame carry labels and ground-truth flow, equal to those
    of the run that labels every frame (``truth_every`` 1); the others carry none; every
    image (colour and depth) is the same, and the recording keeps that mix."""
    ep, path = episode
    sparse = ep.result.stream.frames
    full_ep = simulate_episode(small_config().with_values({"interaction.capture.truth_every": 1}))
    try:
        assert full_ep.result.success, full_ep.result.reason
        full = full_ep.result.stream.frames
        assert all(f.truth is not None for f in full)
        assert_identical(full, sparse)
        labelled = [f.is_target or f.sample % 8 == 0 for f in sparse]
        assert [f.truth is not None for f in sparse] == labelled
        assert 0 < sum(labelled) < len(sparse) / 4
        for fa, fb in zip(full, sparse, strict=True):
            if fb.truth is not None:
                assert np.array_equal(fa.truth.labels, fb.truth.labels)
                assert np.array_equal(fa.truth.flow_to_target, fb.truth.flow_to_target)
                assert np.array_equal(fa.truth.flow_valid, fb.truth.flow_valid)
        assert full_ep.result.target_robot_pixels == ep.result.target_robot_pixels
        replayed = Recording(path).to_stream().frames
        assert [f.truth is not None for f in replayed] == labelled
        assert_identical(sparse, replayed)
    finally:
        full_ep.close()


class Interrupt(RuntimeError):
    pass


class FailingWriter(RecordingWriter):
    """Raises (as a crash would) after ``n`` frames are on disk."""

    def __init__(self, path, n: int):
        super().__init__(path)
        self.n = n

    def add_frame(self, index: int, frame: Frame) -> None:
        if index == self.n:
            raise Interrupt(f"interrupted at frame {index}")
        super().add_frame(index, frame)


def test_interrupted_episode_keeps_frames_written(episode, tmp_path):
    ep, _ = episode
    session = SimSession.build(small_config())
    writer = FailingWriter(tmp_path / "rec", n=6)
    try:
        with pytest.raises(Interrupt), writer:
            session.interact(ep.segment.mask, sink=writer)
    finally:
        session.close()
    rec = Recording(tmp_path / "rec")
    assert not rec.complete and len(rec) == 6
    # the first frames of the same seed are the same as in the full episode (without flow)
    assert_identical(ep.result.stream.frames[:6], rec.to_stream().frames)
