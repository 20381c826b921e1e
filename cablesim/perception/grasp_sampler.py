"""Grasp sampling from a vote image (SPEC section 5, thesis 6.1.3).

Candidates: for each vote level v (most-supported first) the mask ``votes >= v`` is thinned,
the skeleton is cut into pieces of at most ``segment_length_px`` pixels and every mask pixel
within ``gather_radius_px`` of the skeleton joins its nearest piece.  Each candidate gets a 3D
pose (:func:`~cablesim.perception.geometry.segment_pose`) and is checked against every
requirement; the first failed one is recorded as its rejection reason:

``area`` (outside [area_min, area_max]), ``eccentricity`` (below the minimum: not elongated),
``depth`` (too little valid depth), ``out_of_plane`` (axis too steep), ``blacklisted`` (near a
successfully sampled segment: centre within ``blacklist_distance`` or mask overlap above
``blacklist_overlap``), ``too_close`` (closer than G_min to a previous grasp),
``unreachable: <reason>`` (the reachability callback said no).

Order: for v from the highest vote level down to ``min_votes`` (only the levels some pixel
has: a level no pixel has gives the same mask as the next higher one); within a level, for
G = G_max, G_max - G_delta, ..., G_min: valid candidates at least G from all previous grasps,
sorted by mean votes then area (largest first).  The first candidate the reachability
callback accepts is the proposal.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np

from cablesim.checks import as_depth, check_params, valid_depth
from cablesim.errors import InputError
from cablesim.frames import Intrinsics
from cablesim.perception.geometry import eccentricity, segment_pose
from cablesim.perception.skeleton import split_skeleton, thinning

Reachability = Callable[[np.ndarray, np.ndarray], tuple[bool, str]]

#: Distinct vote levels a vote image may have (votes count actions: a few per grasp).
MAX_VOTE_LEVELS = 1024


@dataclass(frozen=True)
class GraspSamplerParams:
    segment_length_px: int = 30
    gather_radius_px: float = 8.0
    area_min: int = 40
    area_max: int = 1500
    eccentricity_min: float = 0.85
    min_depth_fraction: float = 0.5
    min_depth_points: int = 10
    max_out_of_plane_deg: float = 45.0
    inlier_distance: float = 0.04
    blacklist_distance: float = 0.02
    blacklist_overlap: float = 0.5
    g_max: float = 0.2
    g_min: float = 0.1
    g_delta: float = 0.05
    min_votes: int = 1

    def __post_init__(self) -> None:
        check_params(self)
        for name in (
            "gather_radius_px",
            "min_depth_fraction",
            "max_out_of_plane_deg",
            "inlier_distance",
            "blacklist_distance",
            "blacklist_overlap",
        ):
            if getattr(self, name) < 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.gather_radius_px > 1e6:
            raise InputError(f"gather_radius_px must be <= 1e6, got {self.gather_radius_px}")
        for name in ("segment_length_px", "area_min", "area_max", "min_depth_points", "min_votes"):
            if getattr(self, name) >= 2**31:
                raise InputError(f"{name} must be < 2**31, got {getattr(self, name)}")
        if self.min_depth_points < 1:
            raise InputError(f"min_depth_points must be >= 1, got {self.min_depth_points}")
        if self.area_min > self.area_max:
            raise InputError(f"area_min {self.area_min} > area_max {self.area_max}")
        if not 0 < self.g_min <= self.g_max or self.g_delta <= 0:
            raise InputError("need 0 < g_min <= g_max and g_delta > 0")
        if (self.g_max - self.g_min) / self.g_delta > 1000:
            raise InputError(
                f"g_delta {self.g_delta} makes more than 1000 frontiers from g_max {self.g_max} "
                f"to g_min {self.g_min}"
            )
        if self.segment_length_px < 2:
            raise InputError("segment_length_px must be >= 2")
        if self.min_votes < 1:
            raise InputError("min_votes must be >= 1")

    def frontiers(self) -> list[float]:
        gs, g = [], self.g_max
        while g >= self.g_min - 1e-9 and len(gs) <= 1000:
            gs.append(round(g, 9))
            if g - self.g_delta >= g:  # below float resolution at this magnitude
                break
            g -= self.g_delta
        return gs


@dataclass
class Candidate:
    """One candidate segment with its checks."""

    level: int  # vote level v (mask = votes >= v)
    mask: np.ndarray
    area: int
    eccentricity: float
    mean_votes: float
    centre: np.ndarray | None = None
    axis: np.ndarray | None = None
    out_of_plane_deg: float | None = None
    depth_fraction: float = 0.0
    min_distance: float = float("inf")  # to previous grasps (m)
    rejected: str | None = None  # None = valid so far / proposed
    frontier: float | None = None  # G at which it was considered

    @property
    def pixel(self) -> tuple[float, float]:
        v, u = np.nonzero(self.mask)
        return float(u.mean()), float(v.mean())


@dataclass
class GraspProposal:
    centre: np.ndarray  # (3,) camera frame
    axis: np.ndarray  # (3,) unit
    mask: np.ndarray
    level: int
    frontier: float | None
    candidate: Candidate


@dataclass
class SamplingResult:
    proposal: GraspProposal | None
    candidates: list[Candidate] = field(default_factory=list)

    def rejections(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for c in self.candidates:
            key = (c.rejected or "ok").split(":")[0]
            out[key] = out.get(key, 0) + 1
        return out


@dataclass
class _Blacklisted:
    centre: np.ndarray
    mask: np.ndarray | None


def candidate_segments(mask: np.ndarray, params: GraspSamplerParams) -> list[np.ndarray]:
    """Masks of skeleton pieces with their nearby mask pixels."""
    if not mask.any():
        return []
    skel = thinning(mask)
    labels = split_skeleton(skel, params.segment_length_px)
    if labels.max() == 0:
        return []
    # nearest skeleton pixel for every pixel (label of the nearest zero of the inverse)
    inv = np.where(skel, 0, 255).astype(np.uint8)
    dist, nearest = cv2.distanceTransformWithLabels(
        inv, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL
    )
    ys, xs = np.nonzero(skel)
    lut = np.zeros(int(nearest.max()) + 1, np.int32)
    lut[nearest[ys, xs]] = labels[ys, xs]
    piece = lut[nearest]
    piece[~mask | (dist > params.gather_radius_px)] = 0
    return [piece == i for i in range(1, int(labels.max()) + 1) if (piece == i).any()]


class GraspSampler:
    """Proposes the next grasp; remembers previous grasps and the blacklist."""

    def __init__(
        self, params: GraspSamplerParams | None = None, reachability: Reachability | None = None
    ) -> None:
        self.params = params if params is not None else GraspSamplerParams()
        self.reachability = reachability
        self.previous: list[np.ndarray] = []
        self.blacklist: list[_Blacklisted] = []

    def add_grasp(
        self, centre: np.ndarray, mask: np.ndarray | None = None, blacklist: bool = True
    ) -> None:
        """Record a grasp that was performed (e.g. the initial one)."""
        c = np.asarray(centre, np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise InputError(f"grasp centre must be a finite (3,) vector, got {c}")
        self.previous.append(c)
        if blacklist:
            self.blacklist.append(_Blacklisted(c, None if mask is None else mask.astype(bool)))

    def accept(self, proposal: GraspProposal) -> None:
        """The proposal was grasped successfully: it becomes a previous grasp, blacklisted."""
        self.add_grasp(proposal.centre, proposal.mask, blacklist=True)

    def _check(
        self, c: Candidate, depth: np.ndarray, ok_depth: np.ndarray, intrinsics: Intrinsics
    ) -> None:
        p = self.params
        if not p.area_min <= c.area <= p.area_max:
            c.rejected = f"area: {c.area} px outside [{p.area_min}, {p.area_max}]"
            return
        if c.eccentricity < p.eccentricity_min:
            c.rejected = f"eccentricity: {c.eccentricity:.2f} < {p.eccentricity_min}"
            return
        n_ok = int((ok_depth & c.mask).sum())
        c.depth_fraction = n_ok / max(c.area, 1)
        if c.depth_fraction < p.min_depth_fraction or n_ok < p.min_depth_points:
            c.rejected = f"depth: {n_ok} valid depth pixels ({c.depth_fraction:.0%})"
            return
        try:
            pose = segment_pose(c.mask, depth, intrinsics, p.inlier_distance, p.min_depth_points)
        except InputError as e:
            c.rejected = f"depth: {e}"
            return
        c.centre, c.axis, c.out_of_plane_deg = pose.centre, pose.axis, pose.out_of_plane_deg
        if pose.out_of_plane_deg > p.max_out_of_plane_deg:
            c.rejected = (
                f"out_of_plane: axis {pose.out_of_plane_deg:.0f} deg out of the image "
                f"plane > {p.max_out_of_plane_deg}"
            )
            return
        for b in self.blacklist:
            if np.linalg.norm(b.centre - pose.centre) < p.blacklist_distance:
                c.rejected = "blacklisted: centre near a previously sampled segment"
                return
            if b.mask is not None and b.mask.shape == c.mask.shape:
                ov = (b.mask & c.mask).sum() / max(c.area, 1)
                if ov > p.blacklist_overlap:
                    c.rejected = f"blacklisted: overlaps a previously sampled segment ({ov:.0%})"
                    return
        if self.previous:
            c.min_distance = float(min(np.linalg.norm(g - pose.centre) for g in self.previous))
        if c.min_distance < p.g_min:
            c.rejected = f"too_close: {c.min_distance:.3f} m < G_min {p.g_min} from a grasp"

    def propose(
        self, votes: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics | None
    ) -> SamplingResult:
        """The next grasp from ``votes`` (HxW int, actions supporting each pixel)."""
        if intrinsics is None:
            raise InputError("intrinsics are missing")
        if not isinstance(intrinsics, Intrinsics):
            raise InputError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")
        depth = as_depth(depth)
        votes = np.asarray(votes)
        if votes.shape != depth.shape:
            raise InputError(f"votes {votes.shape} and depth {depth.shape} differ in size")
        if depth.shape != (intrinsics.height, intrinsics.width):
            # checked here: inside the per-candidate checks it would only reject every
            # candidate as "depth" and silently give no proposal
            raise InputError(
                f"depth is {depth.shape[1]}x{depth.shape[0]} but intrinsics are for "
                f"{intrinsics.width}x{intrinsics.height}"
            )
        if not (np.issubdtype(votes.dtype, np.integer) or votes.dtype == np.bool_):
            raise InputError(f"votes must be an integer (or bool) image, got {votes.dtype}")
        if votes.ndim != 2 or votes.size == 0:
            raise InputError(f"votes must be a non-empty HxW image, got shape {votes.shape}")
        if votes.dtype == np.uint64 and votes.max() > np.iinfo(np.int64).max:
            raise InputError(f"votes up to {votes.max()} do not fit a 64-bit signed integer")
        votes = votes.astype(np.int64)  # no wrap-around whatever the input's integer type
        p = self.params
        ok_depth = valid_depth(depth)
        result = SamplingResult(None)
        unreachable: list[tuple[np.ndarray, str]] = []
        levels = np.unique(votes[votes >= p.min_votes])[::-1]
        if len(levels) > MAX_VOTE_LEVELS:
            raise InputError(
                f"votes have {len(levels)} distinct levels >= {p.min_votes} (at most "
                f"{MAX_VOTE_LEVELS}): a vote image counts the actions supporting each pixel"
            )
        for level in (int(v) for v in levels):
            level_mask = votes >= level
            cands = []
            for m in candidate_segments(level_mask, p):
                c = Candidate(
                    level=level,
                    mask=m,
                    area=int(m.sum()),
                    eccentricity=eccentricity(m),
                    mean_votes=float(votes[m].mean()),
                )
                self._check(c, depth, ok_depth, intrinsics)
                cands.append(c)
            result.candidates.extend(cands)
            valid = [c for c in cands if c.rejected is None]
            valid.sort(key=lambda c: (-c.mean_votes, -c.area))
            for g in p.frontiers():
                for c in valid:
                    if c.rejected is not None or c.frontier is not None:
                        continue
                    if c.min_distance < g:
                        continue
                    c.frontier = g
                    if self.reachability is not None:
                        same = [
                            w
                            for u, w in unreachable
                            if np.linalg.norm(u - c.centre) < p.blacklist_distance
                        ]
                        if same:  # the same segment seen at a higher vote level
                            c.rejected = f"unreachable: {same[0]} (same segment as before)"
                            continue
                        ok, why = self.reachability(c.centre, c.axis)
                        if not ok:
                            c.rejected = f"unreachable: {why}"
                            unreachable.append((c.centre, why))
                            continue
                    result.proposal = GraspProposal(c.centre, c.axis, c.mask, level, g, c)
                    return result
        return result
