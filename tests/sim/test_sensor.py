"""Sensor models: RGB shot/read noise with exposure, stereo-like depth; off by default, seeded,
applied by SimCamera from their own random streams."""

from __future__ import annotations

import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.errors import ConfigError, InputError
from cablesim.seeding import stream
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import (
    CameraConfig,
    RGBSensorConfig,
    RobotConfig,
    SceneConfig,
    StereoDepthConfig,
)
from cablesim.sim.sensor import rgb_sensor, stereo_depth
from cablesim.sim.world import World

F = 433.0  # px, the default camera's focal length at 640x480


def _grey(v: int, shape=(120, 160)) -> np.ndarray:
    return np.full((*shape, 3), v, np.uint8)


def test_off_by_default():
    c = CameraConfig()
    assert not c.rgb_noise and not c.depth_noise and c.depth_model == "gaussian"
    r = CameraConfig.realistic()
    assert r.rgb_noise and r.depth_noise and r.depth_model == "stereo"
    t = CameraConfig.thesis()
    assert (t.width, t.height) == (1280, 720)
    with pytest.raises(ConfigError, match="depth_model"):
        CameraConfig(depth_model="tof")
    with pytest.raises(ConfigError, match="rgb_sensor.exposure"):
        CameraConfig(rgb_sensor=RGBSensorConfig(exposure=0.0))
    with pytest.raises(ConfigError, match="depth_stereo.edge_px"):
        CameraConfig(depth_stereo=StereoDepthConfig(edge_px=-1))


def test_rgb_noise_statistics_and_exposure():
    cfg = RGBSensorConfig(frame_gain_jitter=0.0)
    rng = np.random.default_rng(0)
    mid = rgb_sensor(_grey(128), cfg, rng).astype(float)
    dark = rgb_sensor(_grey(20), cfg, rng).astype(float)
    assert abs(mid.mean() - 128) < 0.3 and abs(dark.mean() - 20) < 0.5  # brightness kept
    assert 1.0 < mid.std() < 3.5 and 2.0 < dark.std() < 5.0  # a few grey levels
    short = rgb_sensor(_grey(128), RGBSensorConfig(exposure=0.25, frame_gain_jitter=0.0), rng)
    assert abs(short.mean() - 128) < 0.5
    assert 1.6 < short.astype(float).std() / mid.std() < 2.4  # 4x less light: ~2x the noise
    # demosaicing correlates neighbours; without it the noise is independent
    n = mid[..., 0] - 128
    corr = np.corrcoef(n[:, :-1].ravel(), n[:, 1:].ravel())[0, 1]
    flat = rgb_sensor(_grey(128), RGBSensorConfig(demosaic_sigma=0.0, frame_gain_jitter=0.0), rng)
    m = flat[..., 0].astype(float) - 128
    corr0 = np.corrcoef(m[:, :-1].ravel(), m[:, 1:].ravel())[0, 1]
    assert corr > 0.3 and abs(corr0) < 0.05
    # per-frame gain: frames differ in brightness
    means = [
        rgb_sensor(_grey(128), RGBSensorConfig(frame_gain_jitter=0.05), rng).mean()
        for _ in range(8)
    ]
    assert np.std(means) > 1.0


def test_rgb_noise_deterministic():
    img = np.random.default_rng(1).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    a = rgb_sensor(img, RGBSensorConfig(), np.random.default_rng(5))
    b = rgb_sensor(img, RGBSensorConfig(), np.random.default_rng(5))
    c = rgb_sensor(img, RGBSensorConfig(), np.random.default_rng(6))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    with pytest.raises(InputError):
        rgb_sensor(img.astype(np.float32), RGBSensorConfig(), np.random.default_rng(0))


def _plane_with_bar(z0: float = 1.04, h: int = 200, w: int = 160, bar: int = 7) -> np.ndarray:
    z = np.full((h, w), z0, np.float32)
    z[:, 80 : 80 + bar] = z0 - 0.015  # a 15 mm hose-like bar in front of the board
    return z


def test_stereo_depth_noise_is_disparity_like_and_correlated():
    cfg = StereoDepthConfig(edge_dropout=0.0)
    z0 = 1.04
    z = np.full((240, 320), z0, np.float32)
    d = stereo_depth(z, cfg, F, np.random.default_rng(0))
    err = (d - z0).astype(np.float64)
    expected = z0**2 * cfg.disparity_noise / (F * cfg.baseline)
    assert 0.8 * expected < err.std() < 1.2 * expected
    assert abs(err.mean()) < 0.2 * expected
    assert np.allclose(d / cfg.quantum, np.round(d / cfg.quantum), atol=1e-3)  # 1 mm steps
    corr = np.corrcoef(err[:, :-1].ravel(), err[:, 1:].ravel())[0, 1]
    assert corr > 0.6  # correlated over the matching window
    white = stereo_depth(z, StereoDepthConfig(window_px=1), F, np.random.default_rng(0))
    e1 = (white - z0).astype(np.float64)
    assert abs(np.corrcoef(e1[:, :-1].ravel(), e1[:, 1:].ravel())[0, 1]) < 0.1


def test_stereo_depth_fattens_and_erodes_thin_objects():
    cfg = StereoDepthConfig(disparity_noise=0.0, edge_dropout=0.0, edge_scale_px=8.0)
    z = _plane_with_bar()
    d = stereo_depth(z, cfg, F, np.random.default_rng(3))
    width = ((d > 0) & (d < 1.04 - 0.0075)).sum(axis=1)
    assert width.min() >= 7 - 2 * cfg.edge_px and width.max() <= 7 + 2 * cfg.edge_px
    assert (width > 7).mean() > 0.2 and (width < 7).mean() > 0.1  # both happen, in patches
    assert (width == 7).mean() < 0.8
    far = np.abs(np.arange(z.shape[1]) - 83) > cfg.edge_px + 4
    assert np.array_equal(d[:, far], z[:, far])  # away from edges only noise (none here)
    d2 = stereo_depth(z, cfg, F, np.random.default_rng(3))
    assert np.array_equal(d, d2)
    drop = stereo_depth(z, StereoDepthConfig(edge_dropout=1.0), F, np.random.default_rng(3))
    assert (drop == 0).any() and not (drop[:, far] == 0).any()  # holes only at edges


@pytest.fixture(scope="module")
def noisy_world() -> World:
    cam = CameraConfig(width=160, height=120).realistic(width=160, height=120)
    return World.build(SceneConfig(seed=1, camera=cam, robot=RobotConfig(enabled=False)))


def test_sim_camera_applies_the_models_from_their_streams(noisy_world: World):
    c = noisy_world.cfg.camera
    with SimCamera(noisy_world) as cam:
        clean_rgb, clean_depth = cam._render_rgbd()  # noqa: SLF001 - the clean render
        img = cam.capture()
        again = cam.capture()
    seed = noisy_world.cfg.seed
    want_rgb = rgb_sensor(clean_rgb, c.rgb_sensor, stream(seed, "rgb_noise"))
    want_depth = stereo_depth(
        clean_depth, c.depth_stereo, cam.intrinsics.f, stream(seed, "depth_noise")
    )
    assert np.array_equal(img.rgb, want_rgb)
    assert np.array_equal(img.depth, want_depth)
    assert not np.array_equal(img.rgb, clean_rgb) and not np.array_equal(again.rgb, img.rgb)
    # a default camera returns the render untouched
    noisy_cfg = noisy_world.cfg
    noisy_world.cfg = noisy_cfg.replace(camera=CameraConfig(width=160, height=120))
    try:
        with SimCamera(noisy_world) as plain:
            r, d = plain._render_rgbd()  # noqa: SLF001
            got = plain.capture()
        assert np.array_equal(got.rgb, r) and np.array_equal(got.depth, d)
    finally:
        noisy_world.cfg = noisy_cfg
