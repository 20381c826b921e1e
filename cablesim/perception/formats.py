"""Compatibility formats (SPEC section 8).

MovingCables flow PNG
    16-bit, 3 channels.  In the PNG's own channel order (R, G, B): channel 1 (R) = flow x
    (columns), channel 2 (G) = flow y (rows), both as ``flow_px = (value - 2**15) / 64``;
    channel 3 (B) = hose instance id.  OpenCV reads and writes BGR, so in the array OpenCV
    returns, index 2 is flow x, index 1 flow y and index 0 the instance id;
    :func:`read_flow_png` / :func:`write_flow_png` handle this.  Instance ids are stored as
    given (uint16); :func:`labels_to_instances` maps cablesim labels (hose i -> i + 1,
    background and robot -> 0).

Real-robot sequence folder (schema ``cablesim-real-sequence`` version 1; the published
schema was not available offline, so this one is documented here and written by
:func:`write_sequence`)::

    actions_gripper.json
      {"format": "cablesim-real-sequence", "version": 1,
       "camera_matrix": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],   # full sensor image
       "crop": [x0, y0, width, height] or null,                  # region of the sensor image
       "image_size": [width, height],                            # size of the stored images
       "depth_scale": 0.001,                                     # metres per depth unit
       "target_mask": "mask.png",                                # hand-labelled grasped hose
       "frames": [{"action": 0, "sample": 0, "timestamp": 0.0,
                   "gripper": [x, y, z],                         # metres, camera frame
                   "rgb": "rgb_000000.png", "depth": "depth_000000.png",
                   "arm": "arm_000000.png" or null}, ...]}      # last frame: action -1
    rgb_*.png      8-bit colour
    depth_*.png    16-bit depth in millimetres (0 = invalid)
    arm_*.png      optional 8-bit arm masks (non-zero = arm)
    mask.png       8-bit grasped-hose mask of the target frame (non-zero = hose)

Intrinsics of the stored images: the crop shifts the principal point, then the images may be
rescaled from the crop size to ``image_size``.  The reader returns a ``Stream`` whose
``meta`` holds ``target_mask`` (bool HxW or None), ``arm_masks`` ({frame index: bool HxW})
and ``crop``.  File problems raise ``RecordingError``; bad arrays ``InputError``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.errors import InputError, RecordingError
from cablesim.perception._checks import as_flow, as_mask
from cablesim.perception.frames import Frame, Intrinsics, Stream

FLOW_OFFSET = 2**15
FLOW_SCALE = 64.0
SEQUENCE_FORMAT = "cablesim-real-sequence"
SEQUENCE_VERSION = 1


# --------------------------------------------------------------------------- flow PNG
def labels_to_instances(labels: np.ndarray) -> np.ndarray:
    """cablesim labels (hose >= 0, background -1, robot -2) -> instance ids (hose + 1, else 0)."""
    labels = np.asarray(labels)
    return np.where(labels >= 0, labels.astype(np.int64) + 1, 0).astype(np.uint16)


def encode_flow_png(flow: np.ndarray, instances: np.ndarray | None = None) -> np.ndarray:
    """HxWx3 uint16 array in OpenCV (BGR) order ready for ``cv2.imwrite``."""
    flow = as_flow(flow)
    lo, hi = -FLOW_OFFSET / FLOW_SCALE, (65535 - FLOW_OFFSET) / FLOW_SCALE
    finite = flow[np.isfinite(flow)]
    if finite.size and (finite.min() < lo or finite.max() > hi):
        raise InputError(
            f"flow of {finite.min():.6g}..{finite.max():.6g} px does not fit a flow PNG "
            f"(range {lo:g}..{hi:.4g} px); it would be clipped"
        )
    h, w = flow.shape[:2]
    out = np.zeros((h, w, 3), np.uint16)
    enc = np.clip(np.rint(np.nan_to_num(flow) * FLOW_SCALE + FLOW_OFFSET), 0, 65535)
    out[..., 2] = enc[..., 0]  # R = x
    out[..., 1] = enc[..., 1]  # G = y
    if instances is not None:
        inst = np.asarray(instances)
        if inst.shape != (h, w):
            raise InputError(f"instances have shape {inst.shape}, expected {(h, w)}")
        if (
            not np.issubdtype(inst.dtype, np.integer)
            or inst.min(initial=0) < 0
            or inst.max(initial=0) > 65535
        ):
            raise InputError("instances must be integers in [0, 65535]")
        out[..., 0] = inst  # B = instance id
    return out


def write_flow_png(path: str | Path, flow: np.ndarray, instances: np.ndarray | None = None) -> None:
    """Write a MovingCables flow PNG (1/64 px resolution, range about +-512 px)."""
    path = Path(path)
    if not cv2.imwrite(str(path), encode_flow_png(flow, instances)):
        raise RecordingError(f"could not write {path}")


def read_flow_png(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(flow HxWx2 float32 px, instance ids HxW uint16) from a MovingCables flow PNG."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"flow PNG not found: {path}")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise RecordingError(f"cannot decode {path} as an image")
    if img.dtype != np.uint16 or img.ndim != 3 or img.shape[2] != 3:
        raise RecordingError(
            f"{path} is not a 16-bit 3-channel PNG (got {img.dtype}, shape {img.shape})"
        )
    flow = np.empty((*img.shape[:2], 2), np.float32)
    flow[..., 0] = (img[..., 2].astype(np.float32) - FLOW_OFFSET) / FLOW_SCALE
    flow[..., 1] = (img[..., 1].astype(np.float32) - FLOW_OFFSET) / FLOW_SCALE
    return flow, img[..., 0].copy()


# --------------------------------------------------------------------------- sequences
def _imwrite(path: Path, img: np.ndarray) -> None:
    if not cv2.imwrite(str(path), img):
        raise RecordingError(f"could not write {path}")


def write_sequence(
    folder: str | Path,
    stream: Stream,
    target_mask: np.ndarray | None = None,
    arm_masks: dict[int, np.ndarray] | None = None,
    crop: tuple[int, int, int, int] | None = None,
    camera_matrix: np.ndarray | None = None,
) -> Path:
    """Write ``stream`` as a real-robot sequence folder (see module docstring).

    ``camera_matrix`` is that of the full sensor image when ``crop`` is given; by default it is
    derived from the stream's intrinsics (shifted back by the crop offset).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    K = stream.intrinsics
    h, w = stream.frames[0].shape
    if camera_matrix is None:
        camera_matrix = K.K.copy()
        if crop is not None:
            if (crop[2], crop[3]) != (w, h):
                raise InputError("give camera_matrix when the images are rescaled from the crop")
            camera_matrix[0, 2] += crop[0]
            camera_matrix[1, 2] += crop[1]
    frames_meta: list[dict[str, Any]] = []
    for i, f in enumerate(stream.frames):
        rgb_name, depth_name = f"rgb_{i:06d}.png", f"depth_{i:06d}.png"
        _imwrite(folder / rgb_name, cv2.cvtColor(f.rgb, cv2.COLOR_RGB2BGR))
        d = np.nan_to_num(f.depth, nan=0.0, posinf=0.0)
        _imwrite(folder / depth_name, np.clip(np.rint(d * 1000.0), 0, 65535).astype(np.uint16))
        arm_name = None
        if arm_masks and i in arm_masks:
            arm_name = f"arm_{i:06d}.png"
            _imwrite(folder / arm_name, as_mask(arm_masks[i], (h, w)).astype(np.uint8) * 255)
        frames_meta.append(
            {
                "action": int(f.action),
                "sample": int(f.sample),
                "timestamp": float(f.timestamp),
                "gripper": [float(x) for x in f.gripper],
                "rgb": rgb_name,
                "depth": depth_name,
                "arm": arm_name,
            }
        )
    mask_name = None
    if target_mask is not None:
        mask_name = "mask.png"
        _imwrite(folder / mask_name, as_mask(target_mask, (h, w)).astype(np.uint8) * 255)
    meta = {
        "format": SEQUENCE_FORMAT,
        "version": SEQUENCE_VERSION,
        "camera_matrix": np.asarray(camera_matrix, float).tolist(),
        "crop": None if crop is None else [int(c) for c in crop],
        "image_size": [w, h],
        "depth_scale": 0.001,
        "target_mask": mask_name,
        "frames": frames_meta,
    }
    (folder / "actions_gripper.json").write_text(json.dumps(meta, indent=1))
    return folder


def _imread(path: Path, flags: int) -> np.ndarray:
    if not path.is_file():
        raise RecordingError(f"missing file {path}")
    img = cv2.imread(str(path), flags)
    if img is None:
        raise RecordingError(f"cannot decode {path} (corrupt or not an image)")
    return img


def _intrinsics(meta: dict[str, Any], w: int, h: int) -> Intrinsics:
    try:
        K = np.asarray(meta["camera_matrix"], float)
        if K.shape != (3, 3):
            raise ValueError(f"camera_matrix has shape {K.shape}")
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        crop = meta.get("crop")
        cw, ch = w, h
        if crop is not None:
            x0, y0, cw, ch = (int(v) for v in crop)
            cx, cy = cx - x0, cy - y0
        base = Intrinsics(fx, fy, cx, cy, cw, ch)
    except (KeyError, TypeError, ValueError, InputError) as e:
        raise RecordingError(f"bad camera_matrix/crop in actions_gripper.json: {e}") from e
    if (cw, ch) != (w, h):
        base = base.scaled(w / cw, h / ch)
    return Intrinsics(base.fx, base.fy, base.cx, base.cy, w, h)


def read_sequence(folder: str | Path) -> Stream:
    """Read a real-robot sequence folder into a ``Stream`` (see module docstring)."""
    folder = Path(folder)
    jpath = folder / "actions_gripper.json"
    if not folder.is_dir():
        raise RecordingError(f"sequence folder not found: {folder}")
    if not jpath.is_file():
        raise RecordingError(f"missing {jpath}")
    try:
        meta = json.loads(jpath.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise RecordingError(f"{jpath} is not valid JSON: {e}") from e
    if not isinstance(meta, dict) or meta.get("format") != SEQUENCE_FORMAT:
        raise RecordingError(
            f"{jpath}: unknown format {meta.get('format') if isinstance(meta, dict) else None!r}"
        )
    if meta.get("version") != SEQUENCE_VERSION:
        raise RecordingError(f"{jpath}: unsupported version {meta.get('version')!r}")
    entries = meta.get("frames")
    if not isinstance(entries, list) or not entries:
        raise RecordingError(f"{jpath}: 'frames' must be a non-empty list")
    scale = float(meta.get("depth_scale", 0.001))
    K: Intrinsics | None = None
    frames: list[Frame] = []
    arm: dict[int, np.ndarray] = {}
    for i, e in enumerate(entries):
        try:
            rgb_name, depth_name = e["rgb"], e["depth"]
            gripper = np.asarray(e["gripper"], float)
            action = int(e["action"])
        except (KeyError, TypeError, ValueError) as ex:
            raise RecordingError(
                f"{jpath}: frame {i} lacks rgb/depth/gripper/action ({ex})"
            ) from ex
        bgr = _imread(folder / rgb_name, cv2.IMREAD_COLOR)
        depth_raw = _imread(folder / depth_name, cv2.IMREAD_UNCHANGED)
        if depth_raw.dtype != np.uint16 or depth_raw.ndim != 2:
            raise RecordingError(f"{folder / depth_name} must be a 16-bit single-channel PNG")
        h, w = bgr.shape[:2]
        if depth_raw.shape != (h, w):
            raise RecordingError(f"frame {i}: depth {depth_raw.shape} and rgb {(h, w)} differ")
        if K is None:
            K = _intrinsics(meta, w, h)
        try:
            frames.append(
                Frame(
                    rgb=cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
                    depth=depth_raw.astype(np.float32) * np.float32(scale),
                    intrinsics=K,
                    gripper=gripper,
                    action=action,
                    sample=int(e.get("sample", 0)),
                    timestamp=float(e.get("timestamp", i)),
                )
            )
        except InputError as ex:
            raise RecordingError(f"{jpath}: frame {i}: {ex}") from ex
        if e.get("arm"):
            arm[i] = _imread(folder / e["arm"], cv2.IMREAD_GRAYSCALE) > 0
    target_mask = None
    if meta.get("target_mask"):
        target_mask = _imread(folder / meta["target_mask"], cv2.IMREAD_GRAYSCALE) > 0
    try:
        return Stream(
            frames,
            {
                "target_mask": target_mask,
                "arm_masks": arm,
                "crop": meta.get("crop"),
                "source": str(folder),
            },
        )
    except InputError as ex:
        raise RecordingError(f"{folder}: {ex}") from ex
