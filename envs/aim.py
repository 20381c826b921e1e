"""Aimed actions: turn the start segment of an observation into an action that hits it.

    from cablesim.envs.aim import aim_at_segment
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(aim_at_segment(obs))   # a grasp on it

The start segment (``obs["segment"]``, the stand-in for a person's click, carried along with
the scene) is a short visible piece of the hose of interest, so an action on it reaches the
hose and earns a reward from the first step, which random actions almost never do.  The point
is the segment pixel nearest to the segment's centroid (on the hose even when the segment is
curved), the angle its first principal direction in the image (u right, v down), in the
environment's units of pi/2 in [-1, 1).

An empty segment (it can leave the image when the hose moves) aims at the image centre with
angle 0; :func:`aim_parameters` reports that case through its ``found`` flag.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from cablesim.errors import InputError

from .hose_explore import PRIMITIVES


class Aim(NamedTuple):
    """Where an aimed action goes, in the units of ``HoseExploreEnv``'s action."""

    u: float  # point, normalised image x in [0, 1]
    v: float  # point, normalised image y in [0, 1]
    angle: float  # hose direction in units of pi/2, in [-1, 1)
    found: bool  # False: the segment was empty (image centre, angle 0)


def _segment_mask(obs_or_segment: Any) -> np.ndarray:
    seg = obs_or_segment["segment"] if isinstance(obs_or_segment, dict) else obs_or_segment
    seg = np.asarray(seg)
    if seg.ndim == 3 and seg.shape[-1] == 1:
        seg = seg[..., 0]
    if seg.ndim != 2:
        raise InputError(f"segment: expected an HxW mask, got shape {seg.shape}")
    return seg > 0


def aim_parameters(obs_or_segment: Any) -> Aim:
    """The point (normalised) and angle (units of pi/2) of the segment in an observation of
    ``HoseExploreEnv`` (or an HxW mask)."""
    seg = _segment_mask(obs_or_segment)
    h, w = seg.shape
    v, u = np.nonzero(seg)
    if len(u) == 0:
        return Aim(0.5, 0.5, 0.0, False)
    pts = np.stack([u, v], 1).astype(np.float64)
    c = pts.mean(0)
    near = pts[int(np.argmin(((pts - c) ** 2).sum(1)))]
    angle = 0.0
    if len(pts) >= 2:
        cov = np.cov((pts - c).T)
        if np.all(np.isfinite(cov)) and np.trace(cov) > 0:
            ev = np.linalg.eigh(cov)[1][:, -1]
            a = math.atan2(ev[1], ev[0])
            angle = ((a + math.pi / 2) % math.pi - math.pi / 2) / (math.pi / 2)
    # pixel centres: pixel i covers [i, i+1) in the env's normalised coordinates times size
    return Aim((near[0] + 0.5) / w, (near[1] + 0.5) / h, float(angle), True)


def aim_at_segment(obs_or_segment: Any, primitive: str | int = "grasp") -> dict[str, Any]:
    """A ``HoseExploreEnv`` action (``Dict``) on the centre of the start segment, along it.

    ``primitive``: ``"grasp"`` / ``"push"`` or its index in ``PRIMITIVES``.
    """
    if isinstance(primitive, str):
        if primitive not in PRIMITIVES:
            raise InputError(f"primitive: {primitive!r} is not one of {PRIMITIVES}")
        index = PRIMITIVES.index(primitive)
    else:
        index = int(primitive)
        if not 0 <= index < len(PRIMITIVES):
            raise InputError(f"primitive: {primitive!r} is not an index of {PRIMITIVES}")
    a = aim_parameters(obs_or_segment)
    return {
        "primitive": index,
        "point": np.array([a.u, a.v], np.float32),
        "angle": np.array([a.angle], np.float32),
    }
