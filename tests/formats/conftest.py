"""A small interaction with real image motion: a textured strip (the grasped hose) follows the
gripper over a static textured board; the target frame has it at rest."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cablesim.frames import Frame, FrameTruth, Intrinsics, Stream
from cablesim.perception.synthetic import SyntheticSpec, triangle_wave

H, W, FOCAL, Z = 72, 96, 300.0, 1.0
STRIP = (30, 40, 10, 86)  # rows y0:y1, columns x0:x1


def _texture(seed: int, sigma: float = 1.5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.uniform(0, 255, (H, W)).astype(np.float32), (0, 0), sigma)
    return cv2.normalize(t, None, 30, 225, cv2.NORM_MINMAX)


def _shift(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    M = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, M, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def moving_strip_stream(gain: float = 0.8, periods: int = 1, spp: int = 8) -> Stream:
    board, strip = _texture(1), _texture(2)
    alpha = np.zeros((H, W), np.float32)
    y0, y1, x0, x1 = STRIP
    alpha[y0:y1, x0:x1] = 1.0
    labels = np.full((H, W), -1, np.int16)
    labels[y0:y1, x0:x1] = 0
    K = Intrinsics(FOCAL, FOCAL, (W - 1) / 2, (H - 1) / 2, W, H)
    depth = np.full((H, W), Z, np.float32)
    profile = triangle_wave(SyntheticSpec(amplitude=0.02, periods=periods, samples_per_period=spp))
    g0 = np.array([0.0, 0.0, Z])

    def image(dx: float, dy: float) -> np.ndarray:
        a = _shift(alpha, dx, dy)
        g = board * (1 - a) + _shift(strip, dx, dy) * a
        return np.repeat(np.clip(np.rint(g), 0, 255).astype(np.uint8)[..., None], 3, axis=2)

    frames = []
    for action, u in enumerate((np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))):
        for k, d in enumerate(profile):
            shift = gain * d * FOCAL / Z * u[:2]
            flow = np.zeros((H, W, 2), np.float32)
            flow[labels == 0] = shift
            truth = FrameTruth(labels, 0, flow, np.ones((H, W), bool))
            t = float(len(frames)) / 15
            img = image(*shift)
            frames.append(Frame(img, depth, K, g0 + d * u, action, k, t, truth=truth))
    target_truth = FrameTruth(labels, 0, np.zeros((H, W, 2), np.float32), np.ones((H, W), bool))
    t = float(len(frames)) / 15
    frames.append(
        Frame(image(0, 0), depth, K, np.array([0.3, 0.3, 0.5]), -1, 0, t, truth=target_truth)
    )
    return Stream(frames, {"synthetic": "moving strip"})


@pytest.fixture(scope="session")
def moving_stream() -> Stream:
    return moving_strip_stream()
