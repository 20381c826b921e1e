"""Threshold tuning on validation sequences (SPEC section 7).

Per sequence, cached :class:`~cablesim.perception.pipeline.StreamStatistics` and the truth
mask suffice: every method's merged mask is ``score(p) > t`` for a per-pixel score, so the
confusion counts for all thresholds t of a grid follow from one sort per sequence:

- segmentation: score = n-th largest vote fraction over actions, t = tau_v;
- ablation: score = n-th largest std(d_phi), t = std_min;
- correlation: for each c0_min, score = n-th largest R^2 among actions with |c0| > c0_min,
  t = R2_min;
- any other method: its own score and grid
  (:meth:`~cablesim.perception.methods.SegmentationMethod.action_scores`, ``grid``), by
  default its fixed mask at its default parameters (one grid point).

(n = action threshold of the vote merge; 1 = union.)  The thresholds maximising the mean
F_beta over sequences are chosen per beta.  Scores follow :func:`~cablesim.perception.metrics.
score_mask` (NaN where undefined, e.g. the precision of an empty prediction) and means leave
the NaNs out, as the published evaluation does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.checks import as_mask
from cablesim.errors import InputError
from cablesim.perception.methods import SegmentationMethod, make_method, method_label
from cablesim.perception.metrics import BETAS, f_beta
from cablesim.perception.stats import StreamStatistics

#: the threshold grids of cablesim's own methods (a method's ``grid()``)
DEFAULT_GRIDS: dict[str, dict[str, np.ndarray]] = {
    name: make_method(name).grid() for name in ("segmentation", "correlation", "ablation")
}


def _counts_for_thresholds(
    score: np.ndarray, truth: np.ndarray, thresholds: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """tp(t), fp(t) for mask = score > t, and the number of truth pixels."""
    pos = np.sort(score[truth].ravel())
    neg = np.sort(score[~truth].ravel())
    tp = len(pos) - np.searchsorted(pos, thresholds, side="right")
    fp = len(neg) - np.searchsorted(neg, thresholds, side="right")
    return tp.astype(np.float64), fp.astype(np.float64), int(len(pos))


def _prf(tp: np.ndarray, fp: np.ndarray, npos: int) -> tuple[np.ndarray, ...]:
    """Precision, recall, IoU per threshold; NaN where undefined (as :func:`score_mask`)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.where(tp + fp > 0, tp / (tp + fp), np.nan)
        r = np.where(npos > 0, tp / max(npos, 1), np.nan)
        iou = np.where(npos + fp > 0, tp / (npos + fp), np.nan)
    return p, r, iou


def _f_beta_counts(tp: np.ndarray, fp: np.ndarray, npos: int, beta: float) -> np.ndarray:
    f_beta(0.5, 0.5, beta)  # validates beta
    b2 = beta * beta
    den = (1 + b2) * tp + b2 * (npos - tp) + fp
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, (1 + b2) * tp / den, np.nan)


class _NanMean:
    """Running sum and count of the finite values of same-shape arrays."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.sum = np.zeros(shape)
        self.count = np.zeros(shape)

    def add(self, i: int, v: np.ndarray) -> None:
        ok = ~np.isnan(v)
        self.sum[i] += np.where(ok, v, 0.0)
        self.count[i] += ok

    @property
    def mean(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.count > 0, self.sum / np.maximum(self.count, 1), np.nan)


@dataclass
class TuningRow:
    method: str
    beta: float
    params: dict[str, float]
    precision: float
    recall: float
    f_beta: float
    iou: float


@dataclass
class TuningResult:
    method: str
    n: int
    rows: dict[float, TuningRow] = field(default_factory=dict)

    def params(self, beta: float = 0.4) -> Any:
        """Method parameters with the thresholds tuned for ``beta``."""
        return make_method(self.method).params_for(self.rows[beta].params)


def _grid(
    m: SegmentationMethod, grid: dict[str, np.ndarray] | None
) -> tuple[str | None, np.ndarray, str, np.ndarray]:
    """(outer name, outer values, inner name, inner values) of a method's grid; the outer
    values are [NaN] for a method with one threshold."""
    g = {**m.grid(), **(grid or {})}
    if m.outer_threshold is None:
        outer_name, outer = None, np.array([np.nan])
    else:
        outer_name, outer = m.outer_threshold, np.asarray(g[m.outer_threshold], float)
    return outer_name, outer, m.threshold, np.asarray(g[m.threshold], float)


def tune_thresholds(
    stats: Sequence[StreamStatistics],
    truths: Sequence[np.ndarray],
    method: str | SegmentationMethod = "correlation",
    betas: Sequence[float] = BETAS,
    n: int = 1,
    grid: dict[str, np.ndarray] | None = None,
) -> TuningResult:
    """Grid search maximising mean F_beta over the sequences, per beta."""
    if len(stats) != len(truths) or not stats:
        raise InputError(
            f"need as many truths as statistics (>0), got {len(stats)} and {len(truths)}"
        )
    m = make_method(method)
    outer_name, outer, inner_name, inner = _grid(m, grid)
    masks = [
        as_mask(t, s.shape, name=f"truth {i}")
        for i, (s, t) in enumerate(zip(stats, truths, strict=True))
    ]
    shape = (len(outer), len(inner))
    P, R, J = _NanMean(shape), _NanMean(shape), _NanMean(shape)
    Fs = {b: _NanMean(shape) for b in betas}
    for s, t in zip(stats, masks, strict=True):
        for i, c in enumerate(outer):
            score = m.score(s, n, None if np.isnan(c) else c)
            tp, fp, npos = _counts_for_thresholds(score, t, inner)
            p, r, j = _prf(tp, fp, npos)
            P.add(i, p)
            R.add(i, r)
            J.add(i, j)
            for b in betas:
                Fs[b].add(i, _f_beta_counts(tp, fp, npos, b))
    res = TuningResult(method_label(method), n)
    for b in betas:
        fb = np.nan_to_num(Fs[b].mean, nan=-1.0)
        i, j = np.unravel_index(np.argmax(fb), fb.shape)
        params = {inner_name: float(inner[j])}
        if outer_name is not None:
            params[outer_name] = float(outer[i])
        res.rows[b] = TuningRow(
            res.method,
            b,
            params,
            float(P.mean[i, j]),
            float(R.mean[i, j]),
            float(Fs[b].mean[i, j]),
            float(J.mean[i, j]),
        )
    return res


def tuning_table(results: Sequence[TuningResult]) -> str:
    """Markdown table: method, beta, thresholds, recall, precision, F_beta, IoU."""
    lines = [
        "| method | n | beta | thresholds | recall | precision | F_beta | IoU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for res in results:
        for b, row in res.rows.items():
            th = ", ".join(f"{k}={v:g}" for k, v in row.params.items())
            lines.append(
                f"| {res.method} | {res.n} | {b:g} | {th} | {row.recall:.3f} | "
                f"{row.precision:.3f} | {row.f_beta:.3f} | {row.iou:.3f} |"
            )
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ counts, for parallel runs
@dataclass
class ThresholdCounts:
    """Confusion counts of one sequence over a threshold grid (mask = score > inner, for each
    outer value), enough to tune and score any threshold of the grid later, on another
    machine: ``tp``/``fp`` have shape (len(outer), len(inner)); ``npos`` truth pixels."""

    method: str
    n: int
    outer_name: str | None  # "c0_min" for correlation, else None
    outer: np.ndarray
    inner_name: str
    inner: np.ndarray
    tp: np.ndarray
    fp: np.ndarray
    npos: int

    def to_dict(self) -> dict:
        return {
            "method": self.method,
            "n": self.n,
            "outer_name": self.outer_name,
            "outer": [float(x) for x in self.outer],
            "inner_name": self.inner_name,
            "inner": [float(x) for x in self.inner],
            "tp": self.tp.astype(np.int64).tolist(),
            "fp": self.fp.astype(np.int64).tolist(),
            "npos": int(self.npos),
        }

    @classmethod
    def from_dict(cls, d: dict) -> ThresholdCounts:
        return cls(
            d["method"],
            int(d["n"]),
            d["outer_name"],
            np.asarray(d["outer"], float),
            d["inner_name"],
            np.asarray(d["inner"], float),
            np.asarray(d["tp"], np.float64),
            np.asarray(d["fp"], np.float64),
            int(d["npos"]),
        )

    def scores(self, beta: float) -> tuple[np.ndarray, ...]:
        """Precision, recall, IoU and F_beta per grid cell (NaN where undefined)."""
        p, r, iou = _prf(self.tp, self.fp, self.npos)
        return p, r, iou, _f_beta_counts(self.tp, self.fp, self.npos, beta)

    def params(self, i: int, j: int) -> dict[str, float]:
        out = {self.inner_name: float(self.inner[j])}
        if self.outer_name is not None:
            out[self.outer_name] = float(self.outer[i])
        return out


def threshold_counts(
    stats: StreamStatistics,
    truth: np.ndarray,
    method: str | SegmentationMethod = "correlation",
    n: int = 1,
    grid: dict[str, np.ndarray] | None = None,
) -> ThresholdCounts:
    """:class:`ThresholdCounts` of one sequence (the method's grid, e.g.
    :data:`DEFAULT_GRIDS`, with ``grid``'s values instead where given)."""
    m = make_method(method)
    outer_name, outer, inner_name, inner = _grid(m, grid)
    t = as_mask(truth, stats.shape, name="truth")
    tp = np.zeros((len(outer), len(inner)))
    fp = np.zeros_like(tp)
    npos = int(t.sum())
    for i, c in enumerate(outer):
        score = m.score(stats, n, None if np.isnan(c) else c)
        tp[i], fp[i], npos = _counts_for_thresholds(score, t, inner)
    return ThresholdCounts(
        method_label(method), n, outer_name, outer, inner_name, inner, tp, fp, npos
    )


def tune_counts(counts: Sequence[ThresholdCounts], beta: float) -> tuple[int, int, float]:
    """The grid cell (i, j) maximising the mean F_beta over sequences (NaNs left out, as
    :func:`tune_thresholds`), and that mean."""
    if not counts:
        raise InputError("tune_counts needs the counts of at least one sequence")
    acc = _NanMean(counts[0].tp.shape)
    for c in counts:
        if c.tp.shape != acc.sum.shape:
            raise InputError("the sequences' counts were computed on different grids")
        acc.sum += np.nan_to_num(c.scores(beta)[3], nan=0.0)
        acc.count += ~np.isnan(c.scores(beta)[3])
    fb = np.nan_to_num(acc.mean, nan=-1.0)
    i, j = np.unravel_index(np.argmax(fb), fb.shape)
    return int(i), int(j), float(acc.mean[i, j])
