"""Votes across actions and grasps (SPEC section 4, last paragraph).

Each action's mask adds one vote per pixel in a common target frame.  Union = at least one
vote, intersection = votes from all actions, or any action threshold n.  Votes of several
grasps add up in the same image (the caller brings their masks into one target frame).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from cablesim.checks import as_mask
from cablesim.errors import InputError


def vote_image(masks: Sequence[np.ndarray] | Iterable[np.ndarray]) -> np.ndarray:
    """Sum of per-action masks as an HxW int16 vote count."""
    masks = [as_mask(m, name=f"mask {i}") for i, m in enumerate(masks)]
    if not masks:
        raise InputError("vote_image needs at least one mask")
    shape = masks[0].shape
    votes = np.zeros(shape, np.int16)
    for i, m in enumerate(masks):
        if m.shape != shape:
            raise InputError(f"mask {i} has size {m.shape}, the first is {shape}")
        votes += m
    return votes


def merge_votes(votes: np.ndarray, n: int | str = 1, n_actions: int | None = None) -> np.ndarray:
    """Mask of pixels with at least ``n`` votes.

    ``n`` may be an int >= 1, ``"union"`` (= 1) or ``"intersection"`` (= ``n_actions``, all).
    """
    votes = np.asarray(votes)
    if votes.ndim != 2 or not np.issubdtype(votes.dtype, np.integer):
        raise InputError(f"votes must be an HxW integer image, got {votes.dtype} {votes.shape}")
    if n == "union":
        n = 1
    elif n == "intersection":
        if n_actions is None or n_actions < 1:
            raise InputError("intersection needs n_actions >= 1")
        n = n_actions
    if not isinstance(n, int | np.integer) or n < 1:
        raise InputError(
            f"action threshold must be an int >= 1, 'union' or 'intersection', got {n!r}"
        )
    return votes >= n


def union(masks: Sequence[np.ndarray]) -> np.ndarray:
    return merge_votes(vote_image(masks), 1)


def intersection(masks: Sequence[np.ndarray]) -> np.ndarray:
    return merge_votes(vote_image(masks), len(masks))


class VoteAccumulator:
    """Votes of several grasps (each with several actions) in one target frame."""

    def __init__(self, shape: tuple[int, int]) -> None:
        self.shape = (int(shape[0]), int(shape[1]))
        self.votes = np.zeros(self.shape, np.int16)
        self.n_actions = 0
        self.n_grasps = 0

    def add(self, masks: Sequence[np.ndarray] | np.ndarray) -> None:
        """Add the action masks of one grasp (a list of HxW masks, or one HxW mask).

        Each mask counts as one action; a non-zero integer image is read as a mask (one vote
        per pixel), not as a vote count.
        """
        if isinstance(masks, np.ndarray) and masks.ndim == 2:
            masks = [masks]
        for i, m in enumerate(masks):
            self.votes += as_mask(m, self.shape, name=f"mask {i}")
            self.n_actions += 1
        self.n_grasps += 1

    def mask(self, n: int | str = 1) -> np.ndarray:
        return merge_votes(self.votes, n, self.n_actions)

    @property
    def max_votes(self) -> int:
        return int(self.votes.max(initial=0))
