"""Evaluation: scores, proposal grades and the environment's reward, in one place.

Ground truth reaches policies only through this module: an :class:`Evaluator` wraps a
ground-truth provider (a simulated session's, or a digital twin's) and the hose of interest,
and answers what evaluation asks (the hose's mask in a frame, scores of a predicted mask, the
SPEC section 7 grade of a grasp proposal, the exact flow between two target frames for the
explicit ``oracle`` merge).  A real robot has no evaluator; the policies then skip scoring.

    ev = session.evaluator()
    ev.score(votes >= 1, ev.stream_truth(stream))   # precision, recall, f0.4, f1, iou, pixels
    ev.grade(segment, reachable=True)               # correct_reachable | ... | background
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cablesim.frames import Stream
from cablesim.perception.metrics import GRADES, grade_proposal, score_mask
from cablesim.sim.flow_gt import gt_flow

__all__ = ["GRADES", "Evaluator", "f04_reward", "scores_dict"]


def scores_dict(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Precision, recall, F_0.4, F_1, IoU and pixel counts of ``pred`` against ``truth``.

    One interaction's numbers for reports, infos and the reward: a score that is undefined
    (the precision of an empty prediction, ...) reads 0 here.  Means over sequences follow
    SPEC section 7 with :func:`cablesim.perception.metrics.mean_scores`, which leaves them out.
    """
    s = score_mask(pred, truth)

    def num(v: float) -> float:
        return 0.0 if np.isnan(v) else float(v)

    return {
        "precision": num(s.precision),
        "recall": num(s.recall),
        "f0.4": num(s.f[0.4]),
        "f1": num(s.f[1.0]),
        "iou": num(s.iou),
        "pixels": int(np.count_nonzero(pred)),
        "truth_pixels": int(np.count_nonzero(truth)),
    }


def f04_reward(before: dict[str, float], after: dict[str, float]) -> float:
    """The environment's reward: the gain in F_0.4 of the merged mask."""
    return float(after["f0.4"] - before.get("f0.4", 0.0))


class Evaluator:
    """Ground truth of the hose of interest, for evaluation only (module docstring)."""

    def __init__(self, truth: Any, hose: int) -> None:
        self.truth = truth  # a ground-truth provider with a camera (SimTruth)
        self.hose = int(hose)

    # ---- masks -------------------------------------------------------------------------
    def current_labels(self) -> np.ndarray:
        """Labels of the current state (hose index, robot, background)."""
        return self.truth.camera.render_labels()

    def current_mask(self) -> np.ndarray:
        """The hose of interest in the current image."""
        return self.current_labels() == self.hose

    def stream_truth(self, stream: Stream) -> np.ndarray | None:
        """The hose of interest in the stream's target frame (None without ground truth)."""
        t = stream.target.truth
        return None if t is None else t.labels == self.hose

    # ---- scores and grades ---------------------------------------------------------------
    def score(self, pred: np.ndarray, truth: np.ndarray | None = None) -> dict[str, float]:
        """Scores of ``pred`` against ``truth`` (default: the current image's mask)."""
        return scores_dict(pred, self.current_mask() if truth is None else truth)

    def grade(self, segment: np.ndarray, reachable: bool, labels: np.ndarray | None = None) -> str:
        """SPEC section 7 grade of a proposal segment in the current image (or ``labels``)."""
        labels = self.current_labels() if labels is None else labels
        return grade_proposal(segment, labels, self.hose, reachable)

    # ---- the explicit oracle merge ---------------------------------------------------------
    def snapshot(self) -> Any:
        """The current state, for :meth:`flow_between` later."""
        return self.truth.camera.snapshot()

    @staticmethod
    def flow_between(new: Any, previous: Any) -> np.ndarray | None:
        """Exact flow new -> previous (new(p) = previous(p + f)); 0 where undefined."""
        if new is None or previous is None:
            return None

        flow, valid = gt_flow(new, previous)[:2]
        return np.where(valid[..., None], flow, 0.0).astype(np.float32)
