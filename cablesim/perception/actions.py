"""Per-action bookkeeping: sample subsampling and gripper displacement (SPEC 3.5, 4).

- :func:`subsample_by_gripper` keeps, in time order, the first frame and every frame whose
  gripper moved at least ``delta`` metres since the last *kept* frame.
- :func:`action_direction` is u_a, the first principal axis of the gripper trajectory.
- :func:`gripper_displacements` is d_g = (g_k - g_1) . u_a for each frame.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Frame


def _positions(frames_or_points: Sequence[Frame] | np.ndarray) -> np.ndarray:
    if isinstance(frames_or_points, np.ndarray):
        g = np.asarray(frames_or_points, np.float64)
    else:
        g = np.array([np.asarray(f.gripper, np.float64) for f in frames_or_points])
    if g.ndim != 2 or g.shape[1] != 3:
        raise InputError(f"gripper positions must be Nx3, got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise InputError("gripper positions contain NaN or inf")
    return g


def subsample_by_gripper(frames: Sequence[Frame], delta: float = 0.001) -> list[Frame]:
    """Frames where the gripper moved >= ``delta`` m since the last kept one (first is kept)."""
    if delta < 0 or not np.isfinite(delta):
        raise InputError(f"delta must be a non-negative distance in metres, got {delta!r}")
    frames = list(frames)
    if not frames:
        return []
    kept = [frames[0]]
    last = np.asarray(frames[0].gripper, np.float64)
    for f in frames[1:]:
        g = np.asarray(f.gripper, np.float64)
        if np.linalg.norm(g - last) >= delta - 1e-12:  # tolerate rounding of exact steps
            kept.append(f)
            last = g
    return kept


def action_direction(frames_or_points: Sequence[Frame] | np.ndarray) -> np.ndarray:
    """Unit direction u_a of an action: first principal axis of its gripper positions.

    The sign is chosen so that the displacement of largest magnitude from the first position
    is positive (the sign does not matter to the methods, which use |c0|).  A trajectory
    without any motion returns the zero vector.
    """
    g = _positions(frames_or_points)
    if len(g) < 2:
        return np.zeros(3)
    c = g - g.mean(0)
    _, s, vt = np.linalg.svd(c, full_matrices=False)
    if s[0] <= 1e-12:
        return np.zeros(3)
    u = vt[0]
    d = (g - g[0]) @ u
    if d[np.argmax(np.abs(d))] < 0:
        u = -u
    return u


def gripper_displacements(
    frames_or_points: Sequence[Frame] | np.ndarray, direction: np.ndarray | None = None
) -> np.ndarray:
    """d_g,k = (g_k - g_1) . u_a (metres) for every frame of one action."""
    g = _positions(frames_or_points)
    u = action_direction(g) if direction is None else np.asarray(direction, np.float64)
    if u.shape != (3,):
        raise InputError(f"direction must have shape (3,), got {u.shape}")
    n = np.linalg.norm(u)
    if n > 0:
        u = u / n
    return (g - g[0]) @ u
