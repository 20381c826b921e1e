"""Training pairs for the learned flow from simulated MovingCables clips, with camera effects.

A clip written by ``cablesim dataset movingcables`` holds every image of one interaction and
the exact flow of each image back to the first and its normal flow
(:mod:`cablesim.dataset.generate`); a pair is (image k, the first image, the flow of image k
back to the first that the model is trained on: ``normal_flow_first_back`` for a model of
``target="normal"``, ``flow_first_back`` for ``"flow"``), image1 being image k as in the
published evaluation (:func:`cablesim.formats.movingcables.evaluate_clip`).

:func:`make_pair` turns one such triple into a training sample, every draw from the generator
it is given (so a sample depends on its seed alone, whatever the order or the number of
processes):

- **scale** ``scale`` (relative to the rendered image) and a **crop** of ``crop`` (h, w)
  working pixels, centred on a moving pixel with probability ``centre_on_motion`` (the moving
  hose may cover a few percent of the image);
- **flips** left-right and up-down (the flow's components change sign);
- **camera effects** on both images alike: contrast, brightness, per-channel gains (white
  balance), gamma, a Gaussian blur; on each image on its own: a brightness step
  (auto-exposure), sensor noise, JPEG compression (blocks and ringing, as H.264 leaves);
- the network input of :func:`cablesim.perception.learned.prepare` (DIS on the degraded
  images), the exact (normal) flow at the working size, the pixels with a known flow (the arm, dilated,
  moves but has no ground truth) and the moving fraction (|flow| > ``moving_px``, area
  averaged when scaled down).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np

from cablesim.config import Config, check_number, check_positive, check_range
from cablesim.errors import ConfigError, RecordingError
from cablesim.formats.movingcables import (
    FLOW_FOLDER,
    NORMAL_FLOW_FOLDER,
    STICK_FOLDER,
    clip_indices,
    list_clips,
    read_flow_png,
    rgb_folder,
)
from cablesim.perception.learned import LearnedFlowConfig, prepare


@dataclass(frozen=True)
class AugmentConfig(Config):
    """How :func:`make_pair` draws a sample (module docstring)."""

    SECTION: ClassVar[str] = "augment"

    scale: tuple[float, float] = (0.35, 1.5)  # of the rendered image (640x480: hose 3-10 px)
    crop: tuple[int, int] = (160, 224)  # (h, w) working pixels
    centre_on_motion: float = 0.7  # share of crops centred on a moving pixel
    flip: bool = True
    contrast: tuple[float, float] = (0.6, 1.3)
    brightness: float = 30.0  # grey levels, +-
    channel_gain: float = 0.15  # per-channel gain 1 +- this
    gamma: tuple[float, float] = (0.7, 1.5)
    blur: tuple[float, float] = (0.0, 1.2)  # Gaussian sigma, px (0: none)
    frame_gain: float = 0.03  # per-image brightness step, std
    noise: tuple[float, float] = (0.0, 5.0)  # sensor noise std, grey levels
    jpeg: float = 0.6  # share of images JPEG-compressed
    jpeg_quality: tuple[int, int] = (20, 95)
    moving_px: float = 1.0  # a pixel moves where |flow| > this (working px)

    def _validate(self) -> None:
        s = self.SECTION
        check_range(f"{s}.scale", self.scale, 0.05, 4.0)
        for i, v in enumerate(self.crop):
            if int(v) < 64 or int(v) % 16:
                raise ConfigError(f"{s}.crop[{i}]", f"must be a multiple of 16 >= 64, got {v}")
        for name in ("centre_on_motion", "jpeg"):
            v = check_number(f"{s}.{name}", getattr(self, name))
            if not 0 <= v <= 1:
                raise ConfigError(f"{s}.{name}", f"must be in [0, 1], got {v}")
        check_range(f"{s}.contrast", self.contrast, 0.0)
        check_range(f"{s}.gamma", self.gamma, 0.05)
        check_range(f"{s}.blur", self.blur, 0.0)
        check_range(f"{s}.noise", self.noise, 0.0)
        check_range(f"{s}.jpeg_quality", self.jpeg_quality, 1, 100)
        for name in ("brightness", "channel_gain", "frame_gain"):
            check_positive(f"{s}.{name}", getattr(self, name), allow_zero=True)
        check_positive(f"{s}.moving_px", self.moving_px)


# ----------------------------------------------------------------------------- clips
@dataclass(frozen=True)
class ClipRef:
    """One clip of a MovingCables split folder and its image numbers."""

    split: Path
    clip: str
    indices: tuple[int, ...]

    def rgb(self, index: int) -> np.ndarray:
        path = rgb_folder(self.split, self.clip) / f"{index:08d}.png"
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise RecordingError(f"cannot read {path}")
        return np.ascontiguousarray(img[..., ::-1])

    def flow(self, index: int, normal: bool = False) -> np.ndarray:
        """The exact flow of image ``index`` back to the first (``normal``: its normal flow)."""
        folder = NORMAL_FLOW_FOLDER if normal else FLOW_FOLDER
        path = self.split / folder / self.clip / f"{index:08d}.png"
        if not path.is_file():
            raise RecordingError(f"{path}: no ground-truth flow (a simulated clip has one)")
        return read_flow_png(path)[0]

    def stick(self, index: int) -> np.ndarray | None:
        path = self.split / STICK_FOLDER / self.clip / f"{index:08d}.png"
        if not path.is_file():
            return None
        m = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if m is None:
            raise RecordingError(f"cannot read {path}")
        return (m if m.ndim == 2 else m.max(axis=2)) > 0


def find_clips(splits: list[Path] | tuple[Path, ...]) -> list[ClipRef]:
    """Every clip with at least two images in the MovingCables split folders ``splits``, in
    a fixed order (the folders' order, then clip names)."""
    out: list[ClipRef] = []
    for split in splits:
        split = Path(split)
        if not split.is_dir():
            raise RecordingError(f"no such MovingCables split folder: {split}")
        for clip in list_clips(split):
            idx = clip_indices(split, clip)
            if len(idx) >= 2:
                out.append(ClipRef(split, clip, tuple(idx)))
    if not out:
        raise RecordingError(f"no clips with two or more images under {[str(s) for s in splits]}")
    return out


# ----------------------------------------------------------------------------- one sample
@dataclass
class Sample:
    """One training pair at the working size: the network input (13xHxW), the DIS flow and
    the exact flow (2xHxW, px), the known pixels and the moving fraction (HxW)."""

    x: np.ndarray
    dis: np.ndarray
    flow: np.ndarray
    valid: np.ndarray
    moving: np.ndarray


def _resize(img: np.ndarray, size: tuple[int, int], down: bool) -> np.ndarray:
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA if down else cv2.INTER_LINEAR)


def _crop_origin(
    moving: np.ndarray, ch: int, cw: int, rng: np.random.Generator, centre: bool
) -> tuple[int, int]:
    h, w = moving.shape
    ys, xs = np.nonzero(moving)
    if centre and len(ys):
        i = int(rng.integers(len(ys)))
        y0, x0 = int(ys[i]) - ch // 2, int(xs[i]) - cw // 2
    else:
        y0, x0 = int(rng.integers(h - ch + 1)), int(rng.integers(w - cw + 1))
    return min(max(y0, 0), h - ch), min(max(x0, 0), w - cw)


def camera_effects(
    rgb1: np.ndarray, rgb2: np.ndarray, aug: AugmentConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Both images through one drawn camera (module docstring); uint8 RGB out."""
    contrast = rng.uniform(*aug.contrast)
    bright = rng.uniform(-aug.brightness, aug.brightness)
    gains = 1.0 + rng.uniform(-aug.channel_gain, aug.channel_gain, 3)
    gamma = rng.uniform(*aug.gamma)
    blur = rng.uniform(*aug.blur)
    out = []
    for img in (rgb1, rgb2):
        step = 1.0 + aug.frame_gain * rng.standard_normal()
        noise_sd = rng.uniform(*aug.noise)
        q = int(rng.integers(aug.jpeg_quality[0], aug.jpeg_quality[1] + 1))
        do_jpeg = rng.random() < aug.jpeg
        f = img.astype(np.float32) / 255.0
        f = np.clip(f, 0, 1) ** gamma
        f = (f - 0.5) * contrast + 0.5 + bright / 255.0
        f = f * (gains * step).astype(np.float32)
        f = f * 255.0
        if blur > 0.3:
            f = cv2.GaussianBlur(f, (0, 0), blur)
        if noise_sd > 0:
            f = f + rng.standard_normal(f.shape).astype(np.float32) * noise_sd
        u8 = np.clip(np.rint(f), 0, 255).astype(np.uint8)
        if do_jpeg:
            ok, buf = cv2.imencode(".jpg", u8[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
            if ok:
                u8 = np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])
        out.append(u8)
    return out[0], out[1]


def make_pair(
    rgb1: np.ndarray,
    rgb2: np.ndarray,
    flow: np.ndarray,
    stick: np.ndarray | None,
    model: LearnedFlowConfig,
    aug: AugmentConfig,
    rng: np.random.Generator,
) -> Sample:
    """One :class:`Sample` from image k (``rgb1``), the first image (``rgb2``) and the exact
    flow of image k back to the first (module docstring)."""
    h, w = rgb1.shape[:2]
    ch, cw = int(aug.crop[0]), int(aug.crop[1])
    s = float(rng.uniform(*aug.scale))
    s = max(s, ch / h, cw / w)  # the crop must fit
    size = (max(cw, round(w * s)), max(ch, round(h * s)))
    down = s < 1.0
    sx, sy = size[0] / w, size[1] / h
    a, b = _resize(rgb1, size, down), _resize(rgb2, size, down)
    f = _resize(flow, size, down) * np.array([sx, sy], np.float32)
    known = np.ones((h, w), np.float32)
    if stick is not None:
        known[cv2.dilate(stick.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0] = 0.0
    known = _resize(known, size, down) > 0.999
    moving = (np.linalg.norm(flow, axis=2) * max(sx, sy) > aug.moving_px).astype(np.float32)
    moving = _resize(moving, size, down)
    y0, x0 = _crop_origin(moving > 0.5, ch, cw, rng, rng.random() < aug.centre_on_motion)
    win = (slice(y0, y0 + ch), slice(x0, x0 + cw))
    a, b, f, known, moving = a[win], b[win], f[win], known[win], moving[win]
    if aug.flip:
        if rng.random() < 0.5:  # left-right
            a, b, f, known, moving = (t[:, ::-1] for t in (a, b, f, known, moving))
            f = f * np.array([-1, 1], np.float32)
        if rng.random() < 0.5:  # up-down
            a, b, f, known, moving = (t[::-1] for t in (a, b, f, known, moving))
            f = f * np.array([1, -1], np.float32)
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    a, b = camera_effects(a, b, aug, rng)
    x, dis, scale = prepare(a, b, model.replace(work_width=max(model.work_width, cw)))
    assert scale == 1.0
    return Sample(
        x=x,
        dis=np.ascontiguousarray(dis.transpose(2, 0, 1)),
        flow=np.ascontiguousarray(f.transpose(2, 0, 1), np.float32),
        valid=np.ascontiguousarray(known, np.float32),
        moving=np.ascontiguousarray(moving, np.float32),
    )


class PairSource:
    """Samples drawn from a list of clips: sample ``i`` of seed ``seed`` is the same whatever
    was drawn before it (its own generator), so a resumed training sees the same data."""

    def __init__(
        self, clips: list[ClipRef], model: LearnedFlowConfig, aug: AugmentConfig, seed: int
    ) -> None:
        if not clips:
            raise RecordingError("no clips to draw training pairs from")
        self.clips, self.model, self.aug, self.seed = clips, model, aug, int(seed)
        self._first: dict[int, np.ndarray] = {}  # clip -> its first image (small LRU)

    def _first_image(self, c: int) -> np.ndarray:
        if c not in self._first:
            if len(self._first) >= 64:
                self._first.pop(next(iter(self._first)))
            self._first[c] = self.clips[c].rgb(self.clips[c].indices[0])
        return self._first[c]

    def sample(self, i: int) -> Sample:
        rng = np.random.default_rng([self.seed, int(i)])
        c = int(rng.integers(len(self.clips)))
        clip = self.clips[c]
        k = clip.indices[int(rng.integers(1, len(clip.indices)))]
        return make_pair(
            clip.rgb(k),
            self._first_image(c),
            clip.flow(k, normal=self.model.target == "normal"),
            clip.stick(k),
            self.model,
            self.aug,
            rng,
        )

    def batch(self, start: int, size: int) -> dict[str, np.ndarray]:
        """Samples ``start`` .. ``start + size - 1`` stacked (arrays with a batch axis)."""
        samples = [self.sample(start + j) for j in range(size)]
        return {
            name: np.stack([getattr(s, name) for s in samples])
            for name in ("x", "dis", "flow", "valid", "moving")
        }
