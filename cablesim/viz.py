"""Pictures for people: vote overlays, flow and map colours, titled panels (one copy).

All images are RGB uint8; :func:`write_png` writes them with OpenCV.  NumPy/OpenCV only.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

GREEN = np.array([0, 255, 0], np.float32)


def overlay_votes(rgb: np.ndarray, votes: np.ndarray, max_votes: int | None = None) -> np.ndarray:
    """Votes in shades of green over a darkened RGB image (as in the thesis figures)."""
    base = rgb.astype(np.float32) * 0.6
    top = max(int(max_votes or votes.max(initial=0)), 1)
    a = np.clip(votes.astype(np.float32) / top, 0, 1)[..., None]
    a = np.where(votes[..., None] > 0, 0.35 + 0.65 * a, 0.0)
    out = base * (1 - a) + GREEN * a
    return np.clip(out, 0, 255).astype(np.uint8)


def overlay_mask(rgb: np.ndarray, mask: np.ndarray, colour=(255, 255, 255)) -> np.ndarray:
    out = (rgb.astype(np.float32) * 0.4).astype(np.uint8)
    out[mask] = colour
    return out


def colour_flow(flow: np.ndarray, max_mag: float | None = None) -> np.ndarray:
    """RGB uint8 HSV wheel: hue = direction, value = magnitude / max_mag."""
    mag = np.linalg.norm(flow, axis=-1)
    ang = np.arctan2(flow[..., 1], flow[..., 0])
    mm = float(max_mag if max_mag is not None else max(mag.max(initial=0.0), 1e-6))
    hsv = np.zeros((*flow.shape[:2], 3), np.uint8)
    hsv[..., 0] = np.round((ang + np.pi) / (2 * np.pi) * 179).astype(np.uint8)
    hsv[..., 1] = 255
    hsv[..., 2] = np.round(np.clip(mag / max(mm, 1e-6), 0, 1) * 255).astype(np.uint8)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def colour_map(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    s = np.clip((np.nan_to_num(x) - lo) / max(hi - lo, 1e-9), 0, 1)
    bgr = cv2.applyColorMap((s * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
    return bgr[..., ::-1].copy()


def hstack(tiles: list[np.ndarray], sep: int = 4) -> np.ndarray:
    h = tiles[0].shape[0]
    bar = np.full((h, sep, 3), 255, np.uint8)
    row: list[np.ndarray] = []
    for t in tiles:
        row += [t, bar]
    return np.concatenate(row[:-1], axis=1)


def label(img: np.ndarray, text: str) -> np.ndarray:
    out = img.copy()
    scale = max(0.35, img.shape[1] / 1200)
    cv2.putText(out, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(out, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1)
    return out


def write_png(path: Path, rgb: np.ndarray) -> None:
    cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1]))
