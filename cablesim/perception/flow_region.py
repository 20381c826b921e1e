"""The region where flow is computed: a crop of the camera image, scaled up (SPEC section 8).

The published code computes flow on a crop of the full images, scaled by a factor (INTER_CUBIC),
divides the flow by the factor, scales it back (INTER_CUBIC) and pastes it into a zero flow of
the full image size.  :class:`RegionFlow` wraps any :class:`FlowEstimator` that way; with the
ground-truth back end (``oracle``) the flow is exact already, so only the crop applies (zero
flow outside it).  A :class:`FlowRegion` with neither crop nor scale is the full image.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Frame
from cablesim.perception.flow import FlowEstimator, OracleFlow


@dataclass(frozen=True)
class FlowRegion:
    """``origin`` (x, y) and ``size`` (width, height) of the crop, ``scale`` its up-scaling."""

    origin: tuple[int, int] | None = None
    size: tuple[int, int] | None = None
    scale: float | None = None

    def __post_init__(self) -> None:
        if (self.origin is None) != (self.size is None):
            raise InputError("a flow crop needs both its origin and its size (or neither)")
        if self.origin is not None:
            x, y = (int(v) for v in self.origin)
            w, h = (int(v) for v in self.size)  # type: ignore[union-attr]
            if x < 0 or y < 0 or w <= 0 or h <= 0:
                raise InputError(f"flow crop origin {self.origin} / size {self.size} is invalid")
            object.__setattr__(self, "origin", (x, y))
            object.__setattr__(self, "size", (w, h))
        if self.scale is not None:
            s = float(self.scale)
            if not np.isfinite(s) or s <= 0:
                raise InputError(f"flow scale factor must be positive, got {self.scale!r}")
            object.__setattr__(self, "scale", s)

    @property
    def is_full(self) -> bool:
        return self.origin is None and self.scale is None

    @property
    def crop(self) -> tuple[int, int, int, int] | None:
        """(x, y, width, height) or None."""
        if self.origin is None or self.size is None:
            return None
        return (*self.origin, *self.size)

    def check(self, shape: tuple[int, int]) -> None:
        if self.crop is not None:
            x, y, w, h = self.crop
            if x + w > shape[1] or y + h > shape[0]:
                raise InputError(
                    f"flow crop {self.crop} (x, y, w, h) exceeds the {shape[1]}x{shape[0]} image"
                )

    def to_dict(self) -> dict[str, Any]:
        return {
            "crop_origin": None if self.origin is None else list(self.origin),
            "crop_size": None if self.size is None else list(self.size),
            "scale_factor": self.scale,
        }

    @staticmethod
    def from_crop(
        crop: tuple[int, int, int, int] | None = None, scale: float | None = None
    ) -> FlowRegion:
        """From a crop (x0, y0, width, height) or None (the whole image) and a scale (None or
        1: none), e.g. ``FlowRegion.from_crop(board_region(cfg, K), 1.5)``."""
        if crop is not None and (len(crop) != 4 or any(int(c) != c for c in crop)):
            raise InputError(f"crop must be (x0, y0, width, height) integers, got {crop!r}")
        origin = None if crop is None else (int(crop[0]), int(crop[1]))
        size = None if crop is None else (int(crop[2]), int(crop[3]))
        return FlowRegion(origin, size, None if scale in (None, 1, 1.0) else scale)

    @staticmethod
    def from_meta(meta: dict[str, Any]) -> FlowRegion:
        """From a stream's ``crop_origin`` / ``crop_size`` / ``scale_factor`` (any may be None)."""
        o, s = meta.get("crop_origin"), meta.get("crop_size")
        if o is None or s is None:
            o = s = None
        return FlowRegion(
            None if o is None else tuple(o),
            None if s is None else tuple(s),
            meta.get("scale_factor"),
        )


def crop_and_scale(image: np.ndarray, region: FlowRegion) -> np.ndarray:
    out = image
    if region.crop is not None:
        x, y, w, h = region.crop
        out = image[y : y + h, x : x + w]
    if region.scale is not None:
        s = region.scale
        out = cv2.resize(out, (0, 0), fx=s, fy=s, interpolation=cv2.INTER_CUBIC)
    return np.ascontiguousarray(out)


def descale_and_paste(flow: np.ndarray, region: FlowRegion, shape: tuple[int, int]) -> np.ndarray:
    """Flow of the cropped, scaled images -> flow of the full image (zero outside the crop)."""
    out = flow
    if region.scale is not None:
        inv = 1.0 / region.scale
        out = cv2.resize(out * inv, (0, 0), fx=inv, fy=inv, interpolation=cv2.INTER_CUBIC)
    if region.crop is None:
        if out.shape[:2] != tuple(shape):
            raise InputError(f"scaled flow came back {out.shape[:2]}, the image is {shape}")
        return np.ascontiguousarray(out, np.float32)
    x, y, w, h = region.crop
    if out.shape[:2] != (h, w):
        raise InputError(f"scaled flow came back {out.shape[:2]}, the crop is {(h, w)}")
    full = np.zeros((*shape, 2), np.float32)
    full[y : y + h, x : x + w] = out
    return full


class RegionFlow(FlowEstimator):
    """``inner`` run on the region's crop, scaled; flow pasted into the full image."""

    def __init__(self, inner: FlowEstimator, region: FlowRegion) -> None:
        self.inner = inner
        self.region = region
        self.name = inner.name
        self.image_based = inner.image_based
        self._target: tuple[np.ndarray, np.ndarray] | None = None

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        shape = image1.shape[:2]
        self.region.check(shape)
        if self._target is not None and self._target[0] is image1:
            a = self._target[1]  # the target frame is the first image of every call
        else:
            a = crop_and_scale(image1, self.region)
            self._target = (image1, a)
        b = crop_and_scale(image2, self.region)
        return descale_and_paste(self.inner.compute(a, b), self.region, shape)

    def frame_flow(self, frame: Frame, target: Frame) -> np.ndarray:
        if isinstance(self.inner, OracleFlow):
            self.region.check(target.shape)
            flow = self.inner.frame_flow(frame, target)
            if self.region.crop is not None:
                x, y, w, h = self.region.crop
                out = np.zeros_like(flow)
                out[y : y + h, x : x + w] = flow[y : y + h, x : x + w]
                return out
            return flow
        if frame.shape != target.shape:
            raise InputError(f"frame size {frame.shape} differs from target size {target.shape}")
        return self.compute(target.rgb, frame.rgb)

    def describe(self) -> dict[str, Any]:
        return {**self.inner.describe(), "region": self.region.to_dict()}


def with_region(flow: FlowEstimator, region: FlowRegion | None) -> FlowEstimator:
    """``flow`` computed in ``region`` (unchanged for None or the full image)."""
    if region is None or region.is_full:
        return flow
    return RegionFlow(flow, region)
