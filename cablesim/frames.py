"""Frames and streams: what crosses the sim/real boundary (SPEC section 2).

A ``Frame`` holds one RGB-D image with the gripper position in the camera frame and its
action/sample indices.  A ``Stream`` is the ordered frames of one interaction; its last frame
is the target frame (arm out of view).  Simulated frames may carry ``FrameTruth``; nothing but
evaluation may read it.  Pure NumPy: this module never imports MuJoCo.

Conventions
- camera frame: OpenCV (x right, y down, z forward), metres;
- ``depth``: metric z-depth in metres, float32, 0 or NaN = invalid;
- ``action``: 0, 1, ... for action frames, ``TARGET_ACTION`` (-1) for the target frame;
- ``labels`` (truth): int16, hose index >= 0, ``LABEL_ROBOT`` (-2), ``LABEL_BACKGROUND`` (-1);
- ``arm_mask`` (optional, not truth): HxW bool, the arm model rendered at the frame's joint
  state through the calibrated camera; perception never lets those pixels vote
  (``cablesim.perception.refine``, ``RefineParams.arm_masks``, on by default).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.errors import InputError

TARGET_ACTION = -1
LABEL_BACKGROUND = -1
LABEL_ROBOT = -2


def _finite(v: numbers.Real) -> bool:
    try:
        return math.isfinite(float(v))
    except OverflowError:  # an integer beyond the float range
        return False


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels for an image of ``width`` x ``height``."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if isinstance(v, bool | np.bool_) or not isinstance(v, numbers.Real):
                raise InputError(f"intrinsics.{name} must be a number, got {v!r}")
            if not _finite(v):
                raise InputError(f"intrinsics.{name} must be finite, got {v!r}")
        for name in ("fx", "fy"):
            v = getattr(self, name)
            if v <= 0:
                raise InputError(f"intrinsics.{name} must be a positive focal length, got {v!r}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool | np.bool_) or not isinstance(v, int | np.integer) or v <= 0:
                raise InputError(f"intrinsics.{name} must be a positive integer, got {v!r}")

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], np.float64)

    @property
    def f(self) -> float:
        """Mean focal length in pixels."""
        return 0.5 * (self.fx + self.fy)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame points (...,3) -> pixel coordinates (...,2) (x = column, y = row)."""
        p = np.asarray(points, np.float64)
        z = p[..., 2]
        return np.stack([self.fx * p[..., 0] / z + self.cx, self.fy * p[..., 1] / z + self.cy], -1)

    def backproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels (...,2) with depths (...) -> camera-frame points (...,3)."""
        uv = np.asarray(uv, np.float64)
        z = np.asarray(depth, np.float64)
        x = (uv[..., 0] - self.cx) / self.fx * z
        y = (uv[..., 1] - self.cy) / self.fy * z
        return np.stack([x, y, z], -1)

    def scaled(self, sx: float, sy: float | None = None) -> Intrinsics:
        sy = sx if sy is None else sy
        return Intrinsics(
            self.fx * sx,
            self.fy * sy,
            (self.cx + 0.5) * sx - 0.5,
            (self.cy + 0.5) * sy - 0.5,
            round(self.width * sx),
            round(self.height * sy),
        )

    def to_dict(self) -> dict[str, float]:
        return {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "width": int(self.width),
            "height": int(self.height),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Intrinsics:
        """From ``to_dict`` output (JSON): numbers for the focal lengths and principal point,
        integers (or integral numbers) for the size; ``InputError`` naming the field."""
        if not isinstance(d, dict):
            raise InputError(f"intrinsics must be a mapping, got {d!r}")
        missing = [k for k in ("fx", "fy", "cx", "cy", "width", "height") if k not in d]
        if missing:
            raise InputError(f"intrinsics missing {missing}")
        values: dict[str, Any] = {}
        for k in ("fx", "fy", "cx", "cy", "width", "height"):
            v = d[k]
            if isinstance(v, bool | np.bool_) or not isinstance(v, numbers.Real):
                raise InputError(f"intrinsics.{k} must be a number, got {v!r}")
            if not _finite(v):
                raise InputError(f"intrinsics.{k} must be finite, got {v!r}")
            if k in ("width", "height"):
                if not float(v).is_integer():
                    raise InputError(f"intrinsics.{k} must be a whole number of pixels, got {v!r}")
                v = int(v)
            else:
                v = float(v)
            values[k] = v
        return cls(**values)


@dataclass
class FrameTruth:
    """Simulation ground truth of one frame (SPEC section 6). Evaluation only."""

    labels: np.ndarray  # HxW int16
    grasped_hose: int | None = None
    # HxWx2 float32 in *target-frame* pixels p: target pixel p shows the surface point that was
    # at p + flow in this frame (SPEC section 4's phi; computed from the target to this frame)
    flow_to_target: np.ndarray | None = None
    flow_valid: np.ndarray | None = None  # HxW bool
    extra: dict[str, Any] = field(default_factory=dict)

    def hose_mask(self, hose: int) -> np.ndarray:
        return self.labels == hose

    @property
    def robot_mask(self) -> np.ndarray:
        return self.labels == LABEL_ROBOT


@dataclass
class Frame:
    """One RGB-D frame of an interaction stream."""

    rgb: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics
    gripper: np.ndarray  # (3,) metres, camera frame
    action: int = TARGET_ACTION
    sample: int = 0
    timestamp: float = 0.0
    gripper_quat: np.ndarray | None = None  # (4,) wxyz, camera frame
    gripper_opening: float | None = None  # metres
    truth: FrameTruth | None = None
    # HxW bool: the arm rendered from the joint state at this frame through the calibrated
    # camera (cablesim.panda.arm_mask), the same in simulation and on the real robot; not truth
    arm_mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        validate_rgbd(self.rgb, self.depth, self.intrinsics)
        for name in ("action", "sample"):
            v = getattr(self, name)
            if isinstance(v, bool | np.bool_) or not isinstance(v, int | np.integer):
                raise InputError(f"frame {name} must be an integer, got {v!r}")
        t = self.timestamp
        if isinstance(t, bool | np.bool_) or not isinstance(t, numbers.Real):
            raise InputError(f"frame timestamp must be a number, got {t!r}")
        if not _finite(t):
            raise InputError(f"frame timestamp must be finite, got {t!r}")
        try:
            g = np.asarray(self.gripper, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"gripper must be 3 numbers, got {self.gripper!r}") from e
        if g.shape != (3,):
            raise InputError(f"gripper must have shape (3,), got {g.shape}")
        self.gripper = g
        if self.gripper_quat is not None:
            q = np.asarray(self.gripper_quat)
            if q.shape != (4,) or not np.issubdtype(q.dtype, np.number):
                raise InputError(f"gripper_quat must be 4 numbers (wxyz), got {q.dtype} {q.shape}")
        if self.gripper_opening is not None:
            v = self.gripper_opening
            if isinstance(v, bool | np.bool_) or not isinstance(v, numbers.Real):
                raise InputError(f"gripper_opening must be a number, got {v!r}")
        if self.truth is not None:
            check_truth(self.truth, self.rgb.shape[:2])
        if self.arm_mask is not None:
            m = np.asarray(self.arm_mask)
            if m.shape != self.rgb.shape[:2]:
                raise InputError(f"arm_mask must have shape {self.rgb.shape[:2]}, got {m.shape}")
            if m.dtype != bool:
                raise InputError(f"arm_mask must be a bool mask, got {m.dtype}")
            self.arm_mask = m

    @property
    def is_target(self) -> bool:
        return self.action == TARGET_ACTION

    @property
    def shape(self) -> tuple[int, int]:
        return self.rgb.shape[:2]


def check_truth(truth: FrameTruth, shape: tuple[int, int]) -> None:
    """``InputError`` unless the ground truth fits an image of ``shape`` (HxW)."""
    if not isinstance(truth, FrameTruth):
        raise InputError(f"truth must be a FrameTruth, got {type(truth).__name__}")
    labels = truth.labels
    if not isinstance(labels, np.ndarray) or not np.issubdtype(labels.dtype, np.integer):
        raise InputError(f"truth labels must be an integer array, got {type(labels).__name__}")
    if labels.shape != tuple(shape):
        raise InputError(f"truth labels have shape {labels.shape}, the image is {tuple(shape)}")
    gh = truth.grasped_hose
    if gh is not None and (isinstance(gh, bool) or not isinstance(gh, int | np.integer)):
        raise InputError(f"truth grasped_hose must be an integer or None, got {gh!r}")
    if truth.flow_to_target is not None:
        flow = truth.flow_to_target
        if not isinstance(flow, np.ndarray) or flow.shape != (*shape, 2):
            raise InputError(
                f"truth flow_to_target has shape {getattr(flow, 'shape', None)}, "
                f"expected {(*shape, 2)}"
            )
    if truth.flow_valid is not None:
        valid = truth.flow_valid
        if not isinstance(valid, np.ndarray) or valid.shape != tuple(shape):
            raise InputError(
                f"truth flow_valid has shape {getattr(valid, 'shape', None)}, expected {shape}"
            )


def validate_rgbd(rgb: np.ndarray, depth: np.ndarray | None, intrinsics: Intrinsics | None) -> None:
    """Raise ``InputError`` naming the problem unless rgb/depth/intrinsics are consistent."""
    if not isinstance(rgb, np.ndarray) or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"rgb must be an HxWx3 array, got shape {getattr(rgb, 'shape', None)}")
    if rgb.dtype != np.uint8:
        raise InputError(f"rgb must be uint8, got {rgb.dtype}")
    if intrinsics is None:
        raise InputError("intrinsics are missing")
    if not isinstance(intrinsics, Intrinsics):
        raise InputError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")
    h, w = rgb.shape[:2]
    if (intrinsics.width, intrinsics.height) != (w, h):
        raise InputError(
            f"intrinsics are for {intrinsics.width}x{intrinsics.height} but the image is {w}x{h}"
        )
    if depth is not None:
        if not isinstance(depth, np.ndarray) or depth.shape != (h, w):
            raise InputError(f"depth must have shape {(h, w)}, got {getattr(depth, 'shape', None)}")
        if depth.dtype != np.float32:
            raise InputError(f"depth must be float32 metres, got {depth.dtype}")
        if np.any(depth < 0):
            raise InputError("depth has negative values (expected metres, 0 or NaN = invalid)")


@dataclass
class Stream:
    """The frames of one interaction, in time order; the last one is the target frame."""

    frames: list[Frame]
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.frames, list):
            self.frames = list(self.frames)
        if not self.frames:
            raise InputError("a stream needs at least one frame")
        for i, f in enumerate(self.frames):
            if not isinstance(f, Frame):
                raise InputError(f"frame {i} is a {type(f).__name__}, not a Frame")
        shape = self.frames[0].shape
        intrinsics = self.frames[0].intrinsics
        for i, f in enumerate(self.frames):
            if f.shape != shape:
                raise InputError(f"frame {i} has size {f.shape}, the stream is {shape}")
            if f.intrinsics != intrinsics:
                raise InputError(
                    f"frame {i} has other intrinsics than frame 0 ({f.intrinsics} vs {intrinsics})"
                )

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self) -> Iterator[Frame]:
        return iter(self.frames)

    @property
    def target(self) -> Frame:
        t = self.frames[-1]
        if not t.is_target:
            raise InputError("the stream has no target frame (last frame has action != -1)")
        return t

    @property
    def intrinsics(self) -> Intrinsics:
        return self.frames[0].intrinsics

    @property
    def actions(self) -> list[int]:
        return sorted({f.action for f in self.frames if not f.is_target})

    def action_frames(self, action: int) -> list[Frame]:
        return [f for f in self.frames if f.action == action]

    @staticmethod
    def from_frames(frames: Sequence[Frame], **meta: Any) -> Stream:
        return Stream(list(frames), dict(meta))
