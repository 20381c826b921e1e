"""A MovingCables clip with analytic motion: a striped band (a cable) slides over a still
textured background; its exact flow back to the first image is minus its shift, its normal
flow that flow's component along the band's normal."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from cablesim.formats.movingcables import ClipFrame, write_clip


def background(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    noise = rng.uniform(0, 255, (h, w, 3)).astype(np.float32)
    return np.clip(cv2.GaussianBlur(noise, (0, 0), 3.0) * 2.5 - 190, 0, 255).astype(np.uint8)


def band_image(h: int, w: int, shift: tuple[float, float], width: int) -> tuple[np.ndarray, ...]:
    """(RGB of the band alone, its mask) with the band's centre line y = h/2 + 0.15 x shifted
    by ``shift`` (x, y)."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    sx, sy = shift
    u, v = xx - sx, yy - sy  # the band's own coordinates
    centre = h / 2 + 0.15 * u
    mask = np.abs(v - centre) <= width / 2
    stripes = (np.floor(u / 6) % 2).astype(np.float32)
    rgb = np.stack([40 + 170 * stripes, 90 + 0 * stripes, 200 - 150 * stripes], axis=2)
    return rgb.astype(np.uint8), mask


#: the unit normal of the band's centre line y = h/2 + 0.15 x
BAND_NORMAL = np.array([-0.15, 1.0]) / np.hypot(0.15, 1.0)


def normal_part(flow: tuple[float, float]) -> tuple[float, float]:
    """The normal flow of a band point moving by ``flow``: its component along the normal."""
    f = np.asarray(flow, np.float64)
    n = float(f @ BAND_NORMAL) * BAND_NORMAL
    return float(n[0]), float(n[1])


def write_synthetic_clip(
    split: Path, clip: str, seed: int, frames: int = 6, size: tuple[int, int] = (240, 320)
) -> list[tuple[float, float]]:
    """Write the clip; returns the band's shift per image (the first is (0, 0))."""
    rng = np.random.default_rng(seed)
    h, w = size
    bg = background(h, w, rng)
    step = rng.uniform(1.0, 2.5, 2) * rng.choice([-1, 1], 2)
    shifts = [(float(step[0] * k), float(step[1] * k)) for k in range(frames)]
    out = []
    for k, (sx, sy) in enumerate(shifts):
        band, mask = band_image(h, w, (sx, sy), 10)
        rgb = np.where(mask[..., None], band, bg)
        flow = np.zeros((h, w, 2), np.float32)
        flow[mask] = (-sx, -sy)
        normal = np.zeros((h, w, 2), np.float32)
        normal[mask] = normal_part((-sx, -sy))
        inst = mask.astype(np.uint16)
        out.append(ClipFrame(2 * k + 1, np.ascontiguousarray(rgb), flow, normal, inst, None))
    write_clip(split, clip, out)
    return shifts
