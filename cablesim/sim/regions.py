"""Image regions of the simulated set-up, from the scene's geometry alone (no rendering).

``board_region(cfg, intrinsics)`` is the task board's front face in the image (on the table,
the mat with its sockets, where the cables lie): the crop in which the thesis computed its flow (SPEC section 8: the task-board region of the 1280x720
image, scaled up 1.5x), for :class:`cablesim.perception.flow_region.RegionFlow`::

    crop = board_region(scene_cfg, camera.intrinsics)        # (x0, y0, width, height)
    flow = RegionFlow(DISFlow(), FlowRegion.from_crop(crop, 1.5))
"""

from __future__ import annotations

import math

import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Intrinsics
from cablesim.sim.config import SceneConfig
from cablesim.sim.layout import sample_camera
from cablesim.sim.world import look_at_frame


def camera_pose(cfg: SceneConfig) -> np.ndarray:
    """T_world_camera (4x4, OpenCV axes) of the scene's camera, jitter included."""
    pose = sample_camera(cfg)
    T = np.eye(4)
    T[:3, :3] = look_at_frame(pose.position, pose.look_at)
    T[:3, 3] = pose.position
    return T


def board_region(
    cfg: SceneConfig, intrinsics: Intrinsics, margin: int = 8
) -> tuple[int, int, int, int]:
    """(x0, y0, width, height) of the board's front face in the image (the table's mat, its
    sockets and what a cable on it can reach), grown by ``margin`` pixels and clipped to the
    image."""
    b = cfg.board
    T = camera_pose(cfg)
    if cfg.surface == "table":
        x0, x1, y0, y1 = cfg.table.region
        m = cfg.table.mat_margin
        top = 0.1  # m: a cable lifted off the mat by the hand
        corners = np.array(
            [[x, y, z] for x in (x0 - m, x1 + m) for y in (y0 - m, y1 + m) for z in (0.0, top)],
            float,
        )
    else:
        corners = np.array(
            [[b.x, y, z] for y in (-b.width / 2, b.width / 2) for z in (0.0, b.height)], float
        )
    cam = (corners - T[:3, 3]) @ T[:3, :3]  # world -> camera (R^T (p - t))
    if np.any(cam[:, 2] <= 0):
        raise InputError(f"the {cfg.surface} is not in front of the camera")
    uv = intrinsics.project(cam)
    w, h = intrinsics.width, intrinsics.height
    x0 = max(0, math.floor(uv[:, 0].min()) - margin)
    y0 = max(0, math.floor(uv[:, 1].min()) - margin)
    x1 = min(w, math.ceil(uv[:, 0].max()) + 1 + margin)
    y1 = min(h, math.ceil(uv[:, 1].max()) + 1 + margin)
    if x1 - x0 < 4 or y1 - y0 < 4:
        raise InputError(f"the {cfg.surface} covers less than 4x4 pixels of the {w}x{h} image")
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)
