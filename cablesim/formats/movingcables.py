"""MovingCables folders and flow PNGs, as published (holesond/movingcables; SPEC section 8).

Layout of one split (``test``, ``train`` or ``validation``)::

    split/rgb_clips/NNNN/DDDDDDDD.png              colour images (``rgba_clips``/``clips`` also read)
    split/flow_first_back/NNNN/DDDDDDDD.png        ground-truth optical flow (flow PNG)
    split/normal_flow_first_back/NNNN/DDDDDDDD.png ground-truth normal flow (flow PNG)
    split/stick_masks/NNNN/DDDDDDDD.png            poking-stick mask (non-zero = stick)

``NNNN`` is the clip number (from 0001), ``DDDDDDDD`` the image number: odd numbers only, from
00000001.  Flow goes from each image **back to the first**: ``current(p) ~ first(p + flow(p))``
(OpenCV's convention with the current image first).

Flow PNG: 16-bit, 3 channels in RGB order (channel 0 = x, 1 = y, as the PNG stores them; OpenCV
returns them reversed, which :func:`read_flow_png` undoes).  ``x`` and ``y`` are written as
``floor(flow * 64 + 2**15)`` clipped to [0, 65535] (computed in float32, as the published
``flow2uint16``) and read as ``(v - 2**15) / 64`` px.  The third channel is the cable instance id
(0 = background) in ground truth, and in *predicted*-flow PNGs the encoded magnitude of the
flow uncertainty (``floor(u * 64 + 2**15)``) or, without uncertainty, the encoded value -1.

:func:`evaluate_clip` runs the published evaluation protocol of a flow back end on one clip
(the numbers come from :func:`cablesim.perception.metrics.movingcables_frame`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from cablesim.checks import as_flow, as_mask
from cablesim.errors import InputError, RecordingError
from cablesim.files import write_image
from cablesim.perception.flow import FlowEstimator, make_flow
from cablesim.perception.metrics import (
    FlowFrameStats,
    MovingCablesSummary,
    movingcables_frame,
    movingcables_summary,
)

FLOW_OFFSET = 2**15
FLOW_SCALE = 64
RGB_FOLDERS = ("rgb_clips", "rgba_clips", "clips")
FLOW_FOLDER = "flow_first_back"
NORMAL_FLOW_FOLDER = "normal_flow_first_back"
STICK_FOLDER = "stick_masks"
# the flow-magnitude thresholds the published evaluation uses per method (pixels)
MOVING_THRESHOLDS: dict[str, float] = {"mfnprob": 2.0, "maskflownet": 2.5, "farneback": 1.0}
STATIC_THRESHOLD = 1.0


# --------------------------------------------------------------------------- flow PNG
def encode_values(values: np.ndarray) -> np.ndarray:
    """``floor(v * 64 + 2**15)`` clipped to uint16, in float32 (the published ``flow2uint16``).

    Non-finite values are written as 0 (encoded 2**15)."""
    v = np.nan_to_num(np.asarray(values, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    enc = np.floor(v * np.float32(FLOW_SCALE) + np.float32(FLOW_OFFSET))
    return np.clip(enc, 0, 65535).astype(np.uint16)


def encode_flow_png(flow: np.ndarray, third: np.ndarray | None = None) -> np.ndarray:
    """HxWx3 uint16 in RGB order: encoded x, encoded y, ``third`` (uint16, default 0).

    Finite flow outside the encodable range (-512 <= flow < 512 px) is an ``InputError``
    rather than clipped into a wrong, valid-looking value (clip it yourself if that is meant)."""
    flow = as_flow(flow)
    finite = flow[np.isfinite(flow)]
    lo, hi = -FLOW_OFFSET / FLOW_SCALE, (65536 - FLOW_OFFSET) / FLOW_SCALE
    if finite.size and (finite.min() < lo or finite.max() >= hi):
        raise InputError(
            f"flow of {finite.min():.6g}..{finite.max():.6g} px does not fit a flow PNG "
            f"({lo:g} <= flow < {hi:g} px); it would be clipped"
        )
    h, w = flow.shape[:2]
    out = np.zeros((h, w, 3), np.uint16)
    out[..., :2] = encode_values(flow)
    if third is not None:
        t = np.asarray(third)
        if t.shape != (h, w):
            raise InputError(f"third channel has shape {t.shape}, expected {(h, w)}")
        if (
            not np.issubdtype(t.dtype, np.integer)
            or t.min(initial=0) < 0
            or t.max(initial=0) > 65535
        ):
            raise InputError("the third channel must hold integers in [0, 65535]")
        out[..., 2] = t
    return out


def uncertainty_channel(uncertainty: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """Third channel of a *predicted*-flow PNG: encoded |uncertainty| (HxWx2 or HxW), or the
    encoded -1 everywhere when there is none (as the published ``save_flow``)."""
    if uncertainty is None:
        return encode_values(np.full(shape, -1.0, np.float32))
    u = np.asarray(uncertainty, np.float32)
    if u.ndim == 3:
        u = np.linalg.norm(u, axis=2)
    if u.shape != tuple(shape):
        raise InputError(f"uncertainty has shape {u.shape}, expected {tuple(shape)}")
    return encode_values(u)


def decode_flow_png(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(flow HxWx2 float32 px, third channel HxW uint16) from an RGB-ordered uint16 array."""
    if img.dtype != np.uint16 or img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"a flow PNG is 16-bit with 3 channels, got {img.dtype} {img.shape}")
    flow = (img[..., :2].astype(np.float32) - FLOW_OFFSET) * np.float32(1.0 / FLOW_SCALE)
    return np.ascontiguousarray(flow), img[..., 2].copy()


def write_flow_png(path: str | Path, flow: np.ndarray, third: np.ndarray | None = None) -> Path:
    """Write a flow PNG (``third``: instance ids for ground truth, see
    :func:`uncertainty_channel` for a prediction)."""
    path = Path(path)
    rgb = encode_flow_png(flow, third)
    write_image(path, np.ascontiguousarray(rgb[..., ::-1]))
    return path


def read_flow_png(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(flow HxWx2 float32 px, third channel HxW uint16) of a flow PNG."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"flow PNG not found: {path}")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise RecordingError(f"cannot decode {path} as an image")
    if img.dtype != np.uint16 or img.ndim != 3 or img.shape[2] != 3:
        raise RecordingError(
            f"{path} is not a 16-bit 3-channel flow PNG (got {img.dtype}, shape {img.shape})"
        )
    return decode_flow_png(np.ascontiguousarray(img[..., ::-1]))


def labels_to_instances(labels: np.ndarray) -> np.ndarray:
    """cablesim labels (hose >= 0, background -1, robot -2) -> instance ids (hose + 1, else 0)."""
    labels = np.asarray(labels)
    return np.where(labels >= 0, labels.astype(np.int64) + 1, 0).astype(np.uint16)


# --------------------------------------------------------------------------- clip folders
@dataclass
class ClipFrame:
    """One image of a MovingCables clip and its ground truth (each part may be missing)."""

    index: int  # odd image number
    rgb: np.ndarray  # HxWx3 uint8
    flow: np.ndarray | None = None  # HxWx2 float32, this image -> first image
    normal_flow: np.ndarray | None = None
    instances: np.ndarray | None = None  # HxW uint16, 0 = background
    stick_mask: np.ndarray | None = None  # HxW bool


def _name(index: int) -> str:
    return f"{int(index):08d}.png"


def rgb_folder(split: str | Path, clip: str) -> Path:
    """The colour folder of ``clip`` (``rgb_clips``, ``rgba_clips`` or ``clips``)."""
    split = Path(split)
    for name in RGB_FOLDERS:
        if (split / name / clip).is_dir():
            return split / name / clip
    raise RecordingError(
        f"no colour folder of clip {clip!r} under {split} (looked in {RGB_FOLDERS})"
    )


def list_clips(split: str | Path) -> list[str]:
    """Clip names (``0001``, ...) of a split folder."""
    split = Path(split)
    for name in RGB_FOLDERS:
        if (split / name).is_dir():
            return sorted(p.name for p in (split / name).iterdir() if p.is_dir())
    raise RecordingError(f"{split} is not a MovingCables split (no {' / '.join(RGB_FOLDERS)})")


def clip_indices(split: str | Path, clip: str) -> list[int]:
    """Image numbers of a clip: odd, from 1, as the published evaluation requires."""
    folder = rgb_folder(split, clip)
    names = sorted(p.name for p in folder.iterdir() if p.suffix == ".png")
    out: list[int] = []
    for n in names:
        stem = n[:-4]
        if len(stem) != 8 or not stem.isdigit() or int(stem) % 2 != 1:
            raise RecordingError(f"{folder / n}: not an odd 8-digit image number")
        out.append(int(stem))
    if not out or out[0] != 1:
        raise RecordingError(f"{folder}: the first image must be 00000001.png")
    return out


def _read_rgb(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise RecordingError(f"cannot read {path}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.dtype != np.uint8:
        raise RecordingError(f"{path}: expected 8-bit colour, got {img.dtype}")
    return np.ascontiguousarray(img[..., 2::-1])  # BGR(A) -> RGB, alpha dropped


def read_clip(split: str | Path, clip: str, stick_masks: bool = True) -> Iterator[ClipFrame]:
    """The images of a clip, in order, with whatever ground truth exists beside them."""
    split = Path(split)
    rgb_dir = rgb_folder(split, clip)
    for idx in clip_indices(split, clip):
        fr = ClipFrame(idx, _read_rgb(rgb_dir / _name(idx)))
        p = split / FLOW_FOLDER / clip / _name(idx)
        if p.is_file():
            fr.flow, fr.instances = read_flow_png(p)
        p = split / NORMAL_FLOW_FOLDER / clip / _name(idx)
        if p.is_file():
            fr.normal_flow, inst = read_flow_png(p)
            if fr.instances is None:
                fr.instances = inst
        p = split / STICK_FOLDER / clip / _name(idx)
        if stick_masks and p.is_file():
            fr.stick_mask = _read_stick(p)
        yield fr


def _read_stick(path: Path) -> np.ndarray:
    m = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if m is None:
        raise RecordingError(f"cannot read {path}")
    return (m if m.ndim == 2 else m.max(axis=2)) > 0


def read_stick_masks(split: str | Path, clip: str) -> list[np.ndarray]:
    """The stick masks of a clip's images, in order (the images that have one), read without
    the images and their flows."""
    split = Path(split)
    paths = (split / STICK_FOLDER / clip / _name(i) for i in clip_indices(split, clip))
    return [_read_stick(p) for p in paths if p.is_file()]


def arm_share(sticks: Iterable[np.ndarray]) -> float:
    """The largest share of an image that a clip's stick (a simulated clip's arm, dilated)
    covers; 0 without masks."""
    return max((float(np.mean(m)) for m in sticks), default=0.0)


def write_clip(split: str | Path, clip: str, frames: Iterable[ClipFrame]) -> Path:
    """Write a clip in the published layout (``rgb_clips`` and whatever ground truth the frames
    hold).  Image numbers must be odd and start at 1."""
    split = Path(split)
    if not (len(clip) == 4 and clip.isdigit()):
        raise InputError(f"clip names are 4 digits (0001, ...), got {clip!r}")
    first = True
    for fr in frames:
        if fr.index % 2 != 1 or (first and fr.index != 1):
            raise InputError(f"image numbers are odd from 1, got {fr.index}")
        first = False
        name = _name(fr.index)
        out = split / "rgb_clips" / clip
        out.mkdir(parents=True, exist_ok=True)
        rgb = np.asarray(fr.rgb)
        if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
            raise InputError(
                f"image {fr.index}: rgb must be HxWx3 uint8, got {rgb.dtype} {rgb.shape}"
            )
        write_image(out / name, np.ascontiguousarray(rgb[..., ::-1]))
        for folder, flow in ((FLOW_FOLDER, fr.flow), (NORMAL_FLOW_FOLDER, fr.normal_flow)):
            if flow is not None:
                (split / folder / clip).mkdir(parents=True, exist_ok=True)
                write_flow_png(split / folder / clip / name, flow, fr.instances)
        if fr.stick_mask is not None:
            (split / STICK_FOLDER / clip).mkdir(parents=True, exist_ok=True)
            m = as_mask(fr.stick_mask, rgb.shape[:2], name=f"stick mask {fr.index}")
            write_image(split / STICK_FOLDER / clip / name, m.astype(np.uint8) * 255)
    if first:
        raise InputError("a clip needs at least one image")
    return split


# --------------------------------------------------------------------------- evaluation
class PublishedFarneback(FlowEstimator):
    """Farneback flow with the parameters of the published MovingCables evaluation
    (pyramid 0.5, 3 levels, window 15, 3 iterations, poly_n 7, sigma 1.5) and its grey
    conversion (OpenCV's BGR weights applied to the RGB image)."""

    name = "farneback-movingcables"

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        g1 = cv2.cvtColor(np.ascontiguousarray(image1), cv2.COLOR_BGR2GRAY)
        g2 = cv2.cvtColor(np.ascontiguousarray(image2), cv2.COLOR_BGR2GRAY)
        flow = cv2.calcOpticalFlowFarneback(g1, g2, None, 0.5, 3, 15, 3, 7, 1.5, 0)
        return np.ascontiguousarray(flow, np.float32)


def evaluate_clip(
    split: str | Path,
    clip: str,
    flow: FlowEstimator | str,
    thr_motion: float,
    thr_static: float = STATIC_THRESHOLD,
    truth: str = "normal_flow",
    use_stick: bool = True,
) -> tuple[list[FlowFrameStats], MovingCablesSummary]:
    """The published evaluation of a flow back end on one clip.

    For every image (the first included): flow = ``estimator.compute(image, first image)``;
    the stick's pixels get zero flow and no motion; a pixel is predicted moving where
    |flow| > ``thr_motion``; ground truth (``truth``: ``normal_flow`` as published, or
    ``flow``) is moving where |gt| > ``thr_motion`` and static where |gt| < ``thr_static``.
    """
    if truth not in ("normal_flow", "flow"):
        raise InputError(f"truth must be 'normal_flow' or 'flow', got {truth!r}")
    est = make_flow(flow)
    first: np.ndarray | None = None
    stats: list[FlowFrameStats] = []
    for fr in read_clip(split, clip, stick_masks=use_stick):
        if first is None:
            first = fr.rgb
        gt = fr.normal_flow if truth == "normal_flow" else fr.flow
        if gt is None:
            raise RecordingError(f"clip {clip} image {fr.index}: no ground-truth {truth}")
        pred = est.compute(fr.rgb, first)
        stats.append(movingcables_frame(gt, pred, thr_motion, thr_static, fr.stick_mask))
    return stats, movingcables_summary(stats)
