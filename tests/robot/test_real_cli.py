"""``cablesim explore --robot franky ... --dry-run`` end to end against the franka-sim server:
the real session opens (calibration file, RealSense camera from a recording of a simulated
scene, FrankyPanda with the safety guard), the first interaction is planned and checked motion
by motion, the plan is written, and the robot does not move."""

from __future__ import annotations

import dataclasses
import gc
import json
import math

import cv2
import numpy as np
import pytest

from cablesim.calibration import FORMAT, VERSION
from cablesim.cli import main
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.sim.session import SimSession
from cablesim.twin.franka_sim import HOST

pytest.importorskip("franky", reason="franky-control is not installed (the 'real' extra)")
pytest.importorskip("pyrealsense2", reason="pyrealsense2 is not installed (the 'real' extra)")

CFG = EpisodeConfig(
    hose=1,
    scene=SceneConfig(
        seed=2, hoses=HoseConfig(count=3), camera=CameraConfig(width=320, height=240)
    ),
)


@pytest.fixture(scope="module")
def server():
    from cablesim.twin import FrankaSimServer
    from cablesim.twin.franka_sim import FrankaSimUnavailable

    try:
        with FrankaSimServer(object_width=0.015, enforce_motion_limits=False) as s:
            yield s
    except FrankaSimUnavailable as e:
        pytest.skip(str(e))


def _joints(T_world_camera: np.ndarray, T_world_base: np.ndarray) -> np.ndarray:
    from cablesim.robot.franky_panda import FrankyPanda

    robot = FrankyPanda(HOST, T_world_camera, T_world_base, realtime=False)
    q = robot.joint_positions
    robot.close()
    del robot
    gc.collect()
    return q


@pytest.mark.slow
def test_dry_run_plans_without_moving(server, tmp_path):
    from cablesim.camera.realsense import write_recording

    session = SimSession.build(CFG)
    try:
        picked = session.pick_start()
        image = session.capture()
        T_world_camera, T_world_base = session.T_world_camera, session.T_world_base
        K = image.intrinsics
    finally:
        session.close()
    frames = [dataclasses.replace(image, timestamp=image.timestamp + i / 15) for i in range(6)]
    write_recording(tmp_path / "scene.db3", frames)
    cv2.imwrite(str(tmp_path / "start.png"), picked.mask.astype(np.uint8) * 255)
    (tmp_path / "calib.json").write_text(
        json.dumps(
            {
                "format": FORMAT,
                "version": VERSION,
                "T_world_camera": T_world_camera.tolist(),
                "T_world_base": T_world_base.tolist(),
                "intrinsics": K.to_dict(),
            }
        )
    )
    before = _joints(T_world_camera, T_world_base)
    out = tmp_path / "plan"
    argv = ["explore", "--robot", "franky", "--robot-host", HOST, "--no-realtime"]
    argv += ["--camera", f"realsense:{tmp_path / 'scene.db3'}"]
    argv += ["--calibration", str(tmp_path / "calib.json"), "--start", str(tmp_path / "start.png")]
    argv += ["--periods", "1", "--dry-run", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    plan = json.loads((out / "plan.json").read_text())
    assert plan["feasible"], plan["reason"]
    kinds = [m["kind"] for m in plan["motions"]]
    assert kinds.count("move_to") >= 2 + 2 * 4 and "grasp" in kinds and "move_joints" in kinds
    assert all(m["ok"] for m in plan["motions"])
    assert (out / "plan.png").stat().st_size > 0
    # the planned grasp is where the start segment is, in the world of the calibration
    grasp = np.asarray(plan["grasp_world"])
    cam = np.linalg.inv(T_world_camera) @ np.append(grasp, 1.0)
    uv = K.project(cam[None, :3])[0]
    v, u = np.nonzero(picked.mask)
    assert math.dist(uv, (u.mean(), v.mean())) < 10
    after = _joints(T_world_camera, T_world_base)
    np.testing.assert_allclose(after, before, atol=0.01)  # nothing moved


def test_missing_calibration_is_refused_before_connecting(tmp_path):
    argv = ["explore", "--robot", "franky", "--robot-host", HOST, "--out", str(tmp_path)]
    assert main([*argv, "--start-point", "10,10"]) == 2  # no --calibration
    argv += ["--calibration", str(tmp_path / "nope.json"), "--start-point", "10,10"]
    assert main(argv) == 2
