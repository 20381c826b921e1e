"""Pictures for people: colour maps, overlays, legends and titled panels (one copy of each).

Plain NumPy + OpenCV; every function takes and returns RGB uint8 images (HxWx3) except
:func:`write_png`, which writes one.  A figure is a row of tiles, each with a title strip above
it (:func:`panel`); a tile may carry a legend on its right (:func:`with_colour_bar`,
:func:`with_flow_wheel`).

- flow: :func:`colour_flow` (HSV wheel: hue = direction, brightness = magnitude), whose key is
  :func:`flow_wheel`;
- scalar maps: :func:`colour_map` with :func:`colour_bar`; depth: :func:`colour_depth`;
- labels: :func:`colour_labels` (hose index, robot, background);
- masks: :func:`overlay_votes`, :func:`overlay_mask`, and :func:`overlay_errors` (true
  positives green, false positives red, false negatives blue).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from cablesim.errors import RecordingError
from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT

FONT = cv2.FONT_HERSHEY_SIMPLEX
WHITE = (255, 255, 255)
BLACK = (0, 0, 0)
TP_COLOUR = (0, 220, 0)
FP_COLOUR = (235, 30, 30)
FN_COLOUR = (40, 110, 255)
SEGMENT_COLOUR = (255, 0, 255)
# per hose index (cycled); robot white, background black
LABEL_COLOURS = np.array(
    [
        [230, 60, 60],
        [60, 200, 80],
        [40, 120, 230],
        [240, 220, 40],
        [200, 60, 200],
        [60, 230, 230],
        [255, 140, 60],
        [170, 170, 170],
    ],
    np.uint8,
)
ROBOT_COLOUR = (255, 255, 255)
CMAPS = {"viridis": cv2.COLORMAP_VIRIDIS, "turbo": cv2.COLORMAP_TURBO, "magma": cv2.COLORMAP_MAGMA}


# ---------------------------------------------------------------------------- text and layout
def text_scale(width: int) -> float:
    """Font scale for a tile ``width`` pixels wide (readable from 160 to 1280 px)."""
    return float(np.clip(width / 900.0, 0.35, 0.6))


def put_text(
    img: np.ndarray,
    text: str,
    org: tuple[int, int],
    scale: float,
    colour: tuple[int, int, int] = BLACK,
    outline: tuple[int, int, int] | None = None,
) -> None:
    """Draw ``text`` in place with its baseline's left end at ``org`` (x, y)."""
    thick = 1 if scale < 0.5 else 2
    if outline is not None:
        cv2.putText(img, text, org, FONT, scale, outline, thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, FONT, scale, colour, thick, cv2.LINE_AA)


def _width(text: str, scale: float) -> int:
    return cv2.getTextSize(text, FONT, scale, 1 if scale < 0.5 else 2)[0][0]


def _fit(text: str, width: int, scale: float) -> str:
    """``text`` cut (with '...') to fit ``width`` pixels at ``scale``."""
    if _width(text, scale) <= width:
        return text
    while text and _width(text + "...", scale) > width:
        text = text[:-1]
    return text + "..."


def wrap(text: str, width: int, scale: float, max_lines: int = 3) -> list[str]:
    """``text`` broken at spaces into lines that fit ``width`` px (the last one cut if need be)."""
    lines: list[str] = []
    for word in text.split(" "):
        if lines and _width(lines[-1] + " " + word, scale) <= width:
            lines[-1] += " " + word
        else:
            lines.append(word)
    if len(lines) > max_lines:
        lines = lines[: max_lines - 1] + [" ".join(lines[max_lines - 1 :])]
    return [_fit(line, width, scale) for line in lines]


def titled(
    img: np.ndarray, title: str, scale: float | None = None, n_lines: int | None = None
) -> np.ndarray:
    """``img`` under a white strip with ``title`` in black, wrapped to the image's width
    (``n_lines`` makes the strip that many lines tall, to line up tiles in a row)."""
    h, w = img.shape[:2]
    scale = text_scale(w) if scale is None else scale
    lines = wrap(title, w - 8, scale)
    line_h = int(round(30 * scale / 0.5))
    strip_h = line_h * max(len(lines), n_lines or 0) + 4
    strip = np.full((strip_h, w, 3), 255, np.uint8)
    for k, line in enumerate(lines):
        put_text(strip, line, (4, (k + 1) * line_h - int(line_h * 0.3) + 2), scale)
    return np.concatenate([strip, _rgb(img)], axis=0)


def label(img: np.ndarray, text: str) -> np.ndarray:
    """``img`` with ``text`` written on it (top left, white on a dark outline): video frames."""
    out = _rgb(img).copy()
    scale = text_scale(out.shape[1])
    put_text(out, text, (5, int(22 * scale / 0.5) + 2), scale, WHITE, outline=BLACK)
    return out


def _pad_to(img: np.ndarray, h: int, w: int) -> np.ndarray:
    out = np.full((h, w, 3), 255, np.uint8)
    out[: img.shape[0], : img.shape[1]] = img
    return out


def hstack(tiles: Sequence[np.ndarray], sep: int = 6) -> np.ndarray:
    """Tiles side by side (top-aligned, padded white to the tallest) with white gaps."""
    h = max(t.shape[0] for t in tiles)
    row: list[np.ndarray] = []
    for t in tiles:
        row += [_pad_to(_rgb(t), h, t.shape[1]), np.full((h, sep, 3), 255, np.uint8)]
    return np.concatenate(row[:-1], axis=1)


def vstack(rows: Sequence[np.ndarray], sep: int = 6) -> np.ndarray:
    """Rows one above the other (left-aligned, padded white to the widest)."""
    w = max(r.shape[1] for r in rows)
    col: list[np.ndarray] = []
    for r in rows:
        col += [_pad_to(_rgb(r), r.shape[0], w), np.full((sep, w, 3), 255, np.uint8)]
    return np.concatenate(col[:-1], axis=0)


def panel(tiles: Sequence[np.ndarray], titles: Sequence[str], sep: int = 6) -> np.ndarray:
    """A row of tiles, each under its title strip (one font size for the whole row)."""
    if len(tiles) != len(titles):
        raise ValueError(f"{len(tiles)} tiles but {len(titles)} titles")
    scale = text_scale(min(t.shape[1] for t in tiles))
    n = max(len(wrap(s, t.shape[1] - 8, scale)) for t, s in zip(tiles, titles, strict=True))
    return hstack([titled(t, s, scale, n) for t, s in zip(tiles, titles, strict=True)], sep)


def _rgb(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return np.ascontiguousarray(img.astype(np.uint8, copy=False))


def write_png(path: str | Path, rgb: np.ndarray) -> None:
    """Write an RGB uint8 image as PNG; ``RecordingError`` if it cannot be written."""
    if not cv2.imwrite(str(path), np.ascontiguousarray(_rgb(rgb)[..., ::-1])):
        raise RecordingError(f"{path}: could not be written")


# ---------------------------------------------------------------------------- colour maps
def colour_map(
    x: np.ndarray, lo: float, hi: float, cmap: str = "viridis", reverse: bool = False
) -> np.ndarray:
    """Scalar image -> RGB through ``cmap``, ``lo`` and ``hi`` at its ends (NaN as ``lo``);
    ``reverse`` runs the map from ``hi`` to ``lo``."""
    s = np.clip((np.nan_to_num(np.asarray(x, np.float64), nan=lo) - lo) / max(hi - lo, 1e-12), 0, 1)
    if reverse:
        s = 1.0 - s
    bgr = cv2.applyColorMap(np.round(s * 255).astype(np.uint8), CMAPS[cmap])
    return bgr[..., ::-1].copy()


def colour_bar(
    height: int,
    lo: float,
    hi: float,
    cmap: str = "viridis",
    unit: str = "",
    fmt: str = "{:.2g}",
    reverse: bool = False,
) -> np.ndarray:
    """The key of :func:`colour_map` (same ``cmap``/``reverse``): a vertical bar ``height`` px
    tall, ``hi`` at the top, with three tick labels."""
    scale = float(np.clip(height / 600.0, 0.35, 0.5))
    ticks = [hi, (lo + hi) / 2, lo]
    labels = [fmt.format(t) + (f" {unit}" if unit else "") for t in ticks]
    text_w = max(cv2.getTextSize(s, FONT, scale, 1)[0][0] for s in labels)
    bar_w, pad = max(10, height // 24), 6
    out = np.full((height, pad + bar_w + 4 + text_w + pad, 3), 255, np.uint8)
    margin = 8
    span = max(height - 2 * margin, 2)
    ramp = np.linspace(hi, lo, span)[:, None].repeat(bar_w, axis=1)
    out[margin : margin + span, pad : pad + bar_w] = colour_map(ramp, lo, hi, cmap, reverse)
    cv2.rectangle(out, (pad - 1, margin - 1), (pad + bar_w, margin + span), BLACK, 1)
    for k, s in enumerate(labels):
        y = margin + int(round(k * (span - 1) / 2))
        cv2.line(out, (pad + bar_w, y), (pad + bar_w + 3, y), BLACK, 1)
        base = int(np.clip(y + 4, 10, height - 2))
        put_text(out, s, (pad + bar_w + 5, base), scale)
    return out


def with_colour_bar(
    img: np.ndarray,
    lo: float,
    hi: float,
    cmap: str = "viridis",
    unit: str = "",
    fmt: str = "{:.2g}",
    reverse: bool = False,
) -> np.ndarray:
    """``img`` (already coloured by :func:`colour_map` with these arguments) with its colour
    bar on the right."""
    bar = colour_bar(img.shape[0], lo, hi, cmap, unit, fmt, reverse)
    return np.concatenate([_rgb(img), bar], axis=1)


def depth_range(depth: np.ndarray) -> tuple[float, float]:
    """The 1st and 99th percentile of the valid (> 0) depths, metres."""
    valid = depth > 0
    if not valid.any():
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(depth[valid], [1, 99]))
    return lo, max(hi, lo + 1e-3)


def colour_depth(depth: np.ndarray, lo: float | None = None, hi: float | None = None) -> np.ndarray:
    """Metric depth -> RGB through ``turbo`` reversed (near = warm) over [lo, hi] (default
    :func:`depth_range`); 0 (no depth) black."""
    if lo is None or hi is None:
        lo, hi = depth_range(depth)
    out = colour_map(depth, lo, hi, "turbo", reverse=True)
    out[~(depth > 0)] = 0
    return out


def depth_tile(depth: np.ndarray) -> np.ndarray:
    """:func:`colour_depth` with its colour bar in metres."""
    lo, hi = depth_range(depth)
    return with_colour_bar(colour_depth(depth, lo, hi), lo, hi, "turbo", "m", "{:.2f}", True)


def colour_labels(labels: np.ndarray) -> np.ndarray:
    """Labels -> RGB: hose ``i`` in ``LABEL_COLOURS[i]``, robot white, background black, any
    other negative label grey."""
    out = np.zeros((*labels.shape, 3), np.uint8)
    hose = labels >= 0
    out[hose] = LABEL_COLOURS[labels[hose] % len(LABEL_COLOURS)]
    out[labels == LABEL_ROBOT] = ROBOT_COLOUR
    out[(labels < 0) & (labels != LABEL_ROBOT) & (labels != LABEL_BACKGROUND)] = 128
    return out


def labels_legend(labels: np.ndarray, height: int) -> np.ndarray:
    """A key of the labels present: a swatch and a name per hose, robot and background."""
    present = sorted(int(v) for v in np.unique(labels))
    names = [(f"hose {v}", LABEL_COLOURS[v % len(LABEL_COLOURS)]) for v in present if v >= 0]
    if LABEL_ROBOT in present:
        names.append(("robot", np.array(ROBOT_COLOUR)))
    names.append(("background", np.zeros(3, np.uint8)))
    return _legend(names, height)


def _legend(entries: Sequence[tuple[str, np.ndarray]], height: int) -> np.ndarray:
    scale = float(np.clip(height / 600.0, 0.35, 0.5))
    row = int(26 * scale / 0.5)
    text_w = max(cv2.getTextSize(s, FONT, scale, 1)[0][0] for s, _ in entries)
    out = np.full((max(height, row * len(entries) + 8), 8 + row + 6 + text_w + 8, 3), 255, np.uint8)
    for k, (name, colour) in enumerate(entries):
        y = 6 + k * row
        c = tuple(int(v) for v in colour)
        cv2.rectangle(out, (8, y), (8 + row - 6, y + row - 6), c, -1)
        cv2.rectangle(out, (8, y), (8 + row - 6, y + row - 6), (90, 90, 90), 1)
        put_text(out, name, (8 + row, y + row - 9), scale)
    return out[:height] if out.shape[0] > height else out


# ---------------------------------------------------------------------------- flow
def colour_flow(
    flow: np.ndarray, max_mag: float | None = None, valid: np.ndarray | None = None
) -> np.ndarray:
    """Optical flow -> RGB on the HSV wheel: hue = direction, brightness = magnitude / max_mag
    (default: the largest valid magnitude); invalid pixels black."""
    flow = np.asarray(flow, np.float64)
    mag = np.linalg.norm(flow, axis=-1)
    if max_mag is None:
        m = mag if valid is None else mag[valid]
        max_mag = float(m.max(initial=0.0))
    ang = np.arctan2(flow[..., 1], flow[..., 0])
    hsv = np.zeros((*flow.shape[:2], 3), np.uint8)
    hsv[..., 0] = np.round((ang + np.pi) / (2 * np.pi) * 179).astype(np.uint8)
    hsv[..., 1] = 255
    hsv[..., 2] = np.round(np.clip(mag / max(max_mag, 1e-6), 0, 1) * 255).astype(np.uint8)
    if valid is not None:
        hsv[~valid] = 0
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def flow_wheel(diameter: int, max_mag: float = 1.0) -> np.ndarray:
    """The key of :func:`colour_flow`: the colour of every flow vector up to ``max_mag`` (rim),
    image axes (u right, v down), on white."""
    r = (diameter - 1) / 2
    v, u = np.mgrid[0:diameter, 0:diameter].astype(np.float64) - r
    inside = u * u + v * v <= r * r
    flow = np.stack([u, v], axis=-1) / max(r, 1e-9) * max_mag
    out = colour_flow(flow, max_mag)
    out[~inside] = 255
    return out


def flow_legend(height: int, max_mag: float) -> np.ndarray:
    """A flow wheel with its scale (``|flow|`` at the rim, px) and the axes, ``height`` tall."""
    scale = float(np.clip(height / 600.0, 0.35, 0.5))
    lines = ["hue: direction", f"rim: {max_mag:.1f} px"]
    text_w = max(cv2.getTextSize(s, FONT, scale, 1)[0][0] for s in lines)
    line_h = int(24 * scale / 0.5)
    d = int(min(height - 2 * line_h - 16, max(text_w, 60)))
    d = max(1, min(max(d, 24), height - 8))  # fits images down to 9 px tall
    w = max(d, text_w) + 16
    out = np.full((height, w, 3), 255, np.uint8)
    x0 = (w - d) // 2
    out[8 : 8 + d, x0 : x0 + d] = flow_wheel(d)
    c = (x0 + d // 2, 8 + d // 2)
    cv2.arrowedLine(out, c, (x0 + d - 3, c[1]), BLACK, 1, cv2.LINE_AA, tipLength=0.15)  # +u
    cv2.arrowedLine(out, c, (c[0], 8 + d - 3), BLACK, 1, cv2.LINE_AA, tipLength=0.15)  # +v
    for k, s in enumerate(lines):
        put_text(out, s, (8, 8 + d + (k + 1) * line_h), scale)
    return out


def with_flow_wheel(img: np.ndarray, max_mag: float) -> np.ndarray:
    """A flow picture (coloured with ``max_mag``) with its wheel legend on the right."""
    return np.concatenate([_rgb(img), flow_legend(img.shape[0], max_mag)], axis=1)


# ---------------------------------------------------------------------------- masks
def overlay_votes(rgb: np.ndarray, votes: np.ndarray, max_votes: int | None = None) -> np.ndarray:
    """Votes in shades of green over a darkened RGB image (as in the thesis figures)."""
    base = rgb.astype(np.float32) * 0.6
    top = max(int(max_votes or votes.max(initial=0)), 1)
    a = np.clip(votes.astype(np.float32) / top, 0, 1)[..., None]
    a = np.where(votes[..., None] > 0, 0.35 + 0.65 * a, 0.0)
    out = base * (1 - a) + np.array([0, 255, 0], np.float32) * a
    return np.clip(out, 0, 255).astype(np.uint8)


def overlay_mask(
    rgb: np.ndarray, mask: np.ndarray, colour: tuple[int, int, int] = WHITE, dim: float = 0.4
) -> np.ndarray:
    """``mask`` in ``colour`` over the RGB image darkened to ``dim`` (40%)."""
    out = (rgb.astype(np.float32) * dim).astype(np.uint8)
    out[mask] = colour
    return out


def overlay_errors(rgb: np.ndarray, pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """A predicted mask scored against the true one over the darkened image: true positives
    green, false positives red, false negatives blue."""
    pred, truth = np.asarray(pred, bool), np.asarray(truth, bool)
    out = (rgb.astype(np.float32) * 0.35).astype(np.uint8)
    out[pred & truth] = TP_COLOUR
    out[pred & ~truth] = FP_COLOUR
    out[~pred & truth] = FN_COLOUR
    return out


def errors_legend(height: int, pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The key of :func:`overlay_errors` with the pixel count of each kind."""
    pred, truth = np.asarray(pred, bool), np.asarray(truth, bool)
    entries = [
        (f"TP {int((pred & truth).sum())}", np.array(TP_COLOUR)),
        (f"FP {int((pred & ~truth).sum())}", np.array(FP_COLOUR)),
        (f"FN {int((~pred & truth).sum())}", np.array(FN_COLOUR)),
    ]
    return _legend(entries, height)


def errors_tile(rgb: np.ndarray, pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """:func:`overlay_errors` with its key on the right."""
    return np.concatenate(
        [overlay_errors(rgb, pred, truth), errors_legend(rgb.shape[0], pred, truth)], axis=1
    )
