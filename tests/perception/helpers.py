"""Synthetic images for flow tests."""

from __future__ import annotations

import cv2
import numpy as np


def texture(h: int, w: int, seed: int = 0, sigma: float = 2.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), sigma)
    return cv2.normalize(t, None, 0, 255, cv2.NORM_MINMAX)


def shifted(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """img translated by (dx, dy): shifted(p + d) = img(p)."""
    M = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(
        img, M, (img.shape[1], img.shape[0]), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT
    )


def to_u8_rgb(img: np.ndarray) -> np.ndarray:
    g = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=2)
