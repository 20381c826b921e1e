"""Surface patterns on simulated cables: stripes, a printed marking, twisted or braided strands.

MuJoCo draws a 1D flex as plain capsules of one colour (it ignores material textures on a
flex), so a pattern is drawn as extra visual geoms appended to the renderer's scene after each
scene update (:func:`add_pattern_geoms`).  Every piece belongs to one rod edge and is placed in
that edge's material frame (tangent, m1, m2: MuJoCo's time-parallel reference frame turned by
the edge's twist angle, :meth:`SimCamera._material_frames
<cablesim.sim.camera.SimCamera._material_frames>`), at a fixed fraction of the edge: a piece
moves rigidly with its edge.  That is how the ground-truth flow carries a cable's surface point
(:mod:`cablesim.sim.flow_gt`: nearest edge, parameter along it, offset from the axis turned by
the edge's bending and twist), so a pattern moves exactly as the flow says
(``tests/sim/test_cable_patterns.py`` warps one image onto another with it).

Before the rod's first physics step MuJoCo holds no reference frame; the pieces are then placed
in :func:`fallback_frames` (a frame carried along the rod from its first edge), which need not
match the ground-truth flow's own fallback for such a snapshot.  Every simulated frame an
interaction records comes after physics steps.

Positions along the cable are material: ``(edge + fraction) * rest edge length``, so a pattern
does not slide when the rod stretches.  The pieces carry the flex's object id: the label pass
labels them as their cable, and depth includes them (they stand about 3 % of the radius off the
surface).  A solid cable adds nothing (the default scene renders as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from cablesim.errors import InputError
from cablesim.sim.layout import HoseSpec

#: strand pieces per lay length (helix segments drawn as flat strips)
HELIX_PIECES = 8
#: how far a pattern stands off the cable surface, as a fraction of the radius
STANDOFF = 0.03


@dataclass(frozen=True)
class Pieces:
    """Pattern pieces of one cable, ready for the scene: N geoms of one ``kind``."""

    kind: int  # mjtGeom
    size: np.ndarray  # (N, 3)
    pos: np.ndarray  # (N, 3)
    mat: np.ndarray  # (N, 3, 3) columns: the geom's local x, y, z axes in the world

    def __len__(self) -> int:
        return len(self.pos)


def fallback_frames(verts: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """(E, 3, 3) material frames (columns tangent, m1, m2) where the rod has no stored
    reference frame yet (before its first physics step): a reference carried along the rod
    by projection from the first edge's (perpendicular to world z, or to x for a vertical
    first edge), turned by each edge's twist."""
    t = np.diff(np.asarray(verts, float), axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-18)
    u = np.empty_like(t)
    ref = np.cross(t[0], (0.0, 0.0, 1.0))
    if np.linalg.norm(ref) < 1e-6:
        ref = np.cross(t[0], (1.0, 0.0, 0.0))
    for e in range(len(t)):
        ref = ref - (ref @ t[e]) * t[e]
        ref /= max(np.linalg.norm(ref), 1e-18)
        u[e] = ref
    tw = np.zeros(len(t)) if len(twist) != len(t) else np.asarray(twist, float)
    m1 = np.cos(tw)[:, None] * u + np.sin(tw)[:, None] * np.cross(t, u)
    return np.stack([t, m1, np.cross(t, m1)], axis=2)


def _spans(n_edges: int, rest: float, period: float, on: tuple[float, float]):
    """(edge, u0, u1) of every part of the intervals ``[k + on[0], k + on[1]] * period``
    (material arclength) that falls on one edge, ``u`` the fraction along the edge."""
    edge, u0, u1 = [], [], []
    for e in range(n_edges):
        a, b = e * rest, (e + 1) * rest
        for k in range(math.floor(a / period) - 1, math.floor(b / period) + 1):
            lo, hi = max(a, (k + on[0]) * period), min(b, (k + on[1]) * period)
            if hi - lo > 1e-9:
                edge.append(e)
                u0.append((lo - a) / rest)
                u1.append((hi - a) / rest)
    return np.array(edge, np.int64), np.array(u0), np.array(u1)


def _along(verts: np.ndarray, edge: np.ndarray, u: np.ndarray) -> np.ndarray:
    return verts[edge] + u[:, None] * (verts[edge + 1] - verts[edge])


def _stripes(verts, frames, radius, rest, period) -> Pieces:
    edge, u0, u1 = _spans(len(frames), rest, period, (0.0, 1.0 / 3.0))
    p0, p1 = _along(verts, edge, u0), _along(verts, edge, u1)
    t = frames[edge, :, 0]
    half = np.einsum("ij,ij->i", p1 - p0, t) / 2
    size = np.stack([np.full(len(edge), radius * (1 + STANDOFF)), half, np.zeros(len(edge))], 1)
    # a cylinder's axis is its local z: x = m1, y = m2, z = tangent
    mat = np.stack([frames[edge, :, 1], frames[edge, :, 2], t], axis=2)
    return Pieces(int(mujoco.mjtGeom.mjGEOM_CYLINDER), size, (p0 + p1) / 2, mat)


def _marking(verts, frames, radius, rest, period) -> Pieces:
    edge, u0, u1 = _spans(len(frames), rest, period, (0.2, 0.8))
    p0, p1 = _along(verts, edge, u0), _along(verts, edge, u1)
    t, m1, m2 = (frames[edge, :, i] for i in range(3))
    half = np.einsum("ij,ij->i", p1 - p0, t) / 2
    n = len(edge)
    size = np.stack([np.full(n, 0.01 * radius), np.full(n, 0.3 * radius), half], 1)
    pos = (p0 + p1) / 2 + radius * (1 + STANDOFF) * m1  # printed on the m1 side
    return Pieces(int(mujoco.mjtGeom.mjGEOM_BOX), size, pos, np.stack([m1, m2, t], axis=2))


def _helices(verts, frames, radius, rest, period, hands: tuple[int, ...]) -> Pieces:
    """Flat strips along helices of lay length ``period`` (one per entry of ``hands``: +1
    right-handed, -1 left-handed, evenly spaced in phase per hand)."""
    n_edges = len(frames)
    per_edge = max(1, math.ceil(rest / (period / HELIX_PIECES)))
    e = np.repeat(np.arange(n_edges), per_edge)
    k = np.tile(np.arange(per_edge), n_edges)
    u0, u1 = k / per_edge, (k + 1) / per_edge
    s0, s1 = (e + u0) * rest, (e + u1) * rest
    dtheta = 2 * math.pi * rest / per_edge / period
    r_end = radius * (1 + STANDOFF) / math.cos(dtheta / 2)  # chord midpoints on the standoff
    t, m1, m2 = (frames[e, :, i] for i in range(3))
    sizes, poss, mats = [], [], []
    counts = {h: hands.count(h) for h in set(hands)}
    seen: dict[int, int] = {}
    for hand in hands:
        j = seen.get(hand, 0)
        seen[hand] = j + 1
        phase = 2 * math.pi * j / counts[hand]
        ends = []
        for s, u in ((s0, u0), (s1, u1)):
            th = hand * 2 * math.pi * s / period + phase
            radial = np.cos(th)[:, None] * m1 + np.sin(th)[:, None] * m2
            ends.append(_along(verts, e, u) + r_end * radial)
        a, b = ends
        z = b - a
        length = np.linalg.norm(z, axis=1)
        z /= np.maximum(length, 1e-18)[:, None]
        mid = (a + b) / 2
        axis_pt = _along(verts, e, (u0 + u1) / 2)
        x = mid - axis_pt
        x -= np.einsum("ij,ij->i", x, z)[:, None] * z
        x /= np.maximum(np.linalg.norm(x, axis=1), 1e-18)[:, None]
        y = np.cross(z, x)
        n = len(e)
        sizes.append(np.stack([np.full(n, 0.01 * radius), np.full(n, 0.2 * radius), length / 2], 1))
        poss.append(mid)
        mats.append(np.stack([x, y, z], axis=2))
    return Pieces(
        int(mujoco.mjtGeom.mjGEOM_BOX),
        np.concatenate(sizes),
        np.concatenate(poss),
        np.concatenate(mats),
    )


def pattern_pieces(
    pattern: str,
    verts: np.ndarray,
    frames: np.ndarray,
    radius: float,
    rest: float,
    period: float,
) -> Pieces | None:
    """The geoms that draw ``pattern`` on one cable: ``verts`` (V, 3) its vertices, ``frames``
    (V - 1, 3, 3) its edges' material frames, ``rest`` the rest length of an edge (m),
    ``period`` the pattern's period (m).  None for a solid cable."""
    if pattern == "solid":
        return None
    verts = np.asarray(verts, float)
    if pattern == "stripes":
        return _stripes(verts, frames, radius, rest, period)
    if pattern == "marking":
        return _marking(verts, frames, radius, rest, period)
    if pattern == "twisted":
        return _helices(verts, frames, radius, rest, period, (1, 1, 1))
    if pattern == "braided":
        return _helices(verts, frames, radius, rest, period, (1, 1, -1, -1))
    raise InputError(f"unknown cable pattern {pattern!r}")


def pattern_geom_bound(spec: HoseSpec) -> int:
    """At most how many geoms :func:`pattern_pieces` draws on the cable ``spec``."""
    c = spec.cable
    if c.pattern == "solid":
        return 0
    edges = spec.n_vertices - 1
    rest = spec.length / edges
    if c.pattern in ("twisted", "braided"):
        return edges * math.ceil(rest / (c.pattern_period / HELIX_PIECES)) * 4
    return edges * (math.ceil(rest / c.pattern_period) + 2)


def add_pattern_geoms(
    scene: mujoco.MjvScene, pieces: Pieces, rgb: tuple[float, float, float], flex_id: int
) -> int:
    """Append ``pieces`` to ``scene`` as geoms of flex ``flex_id`` (labelled as its cable)
    drawn in ``rgb``; returns how many fitted (the scene's ``maxgeom`` bounds them)."""
    n = min(len(pieces), scene.maxgeom - scene.ngeom)
    rgba = np.array([*rgb, 1.0])
    flex = int(mujoco.mjtObj.mjOBJ_FLEX)
    dynamic = int(mujoco.mjtCatBit.mjCAT_DYNAMIC)
    mats = pieces.mat.reshape(-1, 9)
    for i in range(n):
        k = scene.ngeom
        g = scene.geoms[k]
        mujoco.mjv_initGeom(g, pieces.kind, pieces.size[i], pieces.pos[i], mats[i], rgba)
        g.objtype, g.objid, g.category, g.segid = flex, flex_id, dynamic, k
        scene.ngeom = k + 1
    return n
