"""Random visible, graspable start segments: the stand-in for a person clicking on the image.

In the real set-up a person marks a short piece of the hose of interest in the current image.
:func:`pick_segment` does that in simulation from ground truth: it draws candidate centre pixels
from the chosen hose's visible mask (seeded generator), takes the hose pixels within a few
centimetres of it (connected to it), and accepts the first candidate that

- has at least ``min_pixels`` pixels with valid depth and is elongated (eccentricity),
- is away from occlusions: no pixel of another hose or of the robot within ``clearance``
  of the segment,
- lies on the hose in 3D (its depth-estimated centre within ``max_axis_error`` of the rod), at
  least ``min_end_distance`` along the hose from either end (near a connector the hose is
  short and taut: pulling it along its axis makes it slip through the fingers), and
  its axis is at most ``max_out_of_plane_deg`` out of the image plane (SPEC 5),
- is graspable: the grasp and pre-grasp poses and the action end points
  (g1 +- D for every configured direction) pass ``robot.check_reachable``.

It raises :class:`~cablesim.errors.UnreachableError` with the reasons when no candidate passes.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from cablesim.camera.base import Camera
from cablesim.episode import primitives as prim
from cablesim.episode.config import InteractionConfig
from cablesim.errors import InputError, UnreachableError
from cablesim.perception.frames import LABEL_ROBOT
from cablesim.perception.geometry import eccentricity, segment_pose
from cablesim.robot.base import Robot


@dataclass
class PickedSegment:
    mask: np.ndarray  # HxW bool
    hose: int
    centre_px: tuple[int, int]  # (u, v)
    centre_world: np.ndarray  # estimated from depth (the visible surface)
    tries: int

    @property
    def pixels(self) -> np.ndarray:
        """(N, 2) pixels as (u, v)."""
        v, u = np.nonzero(self.mask)
        return np.stack([u, v], 1)


def _disk(shape: tuple[int, int], u: int, v: int, r: float) -> np.ndarray:
    h, w = shape
    yy, xx = np.ogrid[:h, :w]
    return (xx - u) ** 2 + (yy - v) ** 2 <= r * r


def pick_segment(
    world: Any,
    robot: Robot,
    camera: Camera,
    hose: int,
    rng: np.random.Generator,
    config: InteractionConfig | None = None,
    half_length: float = 0.03,
    clearance: float = 0.01,
    min_pixels: int = 10,
    min_eccentricity: float = 0.8,
    max_axis_error: float = 0.02,
    max_out_of_plane_deg: float = 30.0,
    min_end_distance: float = 0.2,
    max_tries: int = 40,
) -> PickedSegment:
    """A random graspable visible segment of ``hose`` in the camera's current image."""
    cfg = config or InteractionConfig()
    if not 0 <= hose < len(world.hoses):
        raise InputError(f"hose {hose} does not exist (the scene has {len(world.hoses)})")
    image = camera.capture()
    labels = camera.render_labels()  # type: ignore[attr-defined]
    depth, K = image.depth, image.intrinsics
    T = np.asarray(camera.T_world_camera, float)
    mine = (labels == hose) & (depth > 0)
    others = ((labels >= 0) & (labels != hose)) | (labels == LABEL_ROBOT)
    vv, uu = np.nonzero(mine)
    if len(vv) == 0:
        raise UnreachableError(f"hose {hose} is not visible in the image")
    verts = world.hose_vertices(hose)
    lengths = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(verts, axis=0), axis=1))])
    approach = np.asarray(prim.DEFAULT_APPROACH)
    reasons: Counter[str] = Counter()
    order = rng.permutation(len(vv))[:max_tries]
    for tries, j in enumerate(order, 1):
        u, v = int(uu[j]), int(vv[j])
        px_per_m = K.f / float(depth[v, u])
        disk = _disk(mine.shape, u, v, max(2.0, half_length * px_per_m))
        lab, _ = ndimage.label(mine & disk)
        seg = lab == lab[v, u]
        if seg.sum() < min_pixels:
            reasons["too few pixels"] += 1
            continue
        if eccentricity(seg) < min_eccentricity:
            reasons["not elongated"] += 1
            continue
        grown = ndimage.binary_dilation(seg, iterations=max(1, round(clearance * px_per_m)))
        if (grown & others).any():
            reasons["near another hose or the robot"] += 1
            continue
        try:
            sp = segment_pose(seg, depth, K)
        except InputError:
            reasons["no depth"] += 1
            continue
        if sp.out_of_plane_deg > max_out_of_plane_deg:
            reasons["axis out of the image plane"] += 1
            continue
        centre = T[:3, :3] @ sp.centre + T[:3, 3]
        axis = T[:3, :3] @ sp.axis
        d, arc = _distance_to_polyline(centre, verts)
        if arc < min_end_distance or arc > lengths[-1] - min_end_distance:
            reasons["too close to a hose end"] += 1
            continue
        if d > max_axis_error:
            reasons["off the hose in 3D"] += 1
            continue
        g_centre = prim.grasp_centre(T, sp.centre, cfg.grasp.surface_offset)
        ok, why = prim.check_interaction(robot, g_centre, axis, cfg, T, approach)
        if not ok:
            reasons["action end points unreachable" if "end point" in why else "unreachable"] += 1
            continue
        return PickedSegment(seg, hose, (u, v), centre, tries)
    summary = ", ".join(f"{n}x {r}" for r, n in reasons.most_common())
    raise UnreachableError(
        f"no graspable visible segment of hose {hose} in {len(order)} tries ({summary})"
    )


def _distance_to_polyline(p: np.ndarray, verts: np.ndarray) -> tuple[float, float]:
    """Distance of ``p`` to the polyline and the arc length of its nearest point."""
    a, b = verts[:-1], verts[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1)
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    e = int(np.argmin(d))
    seg = np.linalg.norm(ab, axis=1)
    return float(d[e]), float(seg[:e].sum() + t[e] * seg[e])
