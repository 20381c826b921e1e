"""Eye-to-hand calibration of a fixed camera with a ChArUco board held by the gripper: the robot
shows the board at N seeded, reachable poses in front of the camera, the board's corners are
detected in each image, and the camera pose in the robot's world frame is solved (closed-form
hand-eye, then a joint refinement of every corner's reprojection).  The same code drives the
simulated Panda (a board welded to its hand, rendered camera) and the real one (franky-control,
a RealSense).

  cablesim calibrate --out calib.json                           # simulation, 12 poses
  cablesim calibrate --robot franky --robot-host 172.16.0.2 --camera realsense \\
      --centre 0.45 0 0.45 --look-from -0.4 0 0.6 --out calib.json --dry-run

--centre (where the board is shown) and --look-from (a rough camera position, within ~10 cm)
are in the robot's world frame (its base frame unless --base is given) and are only used to
plan the poses; in simulation they default to a point 0.55 m in front of the simulated camera
and the camera's position.  The arm-only reachability check does not know the board: keep the
board's poses clear of obstacles (--spread, --max-tilt).

Writes --out (JSON: T_world_camera, T_world_base, T_base_camera, intrinsics, board, per-pose
residuals, mean/max reprojection error and hand-eye residuals, date; read it with
cablesim.calibration.load_calibration).  In simulation the file also records the error against
the true camera pose.  --board-image writes the printable board (print at 100 %).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.calibration import (
    BoardSpec,
    PlanConfig,
    calibrate_devices,
    pose_difference,
    write_calibration,
)
from cablesim.camera.realsense import RealSenseCamera
from cablesim.errors import CalibrationError, ConfigError, InputError
from cablesim.panda.ik import Obstacle
from cablesim.pose import Pose
from cablesim.progress import Progress, quiet
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.seeding import stream
from cablesim.sim.config import (
    CameraConfig,
    EpisodeConfig,
    HoseConfig,
    RobotConfig,
    SceneConfig,
)
from cablesim.sim.session import SimSession


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", default="sim", help="sim (default) or franky")
    p.add_argument("--robot-host", default=None, help="the robot's FCI address (franky)")
    p.add_argument("--camera", default="sim", help="sim (default), realsense or realsense:SERIAL")
    p.add_argument("--poses", type=int, default=12, help="board poses to show (default 12)")
    p.add_argument("--out", type=Path, required=True, help="calibration file to write (JSON)")
    p.add_argument("--seed", type=int, default=0, help="seed of the pose draw and the sim scene")
    p.add_argument("--dry-run", action="store_true", help="plan and check the poses, no motion")
    p.add_argument("--width", type=int, default=1280, help="image width (default 1280)")
    p.add_argument("--height", type=int, default=720, help="image height (default 720)")
    p.add_argument("--centre", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"))
    p.add_argument("--look-from", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"))
    p.add_argument("--spread", type=float, default=0.08, help="m around --centre (0.08)")
    p.add_argument("--max-tilt", type=float, default=30.0, help="degrees (default 30)")
    p.add_argument("--max-roll", type=float, default=60.0, help="degrees (default 60)")
    p.add_argument("--candidates", type=int, default=120, help="poses drawn (default 120)")
    p.add_argument("--board", type=Path, default=None, help="BoardSpec JSON (default 7x5)")
    p.add_argument("--board-image", type=Path, default=None, help="write the printable board")
    p.add_argument(
        "--base",
        type=float,
        nargs=4,
        default=None,
        metavar=("X", "Y", "Z", "YAW"),
        help="the real robot's base in the world (m, rad); default: world = base",
    )
    p.add_argument("--speed", type=float, default=0.1, help="TCP speed, m/s (default 0.1)")
    p.add_argument(
        "--flush-frames", type=int, default=None, help="frames dropped before each image"
    )
    p.add_argument("--no-realtime", action="store_true", help="franky: no realtime kernel")
    p.add_argument(
        "--table-z",
        type=float,
        default=0.0,
        help="franky: height of the table top in the world (m, default 0), an obstacle of the "
        "reachability check",
    )
    p.add_argument("--no-table", action="store_true", help="franky: no table obstacle")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def _board(args: argparse.Namespace) -> BoardSpec:
    if args.board is None:
        return BoardSpec().validate()
    try:
        doc = json.loads(Path(args.board).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"--board {args.board}: unreadable ({e})") from e
    if not isinstance(doc, dict):
        raise InputError(f"--board {args.board}: expected a JSON object of BoardSpec fields")
    return BoardSpec.from_dict(doc)


def write_board_image(board: BoardSpec, path: Path, dpi: float = 300.0) -> Path:
    """The board as a printable PNG at ``dpi`` with a title line under it."""
    px_per_m = dpi / 0.0254
    img = board.image(px_per_m)
    w, h = board.plate_size
    title = (
        f"cablesim ChArUco {board.squares_x}x{board.squares_y}, squares "
        f"{board.square_length * 1000:.1f} mm, markers {board.marker_length * 1000:.1f} mm, "
        f"{board.dictionary}; print at 100 % ({w * 1000:.0f} x {h * 1000:.0f} mm)"
    )
    band = np.full((int(0.012 * px_per_m), img.shape[1]), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    (tw, th), _ = cv2.getTextSize(title, font, 1.0, 2)
    scale = min(0.94 * img.shape[1] / tw, 0.6 * band.shape[0] / th)
    x = int(0.03 * img.shape[1])
    y = int(band.shape[0] * 0.5 + 0.5 * th * scale)
    cv2.putText(band, title, (x, y), font, scale, 0, max(1, int(2 * scale)), cv2.LINE_AA)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.concatenate([img, band])):
        raise InputError(f"--board-image {path}: could not write the image")
    return path


def _check(args: argparse.Namespace) -> None:
    if args.robot not in ("sim", "franky"):
        raise ConfigError("--robot", f"sim or franky, got {args.robot!r}")
    cam = args.camera.split(":", 1)[0]
    if cam not in ("sim", "realsense"):
        raise ConfigError("--camera", f"sim, realsense or realsense:SERIAL, got {args.camera!r}")
    if (args.robot == "sim") != (cam == "sim"):
        raise ConfigError("--camera", "the simulated robot goes with the simulated camera")
    if args.robot == "franky" and not args.robot_host:
        raise ConfigError("--robot-host", "the real robot needs its address")
    if args.robot == "franky" and (args.centre is None or args.look_from is None):
        raise ConfigError(
            "--centre/--look-from",
            "the real robot needs where to show the board and a rough "
            "camera position (world frame, m)",
        )
    if args.flush_frames is not None and args.flush_frames < 0:
        raise ConfigError("--flush-frames", f"must be >= 0, got {args.flush_frames}")


def _base_matrix(base: list[float] | None) -> np.ndarray | None:
    if base is None:
        return None
    x, y, z, yaw = base
    T = np.eye(4)
    T[:3, :3] = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
    T[:3, 3] = [x, y, z]
    return T


def _sim_devices(args: argparse.Namespace) -> tuple[Any, Any, Any, np.ndarray, dict]:

    scene = SceneConfig(
        seed=args.seed,
        camera=CameraConfig(width=args.width, height=args.height),
        hoses=HoseConfig(count=1),
        robot=RobotConfig(hand_board=True),
    )
    session = SimSession.build(EpisodeConfig(scene=scene))

    base = Pose(*session.world.panda_base).matrix()
    return session, session.robot, session.camera, base, {"scene": scene.to_dict()}


def _real_devices(args: argparse.Namespace) -> tuple[Any, Any, Any, np.ndarray | None, dict]:

    table = Obstacle.box("table", (0.0, 0.0, args.table_z - 0.02), (1.5, 1.5, 0.02))
    obstacles = [] if args.no_table else [table]

    _, _, serial = args.camera.partition(":")
    camera = RealSenseCamera(width=args.width, height=args.height, serial=serial or None)
    base = _base_matrix(args.base)
    try:
        # the camera pose is what we are about to measure: the robot gets a placeholder
        robot = FrankyPanda(
            args.robot_host,
            np.eye(4),
            T_world_base=base,
            obstacles=obstacles,
            realtime=not args.no_realtime,
        )
    except BaseException:
        camera.close()
        raise
    return camera, robot, camera, base, {}


def run(args: argparse.Namespace) -> int:
    _check(args)
    board = _board(args)
    say = quiet if args.quiet else Progress("calibrate")
    if args.board_image is not None:
        say(f"board image: {write_board_image(board, args.board_image)}")
    t0 = time.perf_counter()
    if args.robot == "sim":
        owner, robot, camera, base, meta = _sim_devices(args)
    else:
        owner, robot, camera, base, meta = _real_devices(args)
    try:
        T_true = camera.T_world_camera if args.robot == "sim" else None
        centre, look_from = args.centre, args.look_from
        if T_true is not None:  # simulation: a point in front of the camera, and the camera
            centre = centre or tuple(T_true[:3, 3] + 0.55 * T_true[:3, 2])
            look_from = look_from or tuple(T_true[:3, 3])
        plan = PlanConfig(
            centre=tuple(centre),
            look_from=tuple(look_from),
            spread=args.spread,
            max_tilt_deg=args.max_tilt,
            max_roll_deg=args.max_roll,
            candidates=args.candidates,
        )
        flush = (
            args.flush_frames if args.flush_frames is not None else (0 if T_true is not None else 3)
        )
        say(
            f"{args.poses} poses around {np.round(plan.centre, 3)} facing "
            f"{np.round(plan.look_from, 3)}; camera {camera.intrinsics.width}x"
            f"{camera.intrinsics.height}{' (dry run)' if args.dry_run else ''}"
        )
        session = calibrate_devices(
            robot,
            camera,
            board,
            args.poses,
            plan,
            stream(args.seed, "calibration"),
            T_world_base=base,
            dry_run=args.dry_run,
            speed=args.speed,
            flush_frames=flush,
            say=say,
        )
        if args.dry_run:
            for i, p in enumerate(session.poses):
                c = p.T_world_board[:3, :3] @ board.centre() + p.T_world_board[:3, 3]
                say(
                    f"pose {i + 1}: board centre {np.round(c, 3)}, TCP {np.round(p.T_world_tcp[:3, 3], 3)}"
                )
            print(f"dry run: {len(session.poses)} reachable poses planned; nothing moved")
            return 0
        result = session.result
        if result is None:  # pragma: no cover - calibrate_devices raises instead
            raise CalibrationError("no calibration was computed")
        result.meta.update(
            robot=args.robot if args.robot == "sim" else f"franky@{args.robot_host}",
            camera=args.camera,
            seed=args.seed,
            runtime_s=time.perf_counter() - t0,
            **meta,
        )
        if T_true is not None:
            dt, dr = pose_difference(result.T_world_camera, T_true)
            result.meta["sim_truth"] = {
                "T_world_camera": np.asarray(T_true).tolist(),
                "position_error_mm": 1000.0 * dt,
                "rotation_error_deg": math.degrees(dr),
            }
        path = write_calibration(result, args.out)
        print(f"calibration: {result.summary()}")
        if T_true is not None:
            t = result.meta["sim_truth"]
            print(
                f"against the simulated camera: {t['position_error_mm']:.3f} mm, "
                f"{t['rotation_error_deg']:.4f} deg"
            )
        print(f"wrote {path} in {time.perf_counter() - t0:.1f}s")
        return 0
    finally:
        owner.close()
