"""Votes of several interactions merged in the latest target frame.

Each interaction ends with its own target frame, and the hose has moved a little between two of
them, so the votes of earlier interactions must be carried into the latest target frame before
they are added.  Choice made here (documented in the README): the merged vote image is kept in
the coordinates of the latest target frame; when a new target frame arrives, the old merged
votes are *backward-warped* into it with the flow from the new target to the previous one
(new(p) shows what previous showed at p + flow; nearest-neighbour sampling, so votes stay
integers), then the new interaction's votes are added.

The flow between target frames is ground-truth free by default (OpenCV DIS with the
low-texture gate, the same back end the perception uses); ``"oracle"`` uses the simulator's
exact flow (evaluation and ablations only), ``"none"`` adds the votes in place.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from cablesim.errors import InputError
from cablesim.perception.flow import DISFlow

#: flow(new_rgb, previous_rgb) -> HxWx2 float32 in new-frame pixels (new(p) = previous(p + f))
TargetFlow = Callable[[np.ndarray, np.ndarray], np.ndarray]


def warp_votes(votes: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """Backward-warp an integer vote image with ``flow`` (nearest neighbour, 0 outside)."""
    h, w = votes.shape
    if flow.shape != (h, w, 2):
        raise InputError(f"flow {flow.shape} does not match votes {votes.shape}")
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    map_x = xs + np.nan_to_num(flow[..., 0]).astype(np.float32)
    map_y = ys + np.nan_to_num(flow[..., 1]).astype(np.float32)
    out = cv2.remap(
        votes.astype(np.float32),
        map_x,
        map_y,
        cv2.INTER_NEAREST,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    return np.rint(out).astype(votes.dtype)


def dis_target_flow() -> TargetFlow:
    est = DISFlow()
    return lambda new, prev: est.compute(new, prev)


class VoteMerger:
    """Merged votes of all interactions so far, in the latest target frame's pixels."""

    def __init__(self, flow: TargetFlow | None = None) -> None:
        self.flow = flow  # None: votes are added in place
        self.votes: np.ndarray | None = None  # int16 HxW
        self.per_interaction: list[np.ndarray] = []  # each interaction's votes, carried along
        self.rgb: np.ndarray | None = None

    def retarget(self, rgb: np.ndarray, flow: np.ndarray | None = None) -> None:
        """Carry every vote image into a new frame ``rgb`` (e.g. after a failed attempt moved
        the scene); ``flow`` overrides the flow from ``rgb`` to the current frame."""
        if self.votes is None or self.rgb is None:
            self.rgb = rgb
            return
        if flow is None and self.flow is not None:
            flow = self.flow(rgb, self.rgb)
        if flow is not None:
            self.votes = warp_votes(self.votes, flow)
            self.per_interaction = [warp_votes(v, flow) for v in self.per_interaction]
        self.rgb = rgb

    def add(self, rgb: np.ndarray, votes: np.ndarray, flow: np.ndarray | None = None) -> None:
        """Add one interaction's ``votes`` (in the pixels of its target frame ``rgb``)."""
        votes = np.asarray(votes).astype(np.int16)
        self.retarget(rgb, flow)
        self.votes = votes.copy() if self.votes is None else self.votes + votes
        self.per_interaction.append(votes.copy())

    def mask(self, n: int = 1) -> np.ndarray:
        if self.votes is None:
            raise InputError("no votes merged yet")
        return self.votes >= n
