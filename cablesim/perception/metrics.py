"""Segmentation and flow metrics, grasp grading (SPEC section 7).

Conventions: an empty prediction has precision 0; an empty truth gives recall 0; F_beta and
IoU are 0 when undefined (``zero_division = 0``).
F_beta = (1 + beta^2) P R / (beta^2 P + R).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from cablesim.errors import InputError
from cablesim.perception._checks import as_flow, as_mask, is_real
from cablesim.perception.frames import LABEL_BACKGROUND, LABEL_ROBOT

BETAS: tuple[float, ...] = (1.0, 0.5, 0.4, 0.3)


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
    if not is_real(beta) or not 0 < beta < float("inf"):
        raise InputError(f"beta must be positive, got {beta}")
    b2 = beta * beta
    return _div((1 + b2) * precision * recall, b2 * precision + recall)


def scores_from_counts(tp: float, fp: float, fn: float) -> tuple[float, float, float]:
    """(precision, recall, IoU) from counts."""
    return _div(tp, tp + fp), _div(tp, tp + fn), _div(tp, tp + fp + fn)


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


def score_mask(pred: np.ndarray, truth: np.ndarray, betas: Sequence[float] = BETAS) -> MaskScores:
    tp, fp, fn = confusion(pred, truth)
    p, r, j = scores_from_counts(tp, fp, fn)
    return MaskScores(p, r, j, {b: f_beta(p, r, b) for b in betas})


def mean_scores(scores: Iterable[MaskScores]) -> MaskScores:
    """Mean over sequences of precision, recall, IoU and each F_beta."""
    s = list(scores)
    if not s:
        raise InputError("mean_scores needs at least one score")
    betas = s[0].f.keys()
    return MaskScores(
        float(np.mean([x.precision for x in s])),
        float(np.mean([x.recall for x in s])),
        float(np.mean([x.iou for x in s])),
        {b: float(np.mean([x.f[b] for x in s])) for b in betas},
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
