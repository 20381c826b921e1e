"""Input checks shared by every layer (the ground floor); every failure is an ``InputError``."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from cablesim.config import check_fields
from cablesim.errors import InputError


def _param_error(field: str, message: str) -> InputError:
    return InputError(f"{field}: {message}")


def check_params(params: Any, prefix: str = "") -> None:
    """Check every field of a parameter dataclass against its type hint (finite numbers,
    integers that are not bools, ...); ``InputError`` naming the field and the value."""
    check_fields(params, prefix, _param_error)


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


def as_mask(
    mask: object, shape: tuple[int, int] | None = None, name: str = "mask", binary: bool = False
) -> np.ndarray:
    """Return ``mask`` as an HxW bool array or raise ``InputError``.

    An integer array counts as a mask where it is non-zero; with ``binary`` it must hold only
    0 and 1 (a label image, where -1 is background, is refused rather than read as a mask).
    """
    if not isinstance(mask, np.ndarray):
        raise InputError(f"{name} must be a numpy array, got {type(mask).__name__}")
    if mask.ndim != 2:
        raise InputError(f"{name} must be a 2D HxW array, got shape {mask.shape}")
    if shape is not None and mask.shape != tuple(shape):
        raise InputError(f"{name} has size {mask.shape}, expected {tuple(shape)}")
    if mask.dtype != np.bool_:
        if not (np.issubdtype(mask.dtype, np.integer)):
            raise InputError(f"{name} must be bool or integer 0/1, got {mask.dtype}")
        if binary and mask.size and (mask.min() < 0 or mask.max() > 1):
            raise InputError(
                f"{name} must be a mask (bool, or integers 0/1), got values "
                f"{mask.min()}..{mask.max()}: a label image? compare it with a label first"
            )
        mask = mask != 0
    return mask


def as_image(img: object, name: str = "image") -> np.ndarray:
    """Return an HxW or HxWx3 uint8 image, or raise ``InputError``."""
    if not isinstance(img, np.ndarray):
        raise InputError(f"{name} must be a numpy array, got {type(img).__name__}")
    if img.dtype != np.uint8:
        raise InputError(f"{name} must be uint8, got {img.dtype}")
    if img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (1, 3)):
        if img.shape[0] == 0 or img.shape[1] == 0:
            raise InputError(f"{name} is empty ({img.shape[1]}x{img.shape[0]} px)")
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


def is_real(value: object) -> bool:
    """A real number (Python or NumPy), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def as_real(value: object, name: str, finite: bool = True) -> float:
    """``value`` as a float, or ``InputError`` unless it is a (finite) real number."""
    if not is_real(value):
        raise InputError(f"{name} must be a number, got {value!r}")
    try:
        v = float(value)  # type: ignore[arg-type]
    except OverflowError:  # an integer beyond the float range
        v = math.copysign(math.inf, value)  # type: ignore[arg-type]
    if finite and not math.isfinite(v):
        raise InputError(f"{name} must be finite, got {value!r}")
    return v


def check_positive(value: float, name: str) -> float:
    if not is_real(value):
        raise InputError(f"{name} must be a positive number, got {value!r}")
    v = as_real(value, name, finite=False)
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be positive and finite, got {value!r}")
    return v
