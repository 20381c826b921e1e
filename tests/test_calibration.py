"""Eye-to-hand calibration (cablesim.calibration, ``cablesim calibrate``): the simulated Panda
shows a rendered ChArUco board to the simulated camera and the camera pose is recovered within
5 mm and 0.5 degrees; the hand-eye solver on exact and noisy synthetic views; calibration files
that are missing or corrupt raise the project's own error naming the file and the field."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.calibration import (
    BoardSpec,
    PlanConfig,
    Sample,
    calibrate,
    detect_board,
    draw_board_poses,
    load_calibration,
    park_martin,
    pose_difference,
    write_calibration,
)
from cablesim.cli import main
from cablesim.errors import CalibrationError, ConfigError
from cablesim.frames import Intrinsics
from cablesim.seeding import stream

K = Intrinsics(640.0, 600.0, 318.0, 242.0, 640, 480)


def _rot(v) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(v, float).reshape(3, 1))[0]


def _T(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _truth_camera(seed: int) -> np.ndarray:
    """The simulated camera's pose for ``seed`` (as the world builds it)."""
    from cablesim.sim.config import SceneConfig
    from cablesim.sim.layout import sample_camera
    from cablesim.sim.world import look_at_frame

    cam = sample_camera(SceneConfig(seed=seed))
    return _T(look_at_frame(cam.position, cam.look_at), cam.position)


@pytest.mark.slow
def test_simulated_calibration_recovers_the_camera_pose(tmp_path, capsys):
    out = tmp_path / "calib.json"
    argv = ["calibrate", "--out", str(out), "--width", "640", "--height", "480"]
    argv += ["--poses", "10", "--seed", "0", "--quiet"]
    assert main(argv) == 0
    assert "against the simulated camera" in capsys.readouterr().out
    cal = load_calibration(out)
    truth = _truth_camera(0)
    dt, dr = pose_difference(cal.T_world_camera, truth)
    assert dt < 0.005 and math.degrees(dr) < 0.5, (dt, math.degrees(dr))
    # the file: what the real-robot session reads, and the residuals
    doc = json.loads(out.read_text())
    assert doc["kind"] == "eye-to-hand" and doc["date"]
    assert doc["sim_truth"]["position_error_mm"] == pytest.approx(1000 * dt)
    assert cal.intrinsics == Intrinsics(*[cal.intrinsics.f] * 2, 319.5, 239.5, 640, 480)
    assert cal.board == BoardSpec()
    base = np.asarray(doc["T_world_base"])
    assert np.allclose(base[:3, 3], [0.22, -0.62, 0.0])  # RobotConfig.base_position
    assert np.allclose(cal.T_base_camera, np.linalg.inv(base) @ cal.T_world_camera)
    assert 5 <= doc["poses_used"] == len(doc["poses"]) <= 10
    r = doc["residuals"]
    assert r["reprojection_px"]["max"] < 0.5 and r["model_reprojection_px"]["mean"] < 0.3
    assert r["handeye_translation_mm"]["mean"] < 2.0 and r["handeye_rotation_deg"]["max"] < 1.0
    for p in doc["poses"]:
        assert p["corners"] >= 8 and len(p["joints"]) == 7
        assert np.asarray(p["T_world_tcp"]).shape == (4, 4)
    # rotation diversity: the views span a good range of board orientations
    Rs = [np.asarray(p["T_world_tcp"])[:3, :3] for p in doc["poses"]]
    spread = max(math.degrees(pose_difference(_T(a, 0), _T(b, 0))[1]) for a in Rs for b in Rs)
    assert spread > 30


@pytest.mark.slow
def test_dry_run_plans_without_moving(tmp_path, capsys):
    out = tmp_path / "calib.json"
    argv = ["calibrate", "--out", str(out), "--width", "320", "--height", "240"]
    argv += ["--poses", "6", "--candidates", "30", "--dry-run", "--quiet"]
    assert main(argv) == 0
    assert "6 reachable poses planned; nothing moved" in capsys.readouterr().out
    assert not out.exists()


def test_command_line_errors_name_the_option(tmp_path, capsys):
    out = str(tmp_path / "c.json")
    assert main(["calibrate", "--robot", "franky", "--camera", "realsense", "--out", out]) == 2
    assert "--robot-host" in capsys.readouterr().err
    assert main(["calibrate", "--robot", "sim", "--camera", "realsense", "--out", out]) == 2
    assert "--camera" in capsys.readouterr().err
    bad = tmp_path / "board.json"
    bad.write_text(json.dumps({"squares_x": 2}))
    assert main(["calibrate", "--board", str(bad), "--out", out, "--dry-run"]) == 2
    assert "board.squares_x" in capsys.readouterr().err


def _synthetic(n: int, noise: float, seed: int = 1):
    """Views of the default board by a camera at X with the board at Y on the TCP."""
    rng = np.random.default_rng(seed)
    board = BoardSpec()
    X = _T(_rot([0.3, -1.9, 0.4]), [-0.4, 0.05, 0.6])  # camera in the world
    Y = board.T_tcp_board() @ _T(_rot([0.01, -0.02, 0.015]), [0.002, -0.003, 0.004])
    plan = PlanConfig(centre=tuple(X[:3, 3] + 0.6 * X[:3, 2]), look_from=tuple(X[:3, 3]))
    obj = board.cv_board().getChessboardCorners()
    samples = []
    for i, p in enumerate(draw_board_poses(board, plan, n, rng)):
        B = p.T_world_tcp
        C = np.linalg.inv(X) @ B @ Y
        cam = obj @ C[:3, :3].T + C[:3, 3]
        pix = K.project(cam) + rng.normal(0, noise, (len(obj), 2))
        from cablesim.calibration import BoardDetection, board_pose

        det = BoardDetection(np.arange(len(obj)), pix, obj.astype(float), 17)
        T_cb, rms = board_pose(det, K)
        samples.append(Sample(i, B, np.zeros(7), det, T_cb, rms))
    return X, Y, samples, board


def test_hand_eye_solver_exact_and_noisy():
    X, Y, samples, board = _synthetic(8, noise=0.0)
    Xs, Ys = park_martin([s.T_world_tcp for s in samples], [s.T_camera_board for s in samples])
    for est, true in ((Xs, X), (Ys, Y)):
        dt, dr = pose_difference(est, true)
        assert dt < 1e-6 and dr < 1e-6
    X, Y, samples, board = _synthetic(12, noise=0.3)
    res = calibrate(samples, K, board)
    dt, dr = pose_difference(res.T_world_camera, X)
    assert dt < 0.002 and math.degrees(dr) < 0.2
    closed, _ = park_martin([s.T_world_tcp for s in samples], [s.T_camera_board for s in samples])
    assert pose_difference(closed, X)[0] > dt  # the joint refinement is better than closed form
    assert 0.2 < res.residuals["model_reprojection_px"]["mean"] < 0.6
    with pytest.raises(CalibrationError, match="at least 5"):
        calibrate(samples[:4], K, board)


@pytest.mark.skipif(
    not hasattr(__import__("cv2"), "calibrateHandEye"),
    reason="this OpenCV's Python bindings lack calibrateHandEye (opencv/opencv#29565)",
)
def test_opencv_hand_eye_agrees_with_park_martin():
    """Where OpenCV has calibrateHandEye, the closed form uses it (fed the inverse TCP poses):
    it agrees with the NumPy Park-Martin (checked with OpenCV 4.14: 1e-16 m, 4e-8 rad)."""
    from cablesim.calibration import solve_eye_to_hand

    X, Y, samples, board = _synthetic(12, noise=0.3)
    Bs, Cs = [s.T_world_tcp for s in samples], [s.T_camera_board for s in samples]
    Xc, Yc, method = solve_eye_to_hand(Bs, Cs)
    assert method.startswith("cv2.calibrateHandEye")
    Xn, Yn = park_martin(Bs, Cs)
    for a, b in ((Xc, Xn), (Yc, Yn)):
        dt, dr = pose_difference(a, b)
        assert dt < 1e-6 and dr < 1e-5


def test_calibration_file_round_trip_and_errors(tmp_path):
    X, Y, samples, board = _synthetic(6, noise=0.1)
    base = _T(_rot([0, 0, 0.5]), [0.1, -0.2, 0.0])
    path = write_calibration(calibrate(samples, K, board, T_world_base=base), tmp_path / "c.json")
    cal = load_calibration(path)
    assert np.allclose(cal.T_world_base, base) and cal.intrinsics == K and cal.board == board
    assert pose_difference(cal.T_world_camera, X)[0] < 0.005
    cal.check_intrinsics(K)
    with pytest.raises(CalibrationError, match="c.json: intrinsics are for 640x480"):
        cal.check_intrinsics(K.scaled(0.5))

    doc = json.loads(path.read_text())

    def broken(name: str, change) -> str:
        d = json.loads(json.dumps(doc))
        change(d)
        p = tmp_path / name
        p.write_text(json.dumps(d))
        return str(p)

    cases = {
        broken("no_camera.json", lambda d: d.pop("T_world_camera")): "T_world_camera: missing",
        broken("skew.json", lambda d: d["T_world_camera"][0].__setitem__(0, 3.0)): (
            "T_world_camera: .*not a rotation"
        ),
        broken("short.json", lambda d: d.__setitem__("T_world_base", [[1, 0], [0, 1]])): (
            "T_world_base: .*4x4"
        ),
        broken("fx.json", lambda d: d["intrinsics"].__setitem__("fx", -1)): "intrinsics: .*fx",
        broken("noK.json", lambda d: d.pop("intrinsics")): "intrinsics: missing",
        broken("fmt.json", lambda d: d.__setitem__("format", "x")): "format: not a",
        broken("ver.json", lambda d: d.__setitem__("version", 9)): "version: unknown",
        broken("board.json", lambda d: d["board"].__setitem__("dictionary", "X")): (
            "board: board.dictionary"
        ),
        broken("base.json", lambda d: d["T_base_camera"][0].__setitem__(3, 5.0)): (
            "T_base_camera: disagrees"
        ),
    }
    for p, message in cases.items():
        with pytest.raises(CalibrationError, match=message) as e:
            load_calibration(p)
        assert p in str(e.value)
    (tmp_path / "trunc.json").write_text(path.read_text()[:200])
    with pytest.raises(CalibrationError, match=r"trunc\.json: not valid JSON"):
        load_calibration(tmp_path / "trunc.json")
    with pytest.raises(CalibrationError, match=r"absent\.json: no such calibration file"):
        load_calibration(tmp_path / "absent.json")


def test_board_spec_and_detection():
    board = BoardSpec()
    assert BoardSpec.from_dict(board.to_dict()) == board
    with pytest.raises(ConfigError, match="board.marker_length"):
        BoardSpec(marker_length=0.04).validate()
    with pytest.raises(ConfigError, match="board.dictionary"):
        BoardSpec(squares_x=20, squares_y=20, dictionary="DICT_4X4_50").validate()
    with pytest.raises(ConfigError, match="board"):
        BoardSpec.from_dict({"colour": "red"})
    # the board's own image: every inner corner found where the board geometry puts it
    img = board.image(px_per_m=3000)
    det = detect_board(img, board)
    assert det is not None and len(det) == (board.squares_x - 1) * (board.squares_y - 1)
    expected = (det.object_points[:, :2] + board.margin) * 3000 - 0.5
    assert np.abs(det.image_points - expected).max() < 0.5
    assert detect_board(np.full((100, 100), 255, np.uint8), board) is None
    # the mount: the board's face looks along the TCP's approach axis, ahead of the TCP
    T = board.T_tcp_board()
    assert np.allclose(T[:3, 2], [0, 0, -1])
    centre = T[:3, :3] @ board.centre() + T[:3, 3]
    assert np.allclose(centre, [0, 0, board.mount_offset])


def test_calibration_module_needs_no_simulator():
    code = (
        "import sys, cablesim.calibration; "
        "bad = [m for m in sys.modules if m == 'mujoco' or m.startswith('cablesim.sim')]; "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_planned_poses_face_the_camera():
    board = BoardSpec()
    plan = PlanConfig(centre=(0.1, 0.0, 0.5), look_from=(-0.4, 0.0, 0.6), max_tilt_deg=20)
    poses = draw_board_poses(board, plan, 50, stream(3, "calibration"))
    again = draw_board_poses(board, plan, 50, stream(3, "calibration"))
    assert all(
        np.array_equal(a.T_world_tcp, b.T_world_tcp) for a, b in zip(poses, again, strict=True)
    )
    for p in poses:
        c = p.T_world_board[:3, :3] @ board.centre() + p.T_world_board[:3, 3]
        assert np.abs(c - plan.centre).max() <= plan.spread + 1e-9
        to_camera = np.asarray(plan.look_from) - c
        to_camera /= np.linalg.norm(to_camera)
        # the printed face (board -z) is turned towards the camera by less than the tilts allow
        cos = float(-p.T_world_board[:3, 2] @ to_camera)
        assert cos > math.cos(math.radians(20 * math.sqrt(2) + 1))
        assert np.allclose(p.T_world_tcp @ board.T_tcp_board(), p.T_world_board)
    with pytest.raises(ConfigError, match="plan.max_tilt_deg"):
        PlanConfig(centre=(0, 0, 0), look_from=(1, 0, 0), max_tilt_deg=80).validate()
