"""Eye-to-hand camera calibration with a ChArUco board held by the gripper (issue 8).

The camera is fixed; the robot holds a ChArUco board and shows it to the camera at N poses.
Each pose gives two transforms of the same board: through the robot (the TCP pose ``B_i`` in the
world, then the unknown, constant board-on-TCP transform ``Y = T_tcp_board``) and through the
camera (the unknown ``X = T_world_camera``, then the board pose ``C_i = T_camera_board`` that
perspective-n-point gives from the detected corners)::

    B_i Y = X C_i        for every pose i

One concept per module, every public name importable from here:

- :mod:`~cablesim.calibration.board`: :class:`BoardSpec` (the board and its nominal mount),
  :func:`detect_board`, :func:`board_pose` (PnP);
- :mod:`~cablesim.calibration.solve`: :func:`solve_eye_to_hand` (closed form: OpenCV's Park,
  or :func:`park_martin` in NumPy), :func:`refine_eye_to_hand` (every corner's reprojection),
  :func:`calibrate` over :class:`Sample` views to a :class:`CalibrationResult`;
- :mod:`~cablesim.calibration.io`: :func:`write_calibration`, :func:`load_calibration` (a
  :class:`Calibration`; errors name the file and the field), ``FORMAT`` and ``VERSION``;
- :mod:`~cablesim.calibration.plan`: :class:`PlanConfig`, :func:`draw_board_poses` and
  :func:`plan_poses` (seeded, reachable, diverse views);
- :mod:`~cablesim.calibration.devices`: :func:`collect_samples` and
  :func:`calibrate_devices` over any :class:`~cablesim.robot.base.Robot` and
  :class:`~cablesim.camera.base.Camera` (the simulated Panda with a board in its hand, or the
  real one);
- :mod:`~cablesim.calibration.transforms`: :func:`pose_difference`, :func:`rotation_angle`,
  :func:`check_transform`.

Pure OpenCV/NumPy (and SciPy's least squares): no simulator, no MuJoCo at import time.
"""

from cablesim.calibration.board import (
    MIN_CORNERS,
    BoardDetection,
    BoardSpec,
    board_pose,
    detect_board,
)
from cablesim.calibration.devices import Session, calibrate_devices, collect_samples
from cablesim.calibration.io import (
    FORMAT,
    VERSION,
    Calibration,
    load_calibration,
    write_calibration,
)
from cablesim.calibration.plan import PlanConfig, PlannedPose, Say, draw_board_poses, plan_poses
from cablesim.calibration.solve import (
    MIN_POSES,
    CalibrationResult,
    Sample,
    calibrate,
    park_martin,
    refine_eye_to_hand,
    solve_eye_to_hand,
)
from cablesim.calibration.transforms import check_transform, pose_difference, rotation_angle

__all__ = [
    "FORMAT",
    "MIN_CORNERS",
    "MIN_POSES",
    "VERSION",
    "BoardDetection",
    "BoardSpec",
    "Calibration",
    "CalibrationResult",
    "PlanConfig",
    "PlannedPose",
    "Sample",
    "Say",
    "Session",
    "board_pose",
    "calibrate",
    "calibrate_devices",
    "check_transform",
    "collect_samples",
    "detect_board",
    "draw_board_poses",
    "load_calibration",
    "park_martin",
    "plan_poses",
    "pose_difference",
    "refine_eye_to_hand",
    "rotation_angle",
    "solve_eye_to_hand",
    "write_calibration",
]
