"""The published motion-correlation sequences (holesond/cmcor, the CMCor dataset; SPEC section 8).

One sequence is a folder named by its recording time (``2024-08-06-153012``)::

    actions_gripper.json       one object, one entry per image (no per-frame records):
                               action_buffer    [int, ...]        -1 = not part of an action
                               ee_point_buffer  [[x, y, z], ...]  gripper, robot base frame, m
                               crop_origin [x, y], crop_size [w, h], scale_factor  (may be null)
                               camera_matrix    3x3               (optional; f = [0][0])
                               robot_base_to_camera_transform 4x4 (optional; camera point =
                                                                   T [base point; 1])
                               legacy, optional: focal_length, gripper_depth, poor_arm_masks
    rgb_%08d.png               colour images from 00000000 until the first missing number
    depth_%08d.png             uint16 millimetres (optional, per image)
    arm_%08d.png               arm mask 0/255 (optional; not read when poor_arm_masks is true)
    grasped_cable_00000000.png the given segment in the first image (> 0)

The last image is the target, whatever its action code.  Crop and scale are not applied to the
stored images: they define where flow is computed and where the evaluation counts pixels.
Without intrinsics the published code takes f = 644.3 px; without a transform the gripper depth
is ``gripper_depth`` or 1.1 m.

Ground truth lives outside the sequence: ``annotations/{validation,test}/<sequence>/
cable_mask_DDDDDDDD.png`` (> 0 = grasped hose, DDDDDDDD the last image's number; the dataset
calls the folder ``motion_correlation_annotations`` beside ``motion_correlation_buffers``), and
``multigrasp_sequences.json`` lists groups of sequences explored on the same hose.

:func:`read_mcor` gives a :class:`McorSequence`: a cablesim :class:`Stream` (gripper in the
camera frame: transformed when the file has the transform, else the base-frame points shifted
so that the first action point sits at (0, 0, Z); negative codes become -1, the target's own
code is kept in ``meta["target_action"]``; a missing depth image is all zeros = invalid), the
given segment, the arm masks and the annotation (also attached to the target frame as
:class:`FrameTruth` with the hose as label 0).  :func:`write_mcor` writes a stream the way the
published ``save_buffer_to_disk`` does (JSON with sorted keys, indent 4; colour as OpenCV
writes it; ``poor_arm_masks: true`` when there are no arm masks, which the published reader
otherwise requires).
"""

from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.checks import as_mask
from cablesim.errors import InputError, RecordingError
from cablesim.files import write_image, write_text
from cablesim.frames import (
    LABEL_BACKGROUND,
    TARGET_ACTION,
    Frame,
    FrameTruth,
    Intrinsics,
    Stream,
)
from cablesim.perception.published import DEFAULT_FOCAL, DEFAULT_GRIPPER_DEPTH

JSON_NAME = "actions_gripper.json"
SEGMENT_NAME = "grasped_cable_00000000.png"
SPLITS = ("validation", "test")
ANNOTATION_DIRS = ("motion_correlation_annotations", "annotations")
LAYOUT = "mcor"


def sequence_name(when: dt.datetime) -> str:
    """The published folder name of a sequence recorded at ``when``: ``YYYY-MM-DD-HHMMSS``."""
    return when.strftime("%Y-%m-%d-%H%M%S")


def _img(kind: str, i: int) -> str:
    return f"{kind}_{i:08d}.png"


def transform_point(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``T [p; 1]``, divided by its last coordinate (the published ``transform_point_to_point``)."""
    p4 = np.ones((4, 1))
    p4[0:3, 0] = p[:]
    r = T.dot(p4)
    r = r / r[-1, 0]
    return r[0:3, 0]


# --------------------------------------------------------------------------- the JSON file
@dataclass
class McorMeta:
    """The content of ``actions_gripper.json``."""

    action_buffer: list[int]
    ee_point_buffer: np.ndarray  # N x 3, base frame
    crop_origin: list[int] | None = None
    crop_size: list[int] | None = None
    scale_factor: float | None = None
    camera_matrix: np.ndarray | None = None
    base_to_camera: np.ndarray | None = None
    focal_length: float | None = None  # legacy
    gripper_depth: float | None = None  # legacy
    poor_arm_masks: bool = False
    extra: dict[str, Any] = field(default_factory=dict)  # keys cablesim does not know

    @property
    def focal(self) -> tuple[float, str]:
        """(f, source) as the published code picks it."""
        if self.camera_matrix is not None:
            return float(self.camera_matrix[0][0]), "camera_matrix"
        if self.focal_length is not None:
            return float(self.focal_length), "focal_length"
        return DEFAULT_FOCAL, "default"

    @property
    def depth(self) -> tuple[float, str]:
        """(Z, source): camera z of the first action frame's gripper, else the legacy number,
        else 1.1 m."""
        idx = [i for i, a in enumerate(self.action_buffer) if a >= 0]
        if self.base_to_camera is not None and idx:
            return float(transform_point(self.base_to_camera, self.ee_point_buffer[idx[0]])[2]), (
                "transform"
            )
        if self.gripper_depth is not None:
            return float(self.gripper_depth), "gripper_depth"
        return DEFAULT_GRIPPER_DEPTH, "default"


_KNOWN = {
    "action_buffer",
    "ee_point_buffer",
    "crop_origin",
    "crop_size",
    "scale_factor",
    "camera_matrix",
    "robot_base_to_camera_transform",
    "focal_length",
    "gripper_depth",
    "poor_arm_masks",
}


def _matrix(d: dict[str, Any], key: str, shape: tuple[int, int], where: Path) -> np.ndarray | None:
    if d.get(key) is None:
        return None
    try:
        m = np.asarray(d[key], np.float64)
    except (TypeError, ValueError) as e:
        raise RecordingError(f"{where}: {key} is not a numeric matrix ({e})") from e
    if m.shape != shape or not np.all(np.isfinite(m)):
        raise RecordingError(f"{where}: {key} must be a finite {shape[0]}x{shape[1]} matrix")
    return m


def _pair(d: dict[str, Any], key: str, where: Path) -> list[int] | None:
    v = d.get(key)
    if v is None:
        return None
    if not isinstance(v, list) or len(v) != 2 or not all(isinstance(x, int | float) for x in v):
        raise RecordingError(f"{where}: {key} must be [int, int] or null, got {v!r}")
    return [int(x) for x in v]


def read_mcor_json(folder: str | os.PathLike[str]) -> McorMeta:
    """Parse and check ``actions_gripper.json`` of a sequence folder."""
    where = Path(folder) / JSON_NAME
    if not where.is_file():
        raise RecordingError(f"{where}: missing (not a motion-correlation sequence)")
    try:
        d = json.loads(where.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RecordingError(f"{where}: not valid JSON ({e})") from e
    if not isinstance(d, dict):
        raise RecordingError(f"{where}: expected one JSON object")
    for key in ("action_buffer", "ee_point_buffer"):
        if not isinstance(d.get(key), list):
            raise RecordingError(f"{where}: {key} must be a list (one entry per image)")
    acts = d["action_buffer"]
    if not all(isinstance(a, int) and not isinstance(a, bool) for a in acts):
        raise RecordingError(f"{where}: action_buffer must hold integers")
    try:
        ee = np.asarray(d["ee_point_buffer"], np.float64).reshape(len(d["ee_point_buffer"]), -1)
    except (TypeError, ValueError) as e:
        raise RecordingError(f"{where}: ee_point_buffer must hold [x, y, z] points ({e})") from e
    if ee.shape[1:] != (3,) or not np.all(np.isfinite(ee)):
        raise RecordingError(f"{where}: ee_point_buffer must hold finite [x, y, z] points")
    if len(acts) != len(ee):
        raise RecordingError(
            f"{where}: {len(acts)} actions but {len(ee)} gripper points (one each per image)"
        )
    scale = d.get("scale_factor")
    if scale is not None and (not isinstance(scale, int | float) or scale <= 0):
        raise RecordingError(f"{where}: scale_factor must be a positive number or null")
    for key in ("focal_length", "gripper_depth"):
        v = d.get(key)
        if v is not None and (not isinstance(v, int | float) or v <= 0):
            raise RecordingError(f"{where}: {key} must be a positive number, got {v!r}")
    return McorMeta(
        action_buffer=[int(a) for a in acts],
        ee_point_buffer=ee,
        crop_origin=_pair(d, "crop_origin", where),
        crop_size=_pair(d, "crop_size", where),
        scale_factor=None if scale is None else float(scale),
        camera_matrix=_matrix(d, "camera_matrix", (3, 3), where),
        base_to_camera=_matrix(d, "robot_base_to_camera_transform", (4, 4), where),
        focal_length=d.get("focal_length"),
        gripper_depth=d.get("gripper_depth"),
        poor_arm_masks=bool(d.get("poor_arm_masks", False)),
        extra={k: v for k, v in d.items() if k not in _KNOWN},
    )


# --------------------------------------------------------------------------- reading
@dataclass
class McorSequence:
    """A sequence read from the published layout (module docstring)."""

    stream: Stream
    meta: McorMeta
    segment: np.ndarray | None = None  # the given segment in the first image
    arm_masks: dict[int, np.ndarray] = field(default_factory=dict)
    truth: np.ndarray | None = None  # the grasped hose in the target (annotation)
    annotation: Path | None = None

    @property
    def crop(self) -> tuple[int, int, int, int] | None:
        """(x, y, w, h) where the published evaluation counts pixels, or None."""
        if self.meta.crop_origin is None or self.meta.crop_size is None:
            return None
        return (*self.meta.crop_origin, *self.meta.crop_size)


def _read(path: Path, flags: int) -> np.ndarray:
    img = cv2.imread(str(path), flags)
    if img is None:
        raise RecordingError(f"{path}: cannot decode (corrupt or not an image)")
    return img


def _mask(path: Path) -> np.ndarray:
    m = _read(path, cv2.IMREAD_UNCHANGED)
    return (m if m.ndim == 2 else m.max(axis=2)) > 0


def find_annotation(
    folder: str | os.PathLike[str], annotations: str | os.PathLike[str] | None = "auto"
) -> Path | None:
    """The ground-truth mask of a sequence: ``annotations/<split>/<name>/cable_mask_*.png``.

    ``annotations`` is the annotations root (holding ``validation`` and ``test``), ``None``
    for none, or ``"auto"``: ``motion_correlation_annotations`` or ``annotations`` beside the
    folder holding the sequence, or inside it.  Within the sequence's folder the mask of the
    last image is taken, else the first ``cable_mask_*.png`` by name (as published).
    """
    folder = Path(folder)
    if annotations is None:
        return None
    if annotations == "auto":
        roots = [folder.parent.parent / d for d in ANNOTATION_DIRS]
        roots += [folder.parent / d for d in ANNOTATION_DIRS]
    else:
        roots = [Path(annotations)]
        if not roots[0].is_dir():
            raise RecordingError(f"annotations root not found: {roots[0]}")
    n_images = 0
    while (folder / _img("rgb", n_images)).is_file():
        n_images += 1
    for root in roots:
        for split in (*SPLITS, ""):
            d = root / split / folder.name if split else root / folder.name
            if not d.is_dir():
                continue
            last = d / f"cable_mask_{max(n_images - 1, 0):08d}.png"
            if last.is_file():
                return last
            masks = sorted(p for p in d.iterdir() if p.name.startswith("cable_mask_"))
            if masks:
                return masks[0]
    return None


def read_annotation(path: str | os.PathLike[str]) -> np.ndarray:
    """A ground-truth mask (> 0 = grasped hose)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"annotation not found: {path}")
    return _mask(path)


def read_mcor(
    folder: str | os.PathLike[str], annotations: str | os.PathLike[str] | None = "auto"
) -> McorSequence:
    """Read a sequence folder of the published layout (module docstring)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise RecordingError(f"sequence folder not found: {folder}")
    meta = read_mcor_json(folder)
    n = 0
    while (folder / _img("rgb", n)).is_file():
        n += 1
    if n != len(meta.action_buffer):
        raise RecordingError(
            f"{folder}: {n} images rgb_00000000.png... but {len(meta.action_buffer)} entries "
            f"in {JSON_NAME}"
        )
    if n == 0:
        raise RecordingError(f"{folder}: no images (rgb_00000000.png is missing)")
    first = _read(folder / _img("rgb", 0), cv2.IMREAD_COLOR)
    h, w = first.shape[:2]
    f, f_src = meta.focal
    if meta.camera_matrix is not None:
        K = meta.camera_matrix
        intr = Intrinsics(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), w, h)
    else:
        intr = Intrinsics(f, f, (w - 1) / 2, (h - 1) / 2, w, h)
    z, z_src = meta.depth
    ee = meta.ee_point_buffer
    if meta.base_to_camera is not None:
        grip = np.array([transform_point(meta.base_to_camera, p) for p in ee])
        frame_kind = "camera"
    else:
        idx = [i for i, a in enumerate(meta.action_buffer) if a >= 0]
        origin = ee[idx[0] if idx else 0]
        grip = ee - origin + np.array([0.0, 0.0, z])
        frame_kind = "base-shifted"
    frames: list[Frame] = []
    arm: dict[int, np.ndarray] = {}
    has_depth = False
    counters: dict[int, int] = {}
    for i in range(n):
        bgr = first if i == 0 else _read(folder / _img("rgb", i), cv2.IMREAD_COLOR)
        if bgr.shape[:2] != (h, w):
            raise RecordingError(f"{folder / _img('rgb', i)}: size {bgr.shape[:2]}, not {(h, w)}")
        dpath = folder / _img("depth", i)
        depth = np.zeros((h, w), np.float32)
        if dpath.is_file():
            raw = _read(dpath, cv2.IMREAD_UNCHANGED)
            if raw.dtype != np.uint16 or raw.shape != (h, w):
                raise RecordingError(f"{dpath}: expected {w}x{h} uint16 millimetres")
            depth = raw.astype(np.float32) * np.float32(0.001)
            has_depth = True
        apath = folder / _img("arm", i)
        if not meta.poor_arm_masks and apath.is_file():
            arm[i] = _mask(apath)
        code = meta.action_buffer[i]
        action = TARGET_ACTION if (code < 0 or i == n - 1) else code
        k = counters.get(action, 0)
        counters[action] = k + 1
        frames.append(
            Frame(
                rgb=np.ascontiguousarray(bgr[..., ::-1]),
                depth=depth,
                intrinsics=intr,
                gripper=grip[i],
                action=action,
                sample=k,
                timestamp=float(i),
            )
        )
    seg_path = folder / SEGMENT_NAME
    segment = _mask(seg_path) if seg_path.is_file() else None
    ann = find_annotation(folder, annotations)
    truth = None
    if ann is not None:
        truth = read_annotation(ann)
        if truth.shape != (h, w):
            raise RecordingError(f"{ann}: size {truth.shape}, the images are {(h, w)}")
        labels = np.where(truth, 0, LABEL_BACKGROUND).astype(np.int16)
        frames[-1].truth = FrameTruth(labels=labels, grasped_hose=0)
    stream_meta = {
        "layout": LAYOUT,
        "source": str(folder),
        "sequence": folder.name,
        "crop_origin": meta.crop_origin,
        "crop_size": meta.crop_size,
        "scale_factor": meta.scale_factor,
        "target_action": meta.action_buffer[-1],
        "action_buffer": list(meta.action_buffer),
        "gripper_frame": frame_kind,
        "gripper_depth": z,
        "gripper_depth_source": z_src,
        "focal_length": f,
        "focal_source": f_src,
        "has_depth": has_depth,
        "annotation": None if ann is None else str(ann),
    }
    return McorSequence(
        stream=Stream(frames, stream_meta),
        meta=meta,
        segment=segment,
        arm_masks=arm,
        truth=truth,
        annotation=ann,
    )


# --------------------------------------------------------------------------- writing
def _write(path: Path, img: np.ndarray) -> None:
    write_image(path, img)  # atomic; a full disk is a DiskFullError naming the file


def write_mcor(
    folder: str | os.PathLike[str],
    stream: Stream,
    segment: np.ndarray | None = None,
    arm_masks: dict[int, np.ndarray] | None = None,
    base_to_camera: np.ndarray | None = None,
    crop_origin: Sequence[int] | None = None,
    crop_size: Sequence[int] | None = None,
    scale_factor: float | None = None,
    depth: bool = True,
    target_action: int | None = None,
    overwrite: bool = False,
) -> Path:
    """Write ``stream`` as a sequence of the published layout (module docstring).

    ``base_to_camera`` (4x4, camera point = T [base point; 1]) gives the base-frame gripper
    points; without it the camera frame is the base frame and the identity is written, so the
    published reader finds the gripper depth.  ``segment`` is the given segment in the first
    image (an empty mask when None).  ``target_action`` is the last entry of
    ``action_buffer`` (default ``stream.meta["target_action"]``, else -1).
    """
    folder = Path(folder)
    if (folder / JSON_NAME).exists() and not overwrite:
        raise RecordingError(f"{folder / JSON_NAME} exists (use overwrite)")
    folder.mkdir(parents=True, exist_ok=True)
    h, w = stream.frames[0].shape
    T = np.eye(4) if base_to_camera is None else np.asarray(base_to_camera, np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError(f"base_to_camera must be a finite 4x4 matrix, got shape {T.shape}")
    T_inv = np.linalg.inv(T)
    if (crop_origin is None) != (crop_size is None):
        raise InputError("give both crop_origin and crop_size, or neither")
    if target_action is None:
        target_action = int(stream.meta.get("target_action", TARGET_ACTION))
    actions = [int(f.action) if f.action >= 0 else -1 for f in stream.frames]
    actions[-1] = int(target_action)
    ee = [
        [
            float(x)
            for x in (
                transform_point(T_inv, f.gripper) if base_to_camera is not None else f.gripper
            )
        ]
        for f in stream.frames
    ]
    doc: dict[str, Any] = {
        "action_buffer": actions,
        "ee_point_buffer": ee,
        "crop_origin": None if crop_origin is None else [int(v) for v in crop_origin],
        "crop_size": None if crop_size is None else [int(v) for v in crop_size],
        "scale_factor": None if scale_factor is None else float(scale_factor),
        "camera_matrix": stream.intrinsics.K.tolist(),
        "robot_base_to_camera_transform": T.tolist(),
    }
    if not arm_masks:
        doc["poor_arm_masks"] = True
    seg = np.zeros((h, w), bool) if segment is None else as_mask(segment, (h, w), name="segment")
    _write(folder / SEGMENT_NAME, seg.astype(np.uint8) * 255)
    for i, f in enumerate(stream.frames):
        _write(folder / _img("rgb", i), np.ascontiguousarray(f.rgb[..., ::-1]))
        if arm_masks:
            if i not in arm_masks:
                raise InputError(f"arm masks are given but not for image {i}")
            m = as_mask(arm_masks[i], (h, w), name=f"arm mask {i}")
            _write(folder / _img("arm", i), m.astype(np.uint8) * 255)
        if depth:
            d = np.nan_to_num(f.depth, nan=0.0, posinf=0.0, neginf=0.0)
            mm = np.clip(np.rint(d * 1000.0), 0, 65535).astype(np.uint16)
            _write(folder / _img("depth", i), mm)
    write_text(folder / JSON_NAME, json.dumps(doc, sort_keys=True, indent=4))
    return folder


def write_annotation(
    root: str | os.PathLike[str], split: str, sequence: str, index: int, mask: np.ndarray
) -> Path:
    """Write ``root/split/sequence/cable_mask_DDDDDDDD.png`` (DDDDDDDD = the last image's
    number)."""
    if split not in SPLITS:
        raise InputError(f"split must be one of {SPLITS}, got {split!r}")
    d = Path(root) / split / sequence
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"cable_mask_{int(index):08d}.png"
    _write(path, as_mask(mask, name="annotation").astype(np.uint8) * 255)
    return path


# --------------------------------------------------------------------------- multiple grasps
def read_multigrasp(path: str | os.PathLike[str]) -> list[list[str]]:
    """``multigrasp_sequences.json``: a list of lists of sequence names (same hose each)."""
    path = Path(path)
    try:
        groups = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RecordingError(f"{path}: unreadable ({e})") from e
    if not isinstance(groups, list) or not all(
        isinstance(g, list) and g and all(isinstance(n, str) for n in g) for g in groups
    ):
        raise RecordingError(f"{path}: expected a list of non-empty lists of sequence names")
    return groups


def write_multigrasp(path: str | os.PathLike[str], groups: Sequence[Sequence[str]]) -> Path:
    """Write a multi-grasp list (each group: the sequences of one hose, in grasp order)."""
    out = [[str(n) for n in g] for g in groups]
    if not all(out):
        raise InputError("every multi-grasp group needs at least one sequence")
    path = Path(path)
    path.write_text(json.dumps(out, indent=4))
    return path


def multigrasp_name(names: Sequence[str]) -> str:
    """The published result-folder name of a group: common prefix, then each name's rest."""
    prefix = os.path.commonprefix(list(names))
    return "-".join([prefix] + [n[len(prefix) :] for n in names])


def retarget(stream: Stream, target: Frame, target_action: int = TARGET_ACTION) -> Stream:
    """``stream`` evaluated in another target frame (a later grasp's), as the published
    multi-grasp evaluation does: the frame is appended as the new last image (the old last
    image keeps its own action code) and ``target_action`` is its code."""
    frames = [*stream.frames[:-1]]
    last = stream.frames[-1]
    own = int(stream.meta.get("target_action", TARGET_ACTION))
    frames.append(
        Frame(
            rgb=last.rgb,
            depth=last.depth,
            intrinsics=last.intrinsics,
            gripper=last.gripper,
            action=own if own >= 0 else TARGET_ACTION,
            sample=last.sample,
            timestamp=last.timestamp,
        )
    )
    frames.append(target)
    meta = dict(stream.meta)
    meta["target_action"] = int(target_action)
    if "action_buffer" in meta:
        meta["action_buffer"] = [*meta["action_buffer"], int(target_action)]
    return Stream(frames, meta)
