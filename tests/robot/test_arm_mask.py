"""Arm masks from kinematics (cablesim.panda.arm_mask): they match the simulated camera's robot
labels, honour non-square and off-centre intrinsics, and travel with the frames of a stream
into recordings (old recordings without them still read)."""

from __future__ import annotations

import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.camera.base import CameraImage
from cablesim.episode.capture import FrameCollector
from cablesim.episode.clock import Tick
from cablesim.errors import InputError
from cablesim.frames import LABEL_ROBOT, Frame, Intrinsics, Stream
from cablesim.panda.arm_mask import ArmMasker, arm_mask, dilate
from cablesim.panda.description import HOME_QPOS
from cablesim.pose import Pose
from cablesim.recording import read_stream, write_stream
from cablesim.robot.grasping import move_joints_safely


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def _look_at(position, target) -> np.ndarray:
    """T_world_camera with OpenCV axes looking from ``position`` at ``target`` (z up)."""
    fwd = np.subtract(target, position, dtype=float)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    T = np.eye(4)
    T[:3, :3] = np.stack([right, np.cross(fwd, right), fwd], 1)
    T[:3, 3] = position
    return T


@pytest.fixture(scope="module")
def session():
    from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
    from cablesim.sim.session import SimSession

    scene = SceneConfig(
        seed=0, camera=CameraConfig(width=160, height=120), hoses=HoseConfig(count=1)
    )
    s = SimSession.build(EpisodeConfig(scene=scene))
    yield s
    s.close()


def test_kinematic_mask_matches_the_simulated_robot_labels(session):
    cam, robot = session.camera, session.robot
    base = Pose(*session.world.panda_base)
    with ArmMasker.for_robot(robot, cam) as masker:
        assert np.allclose(masker.T_world_base, base.matrix())
        parked = masker(robot.joint_positions, robot.gripper_opening)
        assert not parked.any()  # the park pose is out of view, in both
        assert not (cam.render_labels() == LABEL_ROBOT).any()
        down = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])  # hand along +x
        for p in ([0.25, 0.0, 0.5], [0.35, 0.05, 0.4]):
            q = robot.solve_ik(Pose.from_rotation(np.array(p), down))
            assert q is not None
            assert move_joints_safely(robot, q)
            labels = cam.render_labels() == LABEL_ROBOT
            mask = masker(robot.joint_positions, robot.gripper_opening)
            assert labels.sum() > 1000  # the arm fills a good part of the 160x120 image
            assert _iou(mask, labels) > 0.9, p
            wide = masker(robot.joint_positions, robot.gripper_opening, margin=3)
            assert (wide >= mask).all() and wide.sum() > mask.sum() + 100
            # a wrong joint state gives a visibly different mask
            other = masker(robot.joint_positions + np.array([0.2, 0, 0, 0, 0, 0, 0]), 0.08)
            assert _iou(other, labels) < 0.8


def test_non_square_and_off_centre_intrinsics():
    """A pinhole camera with fx != fy and an off-centre principal point sees the image of a
    square, centred camera at the same pose under the affine map between the two."""
    T = _look_at((1.3, 0.5, 0.8), (0.45, 0.0, 0.45))
    fine = Intrinsics(600.0, 600.0, 319.5, 239.5, 640, 480)
    odd = Intrinsics(230.0, 185.0, 71.3, 67.8, 160, 120)
    q = HOME_QPOS
    a = arm_mask(q, 0.08, fine, T)
    b = arm_mask(q, 0.08, odd, T)
    assert 500 < b.sum() < 0.6 * b.size
    # u_odd = fx_odd / fx_fine (u_fine - cx_fine) + cx_odd, likewise v
    import cv2

    sx, sy = odd.fx / fine.fx, odd.fy / fine.fy
    M = np.array([[sx, 0, odd.cx - sx * fine.cx], [0, sy, odd.cy - sy * fine.cy]])
    warped = cv2.warpAffine(a.astype(np.float32), M, (odd.width, odd.height)) > 0.5
    assert _iou(warped, b) > 0.97
    # the same camera with the principal point mirrored is a different image
    mirrored = Intrinsics(odd.fx, odd.fy, 159 - odd.cx, 119 - odd.cy, 160, 120)
    assert _iou(arm_mask(q, 0.08, mirrored, T), b) < 0.8


def test_masks_from_another_thread():
    """A real camera's ticks arrive on a capture thread: the masker renders there too (an EGL
    context current in the main thread cannot be made current in another)."""
    import threading

    K = Intrinsics(150.0, 150.0, 79.5, 59.5, 160, 120)
    T = _look_at((1.3, 0.5, 0.8), (0.45, 0.0, 0.45))
    with ArmMasker(K, T) as masker:
        here = masker(HOME_QPOS, 0.08)
        there: list = []
        t = threading.Thread(target=lambda: there.append(masker(HOME_QPOS, 0.08)))
        t.start()
        t.join()
        assert len(there) == 1 and here.any() and np.array_equal(here, there[0])
    with pytest.raises(InputError, match="closed"):
        masker(HOME_QPOS, 0.08)


def test_bad_input_is_named():
    K = Intrinsics(100.0, 100.0, 31.5, 23.5, 64, 48)
    T = _look_at((1.3, 0.5, 0.8), (0.45, 0.0, 0.45))
    with pytest.raises(InputError, match="T_world_camera"):
        ArmMasker(K, np.eye(3))
    with pytest.raises(InputError, match="margin"):
        ArmMasker(K, T, margin=-1)
    with ArmMasker(K, T) as masker:
        with pytest.raises(InputError, match="joints"):
            masker(np.zeros(6), 0.08)
    with pytest.raises(InputError, match="margin"):
        dilate(np.zeros((4, 4), bool), -2)
    with pytest.raises(InputError, match="no arm model"):
        ArmMasker.for_robot(object(), None)


def test_frames_carry_the_mask_into_recordings(tmp_path):
    K = Intrinsics(100.0, 100.0, 31.5, 23.5, 64, 48)
    T = _look_at((1.3, 0.5, 0.8), (0.45, 0.0, 0.45))
    rgb = np.zeros((48, 64, 3), np.uint8)
    depth = np.ones((48, 64), np.float32)
    with ArmMasker(K, T, margin=1) as masker:
        collector = FrameCollector(T, min_gripper_step=0.0, arm_mask=masker.for_tick)
        collector.begin_action(0)
        ticks = []
        for i, j1 in enumerate((0.0, 0.3)):
            q = HOME_QPOS + np.array([j1, 0, 0, 0, 0, 0, 0])
            tick = Tick(
                0.1 * i,
                Pose(np.array([0.5, 0.0, 0.4]), np.array([1.0, 0, 0, 0])),
                0.04,
                q,
                frame=CameraImage(rgb, depth, 0.1 * i, K),
            )
            ticks.append(tick)
            collector.on_tick(tick)
        collector.end_action()
        collector.capture_target(lambda: CameraImage(rgb, depth, 1.0, K), ticks[0])
        frames = collector.frames
        assert len(frames) == 3
        for f, t in zip(frames, (*ticks, ticks[0]), strict=True):
            assert f.arm_mask is not None and f.arm_mask.any()
            assert np.array_equal(f.arm_mask, masker(t.joints, t.opening))
        assert not np.array_equal(frames[0].arm_mask, frames[1].arm_mask)
    write_stream(Stream(frames), tmp_path / "rec")
    back = read_stream(tmp_path / "rec")
    for a, b in zip(frames, back, strict=True):
        assert b.arm_mask is not None and np.array_equal(a.arm_mask, b.arm_mask)
    # frames without a mask (every recording written before masks existed) read back as None
    plain = [Frame(f.rgb, f.depth, K, f.gripper, f.action, f.sample) for f in frames]
    write_stream(Stream(plain), tmp_path / "old")
    assert all(f.arm_mask is None for f in read_stream(tmp_path / "old"))
    with pytest.raises(InputError, match="arm_mask"):
        Frame(rgb, depth, K, np.zeros(3), arm_mask=np.zeros((4, 4), bool))
