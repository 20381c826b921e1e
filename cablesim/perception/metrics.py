"""Segmentation and flow metrics, grasp grading (SPEC sections 7 and 8).

Mask scores follow the published evaluation (holesond/cmcor ``get_mask_metrics``): from the
counts TP, FP, FN of one sequence, precision = TP / (TP + FP) is NaN for an empty prediction,
recall = TP / (TP + FN) NaN for an empty truth, IoU NaN when both are empty, and
F_beta = (1 + beta^2) TP / ((1 + beta^2) TP + beta^2 FN + FP) (= (1 + beta^2) P R / (beta^2 P + R)
where both are defined), NaN only when prediction and truth are both empty.  Means over
sequences leave the NaNs out (``nanmean``).  ``crop`` = (x, y, width, height) counts only the
pixels of that region, as the published evaluation does with a sequence's flow crop.

The MovingCables flow protocol (holesond/movingcables ``ClipEvaluator``) is
:func:`movingcables_frame` per image and :func:`movingcables_summary` over a set of images;
:func:`flow_epe` is cablesim's own EPE on moving pixels.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from cablesim.checks import as_flow, as_mask, is_real
from cablesim.errors import InputError
from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT

BETAS: tuple[float, ...] = (1.0, 0.5, 0.4, 0.3, 0.2, 0.1)
NAN = float("nan")


def crop_region(image: np.ndarray, crop: Sequence[int] | None) -> np.ndarray:
    """``image[y:y+h, x:x+w]`` for ``crop`` = (x, y, w, h); the image itself for None."""
    if crop is None:
        return image
    values = list(crop) if isinstance(crop, Sequence | np.ndarray) else []
    if len(values) != 4 or not all(
        isinstance(v, int | np.integer) and not isinstance(v, bool) for v in values
    ):
        raise InputError(f"crop must be four integers (x, y, width, height), got {crop!r}")
    x, y, w, h = (int(v) for v in values)
    if x < 0 or y < 0 or w <= 0 or h <= 0:
        raise InputError(f"crop must have a non-negative origin and a positive size, got {crop!r}")
    return image[y : y + h, x : x + w]


def confusion(pred: np.ndarray, truth: np.ndarray) -> tuple[int, int, int]:
    """(true positives, false positives, false negatives) of two HxW masks."""
    truth = as_mask(truth, name="truth", binary=True)
    pred = as_mask(pred, truth.shape, name="prediction", binary=True)
    tp = int(np.count_nonzero(pred & truth))
    fp = int(np.count_nonzero(pred)) - tp
    fn = int(np.count_nonzero(truth)) - tp
    return tp, fp, fn


def _div(a: float, b: float) -> float:
    return float(a) / float(b) if b > 0 else 0.0


def f_beta(precision: float, recall: float, beta: float) -> float:
    """F_beta from precision and recall (0 where both are 0)."""
    if not is_real(beta) or not 0 < beta < float("inf"):
        raise InputError(f"beta must be positive, got {beta}")
    b2 = beta * beta
    return _div((1 + b2) * precision * recall, b2 * precision + recall)


def f_beta_counts(tp: float, fp: float, fn: float, beta: float) -> float:
    """F_beta from counts as published: NaN only when TP = FP = FN = 0."""
    if not is_real(beta) or not 0 < beta < float("inf"):
        raise InputError(f"beta must be positive, got {beta}")
    b2 = beta * beta
    den = (1 + b2) * tp + b2 * fn + fp
    return (1 + b2) * tp / den if den > 0 else NAN


def _ratio(a: float, b: float) -> float:
    return float(a) / float(b) if b > 0 else NAN


def scores_from_counts(tp: float, fp: float, fn: float) -> tuple[float, float, float]:
    """(precision, recall, IoU) from counts; NaN where undefined."""
    return _ratio(tp, tp + fp), _ratio(tp, tp + fn), _ratio(tp, tp + fp + fn)


@dataclass
class MaskScores:
    precision: float
    recall: float
    iou: float
    f: dict[float, float] = field(default_factory=dict)  # beta -> F_beta

    def as_row(self, beta: float = 0.4) -> dict[str, float]:
        return {
            "recall": self.recall,
            "precision": self.precision,
            "f_beta": self.f.get(beta, f_beta(self.precision, self.recall, beta)),
            "iou": self.iou,
        }

    def to_dict(self) -> dict[str, float]:
        out = {"precision": self.precision, "recall": self.recall, "iou": self.iou}
        out.update({f"f{b:g}": v for b, v in self.f.items()})
        return out


def score_mask(
    pred: np.ndarray,
    truth: np.ndarray,
    betas: Sequence[float] = BETAS,
    crop: Sequence[int] | None = None,
) -> MaskScores:
    """Precision, recall, IoU and F_beta of one prediction (module docstring)."""
    truth = as_mask(truth, name="truth", binary=True)
    pred = as_mask(pred, truth.shape, name="prediction", binary=True)
    tp, fp, fn = confusion(crop_region(pred, crop), crop_region(truth, crop))
    p, r, j = scores_from_counts(tp, fp, fn)
    return MaskScores(p, r, j, {b: f_beta_counts(tp, fp, fn, b) for b in betas})


def nanmean(values: Iterable[float]) -> float:
    """Mean of the finite values (NaN if there is none), without a warning."""
    v = np.asarray(list(values), np.float64)
    v = v[~np.isnan(v)]
    return float(v.mean()) if v.size else NAN


def mean_scores(scores: Iterable[MaskScores]) -> MaskScores:
    """Mean over sequences of precision, recall, IoU and each F_beta, NaNs left out."""
    s = list(scores)
    if not s:
        raise InputError("mean_scores needs at least one score")
    betas = s[0].f.keys()
    return MaskScores(
        nanmean(x.precision for x in s),
        nanmean(x.recall for x in s),
        nanmean(x.iou for x in s),
        {b: nanmean(x.f[b] for x in s) for b in betas},
    )


def flow_epe(
    flow: np.ndarray,
    truth: np.ndarray,
    valid: np.ndarray | None = None,
    moving_threshold: float = 0.5,
) -> float:
    """Endpoint error averaged over *moving* pixels: valid truth with |truth| > threshold px.

    NaN if there is no such pixel.
    """
    truth = as_flow(truth, name="truth flow")
    flow = as_flow(flow, truth.shape[:2], name="flow")
    sel = np.linalg.norm(truth, axis=-1) > moving_threshold
    sel &= np.all(np.isfinite(truth), -1)
    if valid is not None:
        sel &= as_mask(valid, truth.shape[:2], name="valid")
    if not sel.any():
        return float("nan")
    return float(np.linalg.norm(flow[sel] - truth[sel], axis=-1).mean())


GRADES = ("correct_reachable", "correct_unreachable", "wrong_hose", "background")


def grade_proposal(
    mask: np.ndarray, labels: np.ndarray, hose: int, reachable: bool, min_fraction: float = 0.5
) -> str:
    """Grade a grasp proposal segment against a label image.

    ``correct_*`` when at least ``min_fraction`` of its pixels lie on ``hose``; otherwise
    ``wrong_hose`` when the most frequent label under it is another hose, else
    ``background`` (robot pixels count as background).
    """
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise InputError(f"labels must be an HxW integer image, got {labels.dtype} {labels.shape}")
    mask = as_mask(mask, labels.shape, name="proposal mask")
    if not mask.any():
        raise InputError("proposal mask is empty")
    under = labels[mask]
    if np.mean(under == hose) >= min_fraction:
        return "correct_reachable" if reachable else "correct_unreachable"
    under = under[under != hose]
    under = np.where(under == LABEL_ROBOT, LABEL_BACKGROUND, under)
    vals, counts = np.unique(under, return_counts=True)
    top = vals[np.argmax(counts)]
    return "background" if top < 0 else "wrong_hose"


# ------------------------------------------------------------------ MovingCables flow protocol
# bins of |ground-truth flow| for the EPE split, as published: 0 to 40 px in steps of 0.1 px
EPE_BIN_EDGES = np.arange(0, 40.1, 0.1)
_BIN_CENTRES = 0.5 * (EPE_BIN_EDGES[:-1] + EPE_BIN_EDGES[1:])


@dataclass
class FlowFrameStats:
    """One image of the MovingCables protocol (see :func:`movingcables_frame`)."""

    recall: float
    precision: float
    iou: float
    false_motion: float  # share of predicted-moving pixels that are static in ground truth
    epe: float  # mean endpoint error over all pixels
    n_pixels: int
    n_gt_moving: int
    n_gt_static: int
    n_pred_moving: int
    epe_by_gt_sum: np.ndarray  # EPE summed per |gt| bin (EPE_BIN_EDGES)
    epe_by_gt_count: np.ndarray
    epe_pred_le1: tuple[float, int]  # (EPE sum, pixels) where |prediction| <= 1 px
    epe_pred_gt1: tuple[float, int]


def movingcables_frame(
    gt_flow: np.ndarray,
    pred_flow: np.ndarray,
    thr_motion: float,
    thr_static: float = 1.0,
    actor_mask: np.ndarray | None = None,
) -> FlowFrameStats:
    """The published per-image evaluation of a predicted flow against (normal-flow) truth.

    The actor (poking stick) pixels of the prediction get zero flow and no motion; predicted
    moving = |pred| > ``thr_motion``; ground truth moving = |gt| > ``thr_motion``, static =
    |gt| < ``thr_static``; precision / recall / IoU of the moving masks (NaN when undefined);
    EPE over all pixels.
    """
    gt = as_flow(gt_flow, name="ground-truth flow")
    pred = as_flow(pred_flow, gt.shape[:2], name="predicted flow").copy()
    moving = np.linalg.norm(pred, axis=2) > thr_motion
    if actor_mask is not None:
        actor = as_mask(actor_mask, gt.shape[:2], name="actor mask")
        moving[actor] = False
        pred[actor] = 0.0
    gt_mag = np.linalg.norm(gt, axis=2)
    epe = np.linalg.norm(gt - pred, axis=2)
    s, c = (
        np.histogram(gt_mag, bins=EPE_BIN_EDGES, weights=epe)[0],
        np.histogram(gt_mag, bins=EPE_BIN_EDGES)[0],
    )
    pmag = np.linalg.norm(pred, axis=2)
    le1 = pmag <= 1
    gt_moving = gt_mag > thr_motion
    gt_static = gt_mag < thr_static
    n_i = int(np.count_nonzero(gt_moving & moving))
    n_u = int(np.count_nonzero(gt_moving | moving))
    n_m = int(np.count_nonzero(gt_moving))
    n_p = int(np.count_nonzero(moving))
    return FlowFrameStats(
        recall=_ratio(n_i, n_m),
        precision=_ratio(n_i, n_p),
        iou=_ratio(n_i, n_u),
        false_motion=_ratio(np.count_nonzero(gt_static & moving), n_p),
        epe=float(np.mean(epe)),
        n_pixels=int(gt_mag.size),
        n_gt_moving=n_m,
        n_gt_static=int(np.count_nonzero(gt_static)),
        n_pred_moving=n_p,
        epe_by_gt_sum=s.astype(np.float64),
        epe_by_gt_count=c.astype(np.int64),
        epe_pred_le1=(float(epe[le1].sum()), int(le1.sum())),
        epe_pred_gt1=(float(epe[~le1].sum()), int((~le1).sum())),
    )


@dataclass
class MovingCablesSummary:
    """Means over images as the published ``show_stats`` reports them."""

    recall: float  # nanmean over images
    precision: float
    iou: float
    false_motion: float
    epe: float  # mean over images of the per-image mean over all pixels
    epe_gt_le1: float  # pooled over all pixels with |gt| <= 1 px (bins of 0.1 px, to 40 px)
    epe_gt_gt1: float
    epe_pred_le1: float  # pooled over all pixels with |prediction| <= 1 px
    epe_pred_gt1: float
    gt_moving_share: float
    gt_static_share: float
    images: int

    def to_dict(self) -> dict[str, float]:
        return dict(vars(self))


def movingcables_summary(frames: Sequence[FlowFrameStats]) -> MovingCablesSummary:
    """Aggregate :func:`movingcables_frame` results over images (one clip or many)."""
    if not frames:
        raise InputError("movingcables_summary needs at least one image")
    s = np.sum([f.epe_by_gt_sum for f in frames], axis=0)
    c = np.sum([f.epe_by_gt_count for f in frames], axis=0)
    lo, hi = _BIN_CENTRES <= 1.0, _BIN_CENTRES > 1.0
    return MovingCablesSummary(
        recall=nanmean(f.recall for f in frames),
        precision=nanmean(f.precision for f in frames),
        iou=nanmean(f.iou for f in frames),
        false_motion=nanmean(f.false_motion for f in frames),
        epe=float(np.mean([f.epe for f in frames])),
        epe_gt_le1=_ratio(s[lo].sum(), c[lo].sum()),
        epe_gt_gt1=_ratio(s[hi].sum(), c[hi].sum()),
        epe_pred_le1=_ratio(
            sum(f.epe_pred_le1[0] for f in frames), sum(f.epe_pred_le1[1] for f in frames)
        ),
        epe_pred_gt1=_ratio(
            sum(f.epe_pred_gt1[0] for f in frames), sum(f.epe_pred_gt1[1] for f in frames)
        ),
        gt_moving_share=float(np.mean([f.n_gt_moving / f.n_pixels for f in frames])),
        gt_static_share=float(np.mean([f.n_gt_static / f.n_pixels for f in frames])),
        images=len(frames),
    )
