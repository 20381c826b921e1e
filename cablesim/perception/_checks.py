"""Input validation shared by the perception modules; every failure is an ``InputError``."""

from __future__ import annotations

import numpy as np

from cablesim.errors import InputError


def as_flow(flow: object, shape: tuple[int, int] | None = None, name: str = "flow") -> np.ndarray:
    """Return ``flow`` as a C-contiguous HxWx2 float32 array or raise ``InputError``."""
    if not isinstance(flow, np.ndarray):
        raise InputError(f"{name} must be a numpy array, got {type(flow).__name__}")
    if flow.ndim != 3 or flow.shape[2] != 2:
        raise InputError(f"{name} must have shape HxWx2, got {flow.shape}")
    if shape is not None and flow.shape[:2] != tuple(shape):
        raise InputError(f"{name} has size {flow.shape[:2]}, expected {tuple(shape)}")
    if not np.issubdtype(flow.dtype, np.floating):
        raise InputError(f"{name} must be a floating-point array, got {flow.dtype}")
    return np.ascontiguousarray(flow, dtype=np.float32)


def as_mask(mask: object, shape: tuple[int, int] | None = None, name: str = "mask") -> np.ndarray:
    """Return ``mask`` as an HxW bool array or raise ``InputError``."""
    if not isinstance(mask, np.ndarray):
        raise InputError(f"{name} must be a numpy array, got {type(mask).__name__}")
    if mask.ndim != 2:
        raise InputError(f"{name} must be a 2D HxW array, got shape {mask.shape}")
    if shape is not None and mask.shape != tuple(shape):
        raise InputError(f"{name} has size {mask.shape}, expected {tuple(shape)}")
    if mask.dtype != np.bool_:
        if not (np.issubdtype(mask.dtype, np.integer)):
            raise InputError(f"{name} must be bool or integer 0/1, got {mask.dtype}")
        mask = mask != 0
    return mask


def as_image(img: object, name: str = "image") -> np.ndarray:
    """Return an HxW or HxWx3 uint8 image, or raise ``InputError``."""
    if not isinstance(img, np.ndarray):
        raise InputError(f"{name} must be a numpy array, got {type(img).__name__}")
    if img.dtype != np.uint8:
        raise InputError(f"{name} must be uint8, got {img.dtype}")
    if img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (1, 3)):
        return img
    raise InputError(f"{name} must be HxW or HxWx3, got shape {img.shape}")


def as_depth(
    depth: object, shape: tuple[int, int] | None = None, name: str = "depth"
) -> np.ndarray:
    """Return an HxW float32 metric depth (0/NaN invalid) or raise ``InputError``."""
    if not isinstance(depth, np.ndarray):
        raise InputError(f"{name} must be a numpy array, got {type(depth).__name__}")
    if depth.ndim != 2:
        raise InputError(f"{name} must be HxW, got shape {depth.shape}")
    if shape is not None and depth.shape != tuple(shape):
        raise InputError(f"{name} has size {depth.shape}, expected {tuple(shape)}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise InputError(f"{name} must be float metres, got {depth.dtype}")
    return depth


def valid_depth(depth: np.ndarray) -> np.ndarray:
    """Pixels with usable depth: finite and > 0."""
    return np.isfinite(depth) & (depth > 0)


def check_positive(value: float, name: str) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be positive and finite, got {value!r}")
    return v
