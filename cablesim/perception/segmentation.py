"""Motion segmentation baseline (SPEC section 4, thesis 6.1.1).

Within action a, pixel p gets one vote for each sample k with |phi_k(p) - phi_1(p)| > tau_m;
M_a(p) = 1 where votes > tau_v * N_a, N_a = kept samples of the action (reference included,
as in the thesis: "the total number of input images participating in action a voting").
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from cablesim.checks import as_flow, check_params
from cablesim.errors import InputError


@dataclass(frozen=True)
class SegmentationParams:
    tau_m: float = 2.0  # px
    tau_v: float = 0.47  # relative vote threshold (SPEC beta = 0.4 row)

    def __post_init__(self) -> None:
        check_params(self)
        if self.tau_m < 0:
            raise InputError(f"tau_m must be >= 0, got {self.tau_m}")
        if not 0 <= self.tau_v <= 1:
            raise InputError(f"tau_v must be in [0, 1], got {self.tau_v}")


@dataclass
class SegmentationResult:
    votes: np.ndarray  # HxW float32 vote count
    n_samples: int  # N_a

    @property
    def fraction(self) -> np.ndarray:
        """votes / N_a (HxW float32)."""
        return self.votes / np.float32(max(self.n_samples, 1))

    def mask(self, tau_v: float) -> np.ndarray:
        return self.votes > tau_v * self.n_samples


class SegmentationAccumulator:
    """Vote counter of one action; the first ``update`` gives the reference flow."""

    def __init__(self, shape: tuple[int, int], params: SegmentationParams | None = None) -> None:
        self.params = params if params is not None else SegmentationParams()
        self.shape = (int(shape[0]), int(shape[1]))
        self.votes = np.zeros(self.shape, np.float32)
        self._ref: np.ndarray | None = None
        self._r = np.empty((*self.shape, 2), np.float32)
        self._mag = np.empty(self.shape, np.float32)
        self.samples = 0

    def update(self, flow: np.ndarray) -> None:
        flow = as_flow(flow, self.shape)
        self.samples += 1
        if self._ref is None:
            self._ref = flow.copy()
            return
        cv2.subtract(flow, self._ref, self._r)
        x, y = cv2.split(self._r)
        cv2.magnitude(x, y, self._mag)
        cv2.threshold(self._mag, self.params.tau_m, 1.0, cv2.THRESH_BINARY, self._mag)
        cv2.accumulate(self._mag, self.votes)

    def result(self) -> SegmentationResult:
        return SegmentationResult(votes=self.votes.copy(), n_samples=self.samples)
