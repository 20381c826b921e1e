"""3D pose of a 2D segment from depth (SPEC 3.1): centre = geometric median, axis = PCA.

``segment_pose(mask, depth, intrinsics)`` back-projects the mask pixels with valid depth,
takes their geometric median (Weiszfeld) as the centre and the first principal component of
the points within ``inlier_distance`` of it as the axis.  The axis is unit length with a
non-negative x component (image left-to-right; y down for vertical axes).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from cablesim.checks import as_depth, as_mask, valid_depth
from cablesim.errors import InputError
from cablesim.frames import Intrinsics


@dataclass
class SegmentPose:
    centre: np.ndarray  # (3,) metres, camera frame
    axis: np.ndarray  # (3,) unit, camera frame
    n_points: int  # mask pixels with valid depth
    n_inliers: int
    out_of_plane_deg: float  # angle between the axis and the image plane
    length: float  # extent of the inliers along the axis (metres)


def geometric_median(points: np.ndarray, tol: float = 1e-7, max_iter: int = 200) -> np.ndarray:
    """Weiszfeld's algorithm; robust to a point coinciding with the estimate."""
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or len(p) == 0:
        raise InputError(f"geometric_median needs a non-empty NxD array, got shape {p.shape}")
    y = np.median(p, axis=0)
    for _ in range(max_iter):
        d = np.linalg.norm(p - y, axis=1)
        near = d < 1e-12
        if near.all():
            return y
        w = 1.0 / np.maximum(d[~near], 1e-12)
        t = (p[~near] * w[:, None]).sum(0) / w.sum()
        n_near = int(near.sum())
        if n_near:  # Vardi-Zhang correction
            r = np.linalg.norm(((p[~near] - y) * w[:, None]).sum(0))
            gamma = min(1.0, n_near / r) if r > 0 else 1.0
            t = (1 - gamma) * t + gamma * y
        if np.linalg.norm(t - y) < tol:
            return t
        y = t
    return y


def segment_points(mask: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Camera-frame 3D points (Nx3) of the mask pixels with valid depth."""
    if intrinsics is None:
        raise InputError("intrinsics are missing")
    if not isinstance(intrinsics, Intrinsics):
        raise InputError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")
    depth = as_depth(depth)
    mask = as_mask(mask, depth.shape)
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise InputError(
            f"depth is {depth.shape[1]}x{depth.shape[0]} but intrinsics are for "
            f"{intrinsics.width}x{intrinsics.height}"
        )
    sel = mask & valid_depth(depth)
    v, u = np.nonzero(sel)
    return intrinsics.backproject(np.stack([u, v], -1).astype(np.float64), depth[v, u])


def principal_axis(points: np.ndarray) -> np.ndarray:
    c = points - points.mean(0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    a = vt[0]
    if a[0] < 0 or (abs(a[0]) < 1e-12 and a[1] < 0):
        a = -a
    return a / np.linalg.norm(a)


def segment_pose(
    mask: np.ndarray,
    depth: np.ndarray,
    intrinsics: Intrinsics,
    inlier_distance: float = 0.04,
    min_points: int = 10,
) -> SegmentPose:
    """Centre and axis of the segment ``mask`` (HxW) from ``depth`` (HxW metres)."""
    mask_b = as_mask(mask, np.shape(depth))
    if not mask_b.any():
        raise InputError("segment mask is empty")
    pts = segment_points(mask_b, depth, intrinsics)
    if len(pts) == 0:
        raise InputError("no valid depth under the segment mask (all 0 or NaN)")
    if len(pts) < min_points:
        raise InputError(f"only {len(pts)} valid depth pixels under the segment, need {min_points}")
    centre = geometric_median(pts)
    d = np.linalg.norm(pts - centre, axis=1)
    inl = pts[d <= inlier_distance]
    if len(inl) < 2:
        raise InputError("fewer than 2 segment points within the inlier distance of the centre")
    axis = principal_axis(inl)
    proj = (inl - centre) @ axis
    angle = float(np.degrees(np.arcsin(min(1.0, abs(axis[2])))))
    return SegmentPose(
        centre=centre,
        axis=axis,
        n_points=len(pts),
        n_inliers=len(inl),
        out_of_plane_deg=angle,
        length=float(proj.max() - proj.min()),
    )


def eccentricity(mask: np.ndarray) -> float:
    """Eccentricity sqrt(1 - l2/l1) of the pixel distribution of ``mask`` (0 round, ->1 line)."""
    v, u = np.nonzero(mask)
    if len(u) < 2:
        return 0.0
    c = np.cov(np.stack([u, v]).astype(np.float64), bias=True)
    l2, l1 = np.linalg.eigvalsh(c)
    if l1 <= 0:
        return 0.0
    return float(np.sqrt(max(0.0, 1.0 - max(l2, 0.0) / l1)))


def line_segment_mask(
    depth: np.ndarray,
    intrinsics: Intrinsics,
    u: float,
    v: float,
    angle: float,
    length: float = 0.04,
    thickness: int = 2,
    min_pixels: int = 5,
) -> np.ndarray | None:
    """A short line of pixels through image point (``u``, ``v``) at ``angle`` radians from the
    image x axis (y down), ``length`` metres long at the point's depth (median of the 5x5
    neighbourhood), kept where depth is valid: how a person's click and drag becomes a segment.
    None when there is no depth at the point or fewer than ``min_pixels`` remain."""

    depth = as_depth(depth)
    h, w = depth.shape
    if not (np.isfinite(u) and np.isfinite(v) and np.isfinite(angle)):
        raise InputError(f"segment point and angle must be finite, got ({u}, {v}, {angle})")
    ui, vi = min(max(int(u), 0), w - 1), min(max(int(v), 0), h - 1)
    z = depth[max(vi - 2, 0) : vi + 3, max(ui - 2, 0) : ui + 3]
    z = z[(z > 0) & np.isfinite(z)]
    if z.size == 0:
        return None
    half = max(0.5 * length * intrinsics.f / float(np.median(z)), 3.0)
    du, dv = half * np.cos(angle), half * np.sin(angle)
    mask = np.zeros((h, w), np.uint8)
    p0 = (int(round(ui - du)), int(round(vi - dv)))
    p1 = (int(round(ui + du)), int(round(vi + dv)))
    cv2.line(mask, p0, p1, 1, thickness=thickness)
    out = mask.astype(bool) & valid_depth(depth)
    return out if out.sum() >= min_pixels else None
