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
- on a surface the cables lie on (the table, ``Surface.needs_slack``), a grasp has at least
  the action amplitude of slack between it and each plugged end (arc length less the straight
  distance, :func:`slack_to_plugged_ends`): friction holds a lying cable along its length,
  so pulling a grasp with less slack away from its socket stretches the cable until it springs
  out of the fingers (measured on the table: 6 of the 7 grasps lost in the ``along`` action of
  seeds 9800-9899 had 0.1-1.4 cm of slack towards a socket, nearly in the pull's line),
- leaves the gripper room: no other hose (nor a far part of the same hose) lies where the open
  fingers or the hand will be or sweep through on the straight approach
  (:func:`gripper_obstruction`; measured: a finger that lands on a neighbouring hose in front
  pushes the hose of interest out of the grasp),
- is graspable: the grasp and pre-grasp poses and the action end points
  (g1 +- D for every configured direction) pass ``robot.check_reachable``, and the motions
  themselves plan on the arm model (approach and one period of each action,
  :func:`~cablesim.episode.primitives.plan_interaction`).

Candidates come in the seeded random order of all visible pixels of the hose, but pixels that
cannot pass are skipped without counting as tries (a cheap screening, with margins so that it
turns down only what the full checks would): a pixel within ``clearance`` of another hose or
the robot, whose own point on the rod (from depth) lies within ``min_end_distance`` of a hose
end (less ``half_length`` and a centimetre), or where the rod runs more than
``max_out_of_plane_deg`` + 25 degrees out of the image plane.  So the ``max_tries`` full checks
(IK and motion planning included) go to pixels that can pass, and a pixel the checks accept is
the same one an unscreened draw would reach first.

It raises :class:`~cablesim.errors.NoGraspableSegmentError` (an ``UnreachableError``) with the
reasons, counted, when no candidate passes; the session then tries another hose or draws
another scene (:mod:`cablesim.sim.session`).
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
from cablesim.episode.surface import BOARD
from cablesim.errors import InputError, NoGraspableSegmentError
from cablesim.frames import LABEL_ROBOT
from cablesim.perception.geometry import eccentricity, segment_pose
from cablesim.pose import grasp_pose
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
    """A random graspable visible segment of ``hose`` in the camera's current image, the
    grasp fitted to that hose's diameter where ``config`` leaves it open."""
    if not 0 <= hose < len(world.hoses):
        raise InputError(f"hose {hose} does not exist (the scene has {len(world.hoses)})")
    cfg = (config or InteractionConfig()).fitted(2 * world.hoses[hose].spec.radius)
    image = camera.capture()
    labels = camera.render_labels()  # type: ignore[attr-defined]
    depth, K = image.depth, image.intrinsics
    T = np.asarray(camera.T_world_camera, float)
    mine = (labels == hose) & (depth > 0)
    others = ((labels >= 0) & (labels != hose)) | (labels == LABEL_ROBOT)
    vv, uu = np.nonzero(mine)
    if len(vv) == 0:
        raise NoGraspableSegmentError(
            f"hose {hose} is not visible in the image", {"not visible": 1}
        )
    verts = world.hose_vertices(hose)
    lengths = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(verts, axis=0), axis=1))])
    surface = getattr(world, "surface", BOARD)
    approach = np.asarray(surface.approach, float)
    screened, passes = _screen(
        uu, vv, depth, K, T, others, verts, lengths, clearance, min_end_distance,
        half_length, max_out_of_plane_deg,
    )  # fmt: skip
    pool = np.count_nonzero(passes)
    reasons: Counter[str] = Counter()
    # a random order of all visible pixels (the seeded draw), the screened-out ones skipped
    perm = rng.permutation(len(vv))
    order = perm[passes[perm]][:max_tries]
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
        if (
            surface.needs_slack
            and cfg.kind == "grasp"
            and min(slack_to_plugged_ends(verts, world.hoses[hose].spec.both_ends, arc))
            < cfg.actions.amplitude
        ):
            reasons["too little slack to a plugged end"] += 1
            continue
        g_centre = surface.grasp_centre(prim.grasp_centre(T, sp.centre, cfg.grasp.surface_offset))
        if gripper_obstruction(world, hose, g_centre, axis, approach, cfg, arc):
            reasons["no room for the gripper"] += 1
            continue
        ok, why = prim.plan_interaction(robot, g_centre, axis, cfg, T, surface)
        if not ok:
            if "end point" in why:
                reasons["action end points unreachable"] += 1
            elif why.startswith("planned"):
                reasons["motions do not plan"] += 1
            else:
                reasons["unreachable"] += 1
            continue
        return PickedSegment(seg, hose, (u, v), centre, tries)
    tried = ", ".join(f"{n}x {r}" for r, n in reasons.most_common()) or "none"
    screen = ", ".join(f"{n} {r}" for r, n in screened.most_common()) or "none"
    raise NoGraspableSegmentError(
        f"no graspable visible segment of hose {hose}: of its {len(vv)} visible pixels "
        f"{pool} passed the screening (turned down: {screen}); {len(order)} tried "
        f"({tried})",
        reasons + Counter({f"screened: {r}": n for r, n in screened.items()}),
    )


def _screen(
    uu: np.ndarray,
    vv: np.ndarray,
    depth: np.ndarray,
    K: Any,
    T: np.ndarray,
    others: np.ndarray,
    verts: np.ndarray,
    lengths: np.ndarray,
    clearance: float,
    min_end_distance: float,
    half_length: float,
    max_out_of_plane_deg: float,
) -> tuple[Counter[str], np.ndarray]:
    """Which visible pixels can pass the picker's rules (bool per pixel; conditions the full
    checks imply, with margins, so that screening skips only pixels that would fail) and,
    counted, why the others cannot."""
    why: Counter[str] = Counter()
    z = depth[vv, uu].astype(float)
    # clearance: the centre pixel itself must be clear of other hoses and the robot
    # the segment contains its centre pixel and is dilated by n steps of the 4-neighbourhood
    # (a taxicab ball): another pixel within n steps of the centre fails the clearance check
    dist = (
        ndimage.distance_transform_cdt(~others, metric="taxicab")[vv, uu]
        if others.any()
        else np.full(len(vv), np.iinfo(np.int32).max)
    )
    clear = dist > np.maximum(1, np.round(clearance * K.f / z))
    why["near another hose or the robot"] = int((~clear).sum())
    # each pixel's 3D point (camera frame) and the nearest point of the rod: its arc length
    # and how far the rod leaves the image plane there
    cam = (verts - T[:3, 3]) @ T[:3, :3]
    pts = np.stack([(uu - K.cx) * z / K.fx, (vv - K.cy) * z / K.fy, z], 1)
    a, ab = cam[:-1], np.diff(cam, axis=0)
    seg_len = np.linalg.norm(ab, axis=1)
    arc = np.empty(len(pts))
    edge = np.empty(len(pts), int)
    for c in range(0, len(pts), 2048):  # chunks bound the (pixels x edges) table
        p = pts[c : c + 2048, None]
        t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1)
        d = np.linalg.norm(a + t[..., None] * ab - p, axis=-1)
        e = np.argmin(d, axis=1)
        edge[c : c + 2048] = e
        arc[c : c + 2048] = lengths[e] + t[np.arange(len(e)), e] * seg_len[e]
    # the segment's centre (the median of up to half_length around the pixel) lies within
    # half_length and a hose radius of its centre pixel's rod point
    slack = half_length + 0.01
    inner = (arc >= min_end_distance - slack) & (arc <= lengths[-1] - min_end_distance + slack)
    why["too close to a hose end"] = int((clear & ~inner).sum())
    tangent = ab / np.maximum(seg_len[:, None], 1e-12)
    out_deg = np.degrees(np.arcsin(np.minimum(1.0, np.abs(tangent[:, 2]))))
    flat = out_deg[edge] <= max_out_of_plane_deg + 25.0  # the rod, not the depth estimate
    why["axis out of the image plane"] = int((clear & inner & ~flat).sum())
    return +why, clear & inner & flat


# The open Panda gripper in the grasp frame (x along the hose, y across it where the fingers
# close, z the approach, origin at the TCP), from cablesim.panda.model: the fingers reach
# 9.5 mm past the TCP and are 21 mm wide, their outer faces at 59 mm with the hand open; the
# hand is 60 mm wide along the hose, 200 mm across (its rounded ends), and starts 45 mm
# behind the TCP.
_FINGERS = (0.0105, 0.059, 0.0095)  # half-extent x, half-extent y, front z
_HAND = (0.03, 0.10, -0.045)


def gripper_obstruction(
    world: Any,
    hose: int,
    centre: np.ndarray,
    axis: np.ndarray,
    approach: np.ndarray,
    cfg: InteractionConfig,
    arc: float | None = None,
    margin: float = 0.005,
    own_arc_clearance: float = 0.08,
) -> str:
    """Why the open gripper grasping ``hose`` at world ``centre`` across ``axis`` would touch
    another hose (or a part of the same hose more than ``own_arc_clearance`` away along it,
    ``arc`` being the grasp point's arc length) on its straight approach along ``approach``,
    or "".  Checked on the rods (ground truth), each inflated by its radius and ``margin``:
    everything in front of the fingertips' final depth within the fingers' footprint, and
    in front of the hand's within the hand's."""

    g = grasp_pose(np.asarray(centre, float), axis, np.asarray(approach, float))
    R = g.rotation
    for i in range(len(world.hoses)):
        pad = world.hoses[i].spec.radius + margin
        pts = _densify(world.hose_vertices(i), 0.005)
        if i == hose:
            if arc is None:
                continue
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
            pts = pts[np.abs(s - arc) > own_arc_clearance]
            if len(pts) == 0:
                continue
        local = (pts - np.asarray(centre, float)) @ R
        ax, ay, az = np.abs(local[:, 0]), np.abs(local[:, 1]), local[:, 2]
        fingers = (ax < _FINGERS[0] + pad) & (ay < _FINGERS[1] + pad) & (az < _FINGERS[2] + pad)
        hand = (ax < _HAND[0] + pad) & (ay < _HAND[1] + pad) & (az < _HAND[2] + pad)
        # only what the approach passes: not behind the hand's start (the pre-grasp offset)
        start = -(cfg.grasp.pregrasp_offset + cfg.grasp.standoff + 0.15)
        hit = (fingers | hand) & (az > start)
        if hit.any():
            who = "the same hose" if i == hose else f"hose {i}"
            part = "fingers" if (fingers & hit).any() else "hand"
            return f"the {part} would touch {who}"
    return ""


def slack_to_plugged_ends(verts: np.ndarray, both_ends: bool, arc: float) -> list[float]:
    """The slack (m) of the rod ``verts`` between arc length ``arc`` and each plugged end:
    the arc length between them less their straight distance.  The first end is always
    plugged, the last one where ``both_ends``."""
    verts = np.asarray(verts, float)
    lengths = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(verts, axis=0), axis=1))])
    arc = float(np.clip(arc, 0.0, lengths[-1]))
    point = np.array([np.interp(arc, lengths, verts[:, k]) for k in range(3)])
    out = [arc - float(np.linalg.norm(point - verts[0]))]
    if both_ends:
        out.append(lengths[-1] - arc - float(np.linalg.norm(verts[-1] - point)))
    return out


def _densify(points: np.ndarray, step: float) -> np.ndarray:
    """A polyline resampled so that consecutive points are at most ``step`` apart."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.concatenate(out)


def _distance_to_polyline(p: np.ndarray, verts: np.ndarray) -> tuple[float, float]:
    """Distance of ``p`` to the polyline and the arc length of its nearest point."""
    a, b = verts[:-1], verts[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1)
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    e = int(np.argmin(d))
    seg = np.linalg.norm(ab, axis=1)
    return float(d[e]), float(seg[:e].sum() + t[e] * seg[e])
