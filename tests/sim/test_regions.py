"""board_region: the task board's image region from the scene geometry (the thesis's flow crop)."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import ConfigError, InputError
from cablesim.sim.camera import intrinsics_from_fovy
from cablesim.sim.config import BoardConfig, CameraConfig, SceneConfig
from cablesim.sim.regions import board_region, camera_pose


def _K(c: CameraConfig):
    return intrinsics_from_fovy(c.width, c.height, c.fovy)


def test_board_region_contains_the_projected_board():
    cfg = SceneConfig()
    K = _K(cfg.camera)
    x0, y0, w, h = board_region(cfg, K, margin=0)
    T = camera_pose(cfg)
    b = cfg.board
    # points spread over the board's front face project inside the region (or off the image)
    ys, zs = np.meshgrid(np.linspace(-b.width / 2, b.width / 2, 7), np.linspace(0, b.height, 7))
    pts = np.stack([np.full(ys.size, b.x), ys.ravel(), zs.ravel()], 1)
    uv = K.project((pts - T[:3, 3]) @ T[:3, :3])
    on_image = (uv[:, 0] >= 0) & (uv[:, 0] < K.width) & (uv[:, 1] >= 0) & (uv[:, 1] < K.height)
    inside = (
        (uv[:, 0] >= x0 - 1) & (uv[:, 0] <= x0 + w) & (uv[:, 1] >= y0 - 1) & (uv[:, 1] <= y0 + h)
    )
    assert np.all(inside[on_image])
    # tight: the region's edges touch the board's projected extent (where not clipped)
    assert abs(uv[:, 0].min() - x0) < 2 and abs(uv[:, 0].max() - (x0 + w)) < 2
    # a margin grows it, the image clips it
    x1, y1, w1, h1 = board_region(cfg, K, margin=8)
    assert x1 == max(0, x0 - 8) and w1 >= w and 0 <= y1 <= y0 and y1 + h1 <= K.height


def test_thesis_geometry_scales_the_region():
    small, big = CameraConfig(), CameraConfig.thesis()
    r0 = board_region(SceneConfig(camera=small), _K(small), margin=0)
    r1 = board_region(SceneConfig(camera=big), _K(big), margin=0)
    # same field of view vertically: 720/480 = 1.5x the pixels across the board
    assert r1[2] == pytest.approx(1.5 * r0[2], rel=0.02)


def test_board_behind_the_camera_is_an_error():
    # a board moved behind the camera is refused by the config itself (board.x stays over the
    # table); a camera moved past the board, looking away from it, is a valid scene
    with pytest.raises(ConfigError, match="board.x"):
        BoardConfig(x=-1.0, connectors=((0.0, 0.5),))
    cfg = SceneConfig(camera=CameraConfig(position=(0.8, 0.0, 0.6), look_at=(2.0, 0.0, 0.5)))
    with pytest.raises(InputError, match="in front"):
        board_region(cfg, _K(cfg.camera))
