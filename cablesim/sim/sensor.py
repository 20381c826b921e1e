"""Sensor models of the simulated camera: RGB sensor noise and stereo-like depth.

Both are optional and off by default (``CameraConfig.rgb_noise``, ``CameraConfig.depth_noise``
with ``depth_model = "stereo"``); :class:`~cablesim.sim.camera.SimCamera` applies them to
every image it returns, each drawn from its own named random stream of the scene's seed
(``rgb_noise``, ``depth_noise``: :mod:`cablesim.seeding`), so the same seed gives the same
noise.  They are plain functions of a clean image and a generator, so a clean recording can
be given the same noise later (``benchmarks/experiments/realistic_flow/`` does, to report noisy and
noise-free results on the very same interactions).

**RGB** (:func:`rgb_sensor`, :class:`~cablesim.sim.config.RGBSensorConfig`).  The rendered
8-bit image is read as sRGB and linearised; a pixel collects ``lin * full_well * exposure``
electrons; shot noise (Gaussian with the Poisson variance) and read noise are added; the gain
``1 / exposure`` restores the brightness, so a short exposure gives a noisier image of the same
brightness; a per-frame brightness factor ``1 + N(0, frame_gain_jitter)`` models auto-exposure
steps and lamp flicker; the noise is blurred with a Gaussian of ``demosaic_sigma`` px (Bayer
demosaicing correlates neighbouring pixels) and rescaled to keep its variance; the result is
gamma-encoded again and rounded to 8 bits.  With the defaults a mid-grey pixel has a noise
of about 1.5 grey levels and a dark one about 2, as a RealSense colour stream indoors.

**Depth** (:func:`stereo_depth`, :class:`~cablesim.sim.config.StereoDepthConfig`), modelled
on active IR stereo with block matching (RealSense D4xx):

- the matching error lives in disparity ``d = f b / z``: ``sigma_d`` px, spatially correlated
  over the matching window (white noise box-filtered over ``window_px`` and rescaled), so
  sigma_z = z^2 sigma_d / (f b): about 2 mm at 1 m for 640x480 (f = 433 px), 1.4 mm at
  1280x720;
- at depth edges (a ``2 edge_px + 1`` neighbourhood spanning more than ``edge_jump``) the
  window's winner spreads one surface over the other: in patches about ``edge_scale_px`` long
  (a smooth random field) the near surface is *fattened* (grey erosion of depth) with
  probability ``fatten_probability``, otherwise a thin near object is *eroded* (the far
  surface spreads over it), by 0 to ``edge_px`` pixels (a second smooth field);
- edge pixels return nothing (0) with probability ``edge_dropout``;
- depth is quantised to ``quantum`` (1 mm).

``gaussian`` depth (``SimCamera``'s original model: sigma = k z^2 per pixel, 1 mm steps,
dropout at edges) stays the default ``depth_model``.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import cv2
import numpy as np

from cablesim.errors import InputError
from cablesim.sim.config import RGBSensorConfig, StereoDepthConfig

_SRGB = np.arange(256, dtype=np.float64) / 255.0
#: sRGB code value (0..255) -> linear light (0..1)
SRGB_TO_LINEAR = np.where(_SRGB <= 0.04045, _SRGB / 12.92, ((_SRGB + 0.055) / 1.055) ** 2.4).astype(
    np.float32
)
_LIN_STEPS = 1 << 16  # linear light is looked up on this grid on the way back


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """Linear light (0..1) -> sRGB (0..1), float32."""
    lin = np.clip(np.asarray(lin, np.float64), 0.0, 1.0)
    out = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return out.astype(np.float32)


#: linear light on a grid of ``_LIN_STEPS`` -> rounded sRGB code value (uint8)
_LINEAR_TO_CODE = np.clip(
    np.rint(linear_to_srgb(np.arange(_LIN_STEPS) / (_LIN_STEPS - 1)) * 255.0), 0, 255
).astype(np.uint8)


def _white_noise(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    return rng.standard_normal(shape, dtype=np.float32)


def _blur_unit(n: np.ndarray, sigma: float) -> np.ndarray:
    """White unit-variance noise blurred with a Gaussian of ``sigma`` px, rescaled to unit
    variance (per channel)."""
    if sigma <= 0:
        return n
    k = cv2.getGaussianKernel(2 * math.ceil(3 * sigma) + 1, sigma).astype(np.float64)
    std = float(np.sum(k**2))  # std of unit white noise after the separable 2-D kernel
    out = cv2.sepFilter2D(n, -1, k, k, borderType=cv2.BORDER_REFLECT)
    return out * np.float32(1.0 / std)


def rgb_sensor(rgb: np.ndarray, cfg: RGBSensorConfig, rng: np.random.Generator) -> np.ndarray:
    """``rgb`` (HxWx3 uint8) as the simulated sensor records it (module docstring)."""
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.ndim != 3:
        raise InputError(f"rgb must be an HxWx3 uint8 image, got {getattr(rgb, 'shape', None)}")
    scale = float(cfg.full_well * cfg.exposure)
    gain = 1.0 + cfg.frame_gain_jitter * float(rng.standard_normal())
    electrons = SRGB_TO_LINEAR[rgb] * np.float32(scale)
    std = cv2.sqrt(electrons + np.float32(cfg.read_noise**2))
    noise = _blur_unit(_white_noise(rgb.shape, rng), cfg.demosaic_sigma)
    # back to linear light (times the frame's gain) on the lookup grid
    out = cv2.multiply(std, noise)
    out += electrons
    out *= np.float32(gain / scale * (_LIN_STEPS - 1))
    idx = np.clip(out, 0, _LIN_STEPS - 1).astype(np.uint16)  # truncation = dither-free floor
    return _LINEAR_TO_CODE[idx]


def _disk(r: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def _smooth_field(shape: tuple[int, int], scale: float, rng: np.random.Generator) -> np.ndarray:
    """A smooth unit-variance Gaussian random field whose correlation length is about
    ``scale`` px (drawn on a coarse grid and interpolated)."""
    h, w = shape
    step = max(scale / 2.0, 1.0)
    gh, gw = max(2, math.ceil(h / step) + 2), max(2, math.ceil(w / step) + 2)
    g = _blur_unit(_white_noise((gh, gw), rng), 1.0)
    up = cv2.resize(g, (round(gw * step), round(gh * step)), interpolation=cv2.INTER_CUBIC)
    up = up[:h, :w]
    sd = float(up.std())
    return up / np.float32(sd if sd > 0 else 1.0)


def stereo_edges(depth: np.ndarray, radius: int, jump: float) -> np.ndarray:
    """Pixels whose ``2 radius + 1`` neighbourhood spans more than ``jump`` metres of valid
    depth (or touches a pixel without depth)."""
    z = depth.astype(np.float32)
    valid = z > 0
    k = _disk(max(radius, 1))
    near = cv2.erode(np.where(valid, z, np.float32(np.inf)), k, borderType=cv2.BORDER_REPLICATE)
    far = cv2.dilate(z, k, borderType=cv2.BORDER_REPLICATE)
    hole = cv2.dilate((~valid).astype(np.uint8), k) > 0
    return ((far - near) > jump) | (hole & valid)


def stereo_depth(
    depth: np.ndarray, cfg: StereoDepthConfig, focal: float, rng: np.random.Generator
) -> np.ndarray:
    """``depth`` (HxW float32 metres, 0 = none) as a block-matching stereo camera with focal
    length ``focal`` px measures it (module docstring)."""
    if not isinstance(depth, np.ndarray) or depth.ndim != 2:
        raise InputError(f"depth must be an HxW array, got {getattr(depth, 'shape', None)}")
    if not focal > 0:
        raise InputError(f"focal length must be positive, got {focal}")
    z = depth.astype(np.float32)
    valid = z > 0
    h, w = z.shape
    R = int(cfg.edge_px)
    edge = stereo_edges(z, max(R, 1), cfg.edge_jump)
    # edges: fatten (near surface spreads) or erode (far surface spreads), 0..R px, in patches
    out = z.copy()
    if R > 0 and edge.any():
        nd = NormalDist()
        kind = _smooth_field((h, w), cfg.edge_scale_px, rng)
        size = _smooth_field((h, w), cfg.edge_scale_px, rng)
        cuts = [nd.inv_cdf(k / (R + 1)) for k in range(1, R + 1)]
        radius = np.digitize(size, cuts).astype(np.int32)  # 0..R, uniform
        p = min(max(cfg.fatten_probability, 1e-9), 1 - 1e-9)
        fatten = kind < nd.inv_cdf(p)
        z_inf = np.where(valid, z, np.float32(np.inf))
        for r in range(1, R + 1):
            sel = edge & (radius == r)
            if not sel.any():
                continue
            k = _disk(r)
            near = cv2.erode(z_inf, k, borderType=cv2.BORDER_REPLICATE)
            far = cv2.dilate(z, k, borderType=cv2.BORDER_REPLICATE)
            out = np.where(sel & fatten & np.isfinite(near), near, out)
            out = np.where(sel & ~fatten, far, out)
    # correlated disparity error
    ok = out > 0
    fb = float(focal) * float(cfg.baseline)
    disp = np.where(ok, fb / np.where(ok, out, 1.0), 0.0).astype(np.float64)
    if cfg.disparity_noise > 0:
        win = max(int(cfg.window_px), 1)
        n = _white_noise((h, w), rng)
        if win > 1:
            n = cv2.blur(n, (win, win), borderType=cv2.BORDER_REFLECT) * np.float32(win)
        disp = disp + cfg.disparity_noise * n.astype(np.float64)
    ok &= disp > 0
    noisy = np.where(ok, fb / np.where(ok, disp, 1.0), 0.0)
    if cfg.quantum > 0:
        noisy = np.round(noisy / cfg.quantum) * cfg.quantum
    drop = edge & (rng.random((h, w)) < cfg.edge_dropout)
    return np.where(ok & ~drop & (noisy > 0), noisy, 0.0).astype(np.float32)
