"""Ground-truth optical flow between two simulated frames (SPEC section 6).

``gt_flow(src, dst)`` gives, for every pixel p of ``src``, where the surface point seen at p
is in ``dst``: ``flow[p] = p_dst - p``, OpenCV convention (first image = ``src``).

- hose pixels: the pixel is back-projected to its 3D surface point and attached to the
  nearest edge segment of its hose (parameter along the segment + offset from the axis); in
  ``dst`` the point sits at the same parameter of the same edge with the offset rotated by
  that edge's rotation between the frames (local bending rotation from a best fit of the
  edge's neighbourhood, then the change of the edge's twist angle about its axis);
- geom pixels (robot links, anything on a body) are carried rigidly with their body; pixels
  of bodies that did not move (board, table) and empty pixels have exactly zero flow;
- ``valid`` is False where the carried point leaves the image or is occluded in ``dst``
  (the ``dst`` pixel shows another object or a surface nearer than the point).

``normal_flow`` is the projection of the flow onto the hose's image-space boundary normal
(perpendicular to the projected rod tangent), defined on hose pixels and 0 elsewhere.

For perception's convention (``FrameTruth.flow_to_target`` of frame k, in target pixels),
use ``flow_to_target(frame_k, target)`` which is ``gt_flow(target, frame_k)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cablesim.errors import InputError
from cablesim.sim.camera import SimSnapshot

DEPTH_TOL_ABS = 0.006  # m: a point is visible in dst if dst depth there is within this ...
DEPTH_TOL_REL = 0.005  # ... plus this fraction of its depth
STRAIGHT_RATIO = 1e-4  # neighbourhood considered straight: roll about the tangent unobservable


class GTFlow(NamedTuple):
    flow: np.ndarray  # HxWx2 float32, in src pixels: src p -> dst p + flow
    valid: np.ndarray  # HxW bool
    normal_flow: np.ndarray  # HxWx2 float32, hose pixels only (0 elsewhere)


@dataclass(frozen=True)
class RodGeometry:
    """Edge segments of all hoses of one snapshot, concatenated: edge e of hose h is global
    edge ``edge_start[h] + e``."""

    a: np.ndarray  # (E, 3) segment start (world)
    b: np.ndarray  # (E, 3) segment end
    twist: np.ndarray  # (E,)
    edge_start: np.ndarray  # (H + 1,)
    verts: tuple[np.ndarray, ...]
    frames: tuple[np.ndarray | None, ...] = ()  # per hose (E, 3, 3) material frames or None

    @staticmethod
    def from_snapshot(snap: SimSnapshot) -> RodGeometry:
        a, b, tw, start = [], [], [], [0]
        for v, t in zip(snap.hose_vertices, snap.hose_twist, strict=True):
            a.append(v[:-1])
            b.append(v[1:])
            tw.append(t if len(t) == len(v) - 1 else np.zeros(len(v) - 1))
            start.append(start[-1] + len(v) - 1)
        if not a:
            z = np.zeros((0, 3))
            return RodGeometry(z, z, np.zeros(0), np.zeros(1, np.int64), ())
        return RodGeometry(
            np.concatenate(a),
            np.concatenate(b),
            np.concatenate(tw),
            np.array(start, np.int64),
            tuple(np.asarray(v, float) for v in snap.hose_vertices),
            tuple(getattr(snap, "hose_frames", ())) or (None,) * len(snap.hose_vertices),
        )

    def nearest_edges(self, points: np.ndarray, hose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Global edge index and clamped segment parameter of the nearest edge of each point's
        own hose.  Vectorised per hose: nearest vertex, then the better of its two edges."""
        edge = np.zeros(len(points), np.int64)
        tau = np.zeros(len(points))
        for h in np.unique(hose):
            sel = np.flatnonzero(hose == h)
            v = self.verts[h]
            p = points[sel]
            # nearest vertex (small V: a dense (N, V) distance table is the fastest)
            d2 = (
                np.einsum("ij,ij->i", p, p)[:, None]
                - 2.0 * p @ v.T
                + np.einsum("ij,ij->i", v, v)[None, :]
            )
            nv = np.argmin(d2, axis=1)
            n_edges = len(v) - 1
            cands = np.stack([np.clip(nv - 1, 0, n_edges - 1), np.clip(nv, 0, n_edges - 1)], 1)
            best_d = np.full(len(sel), np.inf)
            for c in range(2):
                e = cands[:, c] + self.edge_start[h]
                t, dist = _segment_param(p, self.a[e], self.b[e])
                better = dist < best_d
                best_d[better], edge[sel[better]], tau[sel[better]] = (
                    dist[better],
                    e[better],
                    t[better],
                )
        return edge, tau


def _segment_param(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ab = b - a
    t = np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    t = np.clip(t, 0.0, 1.0)
    d = p - (a + t[:, None] * ab)
    return t, np.einsum("ij,ij->i", d, d)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-18)


def _min_rotation(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(E, 3, 3) smallest rotations taking unit vectors u to unit vectors v."""
    c = np.einsum("ij,ij->i", u, v)
    w = np.cross(u, v)
    k = np.zeros((len(u), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    anti = c < -1 + 1e-9  # opposite: any half turn about an axis perpendicular to u
    scale = 1.0 / np.where(anti, 1.0, 1.0 + c)
    R = np.eye(3)[None] + k + np.einsum("nij,njk->nik", k, k) * scale[:, None, None]
    if anti.any():
        perp = _unit(np.cross(u[anti], np.where(np.abs(u[anti, :1]) < 0.9, [1, 0, 0], [0, 1, 0])))
        R[anti] = 2 * perp[:, :, None] * perp[:, None, :] - np.eye(3)[None]
    return R


def _axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(E, 3, 3) rotations by ``angle`` about unit ``axis`` (Rodrigues)."""
    x, y, z = axis.T
    k = np.zeros((len(axis), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -z, y, -x
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = z, -y, x
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3)[None] + s * k + (1 - c) * np.einsum("nij,njk->nik", k, k)


def edge_rotations(
    src: RodGeometry, dst: RodGeometry, hoses: np.ndarray | None = None
) -> np.ndarray:
    """(E, 3, 3) rotation of each edge's material frame from ``src`` to ``dst``.

    The bending part is the best-fit (Kabsch) rotation of the edge's neighbourhood (its own
    vertices and one more on each side), corrected to take the src tangent exactly onto the
    dst tangent; where the neighbourhood is straight in either frame the roll about the
    tangent cannot be seen from the centreline and the smallest rotation is used.  The twist
    part rotates about the dst tangent by the change of the edge's twist angle (a positive
    angle turns right-handedly about the vertex k -> k+1 direction).  Where both snapshots
    carry MuJoCo's material frames of the hose (``RodGeometry.frames``, after physics steps),
    the rotation is exactly the one between them instead.  Only ``hoses`` (all by default)
    are computed; the other edges get the identity."""
    n = len(src.a)
    R = np.tile(np.eye(3), (n, 1, 1))
    sel = range(len(src.verts)) if hoses is None else [int(x) for x in hoses]
    if not len(sel):
        return R
    # every requested hose at once: edge e (global) of hose h has the neighbourhood vertices
    # e + h + (-1 .. 2), clipped to the hose, in the concatenated vertex arrays
    idx, edges = [], []
    for h in sel:
        vs, vd = src.verts[h], dst.verts[h]
        if vs.shape != vd.shape:
            raise InputError("the two snapshots have hoses with different vertex counts")
        fs = src.frames[h] if h < len(src.frames) else None
        fd = dst.frames[h] if h < len(dst.frames) else None
        if fs is not None and fd is not None:
            sl = slice(src.edge_start[h], src.edge_start[h + 1])
            R[sl] = np.einsum("nij,nkj->nik", fd, fs)  # F_dst F_src^T
            continue
        n_e = len(vs) - 1
        k = np.arange(n_e)
        v0 = int(src.edge_start[h]) + h  # first vertex of hose h in the concatenation
        idx.append(v0 + np.clip(k[:, None] + np.arange(-1, 3)[None, :], 0, n_e))
        edges.append(int(src.edge_start[h]) + k)
    if not idx:  # every hose carried MuJoCo's material frames
        return R
    idx_all, e = np.concatenate(idx), np.concatenate(edges)
    ps = np.concatenate(src.verts)[idx_all]
    pd = np.concatenate(dst.verts)[idx_all]
    ps = ps - ps.mean(1, keepdims=True)
    pd = pd - pd.mean(1, keepdims=True)
    H = np.einsum("nki,nkj->nij", ps, pd)
    U, S, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nij,njk->nik", U, Vt)).T)
    d[d == 0] = 1
    D = np.ones((len(e), 3))
    D[:, 2] = d
    fit = np.einsum("nji,nj,nkj->nik", Vt, D, U)  # V diag(d) U^T
    ts, td = _unit(src.b[e] - src.a[e]), _unit(dst.b[e] - dst.a[e])
    sv_s = np.linalg.svd(ps, compute_uv=False)
    sv_d = np.linalg.svd(pd, compute_uv=False)
    straight = (sv_s[:, 1] <= STRAIGHT_RATIO * np.maximum(sv_s[:, 0], 1e-18)) | (
        sv_d[:, 1] <= STRAIGHT_RATIO * np.maximum(sv_d[:, 0], 1e-18)
    )
    corr = _min_rotation(_unit(np.einsum("nij,nj->ni", fit, ts)), td)
    bend = np.einsum("nij,njk->nik", corr, fit)
    bend[straight] = _min_rotation(ts[straight], td[straight])
    twist = _axis_rotation(td, dst.twist[e] - src.twist[e])
    R[e] = np.einsum("nij,njk->nik", twist, bend)
    return R


def _check_pair(src: SimSnapshot, dst: SimSnapshot) -> None:
    if src.shape != dst.shape:
        raise InputError(f"snapshots have different sizes: {src.shape} and {dst.shape}")
    if src.intrinsics != dst.intrinsics:
        raise InputError("snapshots have different intrinsics")
    if len(src.hose_vertices) != len(dst.hose_vertices):
        raise InputError("snapshots have different numbers of hoses")
    if src.body_pos.shape != dst.body_pos.shape:
        raise InputError("snapshots come from different models (body counts differ)")


@dataclass(frozen=True)
class SourcePixels:
    """What :func:`gt_flow` needs of its *source* snapshot alone, computed once per snapshot
    (``_flow_source``): ``flow_to_target`` uses the target frame as the source of
    every flow of an interaction, so this work is shared by all of them.

    The candidates are the seen pixels that can move: hose pixels and pixels of geoms on a body
    other than the world, in raster order.  Hose candidates come first in ``hose_*`` order
    (their positions among the candidates are ``hose_index``)."""

    vv: np.ndarray  # (N,) row of each candidate
    uu: np.ndarray  # (N,) column
    label: np.ndarray  # (N,) int64 label (hose index >= 0, else < 0)
    body: np.ndarray  # (N,) int64 body id (-1 on hoses)
    X: np.ndarray  # (N, 3) world point seen at the pixel
    is_hose: np.ndarray  # (N,) bool
    # hose candidates only, in candidate order
    edge: np.ndarray  # (Nh,) global edge of the point's own hose
    tau: np.ndarray  # (Nh,) parameter along it
    base: np.ndarray  # (Nh, 3) the point's foot on the edge (world)
    offset: np.ndarray  # (Nh, 3) X - base
    normal: np.ndarray  # (Nh, 2) image-space boundary normal (unit)
    # per pixel, for the in-place visibility of static pixels
    depth_tol: np.ndarray  # HxW float32: DEPTH_TOL_ABS + DEPTH_TOL_REL * depth

    @staticmethod
    def from_snapshot(src: SimSnapshot) -> SourcePixels:
        K = src.intrinsics
        seen = src.depth > 0
        labels = src.labels.astype(np.int64)
        cand = seen & ((labels >= 0) | ((labels < 0) & (src.body >= 1)))
        vv, uu = np.nonzero(cand)
        label = labels[vv, uu]
        body = src.body[vv, uu].astype(np.int64)
        is_hose = label >= 0
        T = src.T_world_camera
        X = np.zeros((len(vv), 3))
        if len(vv):
            P = K.backproject(np.stack([uu, vv], -1), src.depth[vv, uu])
            X = P @ T[:3, :3].T + T[:3, 3]
        rs = _rod(src)
        Xh = X[is_hose]
        edge, tau = rs.nearest_edges(Xh, label[is_hose])
        base = rs.a[edge] + tau[:, None] * (rs.b[edge] - rs.a[edge])
        # image-space tangent of the edge at the point: d/ds of the projection of base + s * t
        Pc = (base - T[:3, 3]) @ T[:3, :3]
        tc = (rs.b[edge] - rs.a[edge]) @ T[:3, :3]
        z = np.maximum(Pc[:, 2], 1e-9)
        du = K.fx * (tc[:, 0] * z - Pc[:, 0] * tc[:, 2]) / z**2
        dv = K.fy * (tc[:, 1] * z - Pc[:, 1] * tc[:, 2]) / z**2
        normal = _unit(np.stack([-dv, du], -1))
        return SourcePixels(
            vv,
            uu,
            label,
            body,
            X,
            is_hose,
            edge,
            tau,
            base,
            Xh - base,
            normal,
            DEPTH_TOL_ABS + DEPTH_TOL_REL * src.depth,
        )


def _rod(snap: SimSnapshot) -> RodGeometry:
    """Per-snapshot rod segment data for ground-truth flow (computed once, kept on it)."""
    rod = snap.__dict__.get("_gt_rod")
    if rod is None:
        rod = snap.__dict__["_gt_rod"] = RodGeometry.from_snapshot(snap)
    return rod


def _flow_source(snap: SimSnapshot) -> SourcePixels:
    """What ground-truth flow *from* ``snap`` needs of it alone (computed once, kept on it)."""
    sp = snap.__dict__.get("_gt_source")
    if sp is None:
        sp = snap.__dict__["_gt_source"] = SourcePixels.from_snapshot(snap)
    return sp


def gt_flow(src: SimSnapshot, dst: SimSnapshot) -> GTFlow:
    """Exact flow from ``src`` pixels to ``dst`` (see module docstring)."""

    if not isinstance(src, SimSnapshot) or not isinstance(dst, SimSnapshot):
        raise InputError("gt_flow needs two SimSnapshot objects (from SimCamera.snapshot())")
    _check_pair(src, dst)
    K = src.intrinsics
    h, w = src.shape
    flow = np.zeros((h, w, 2), np.float32)
    normal_flow = np.zeros((h, w, 2), np.float32)
    sp = _flow_source(src)

    # which pixels move: hose pixels, and geom pixels of bodies whose pose changed
    moved_body = np.any(np.abs(src.body_pos - dst.body_pos) > 0, axis=1) | np.any(
        np.abs(src.body_mat - dst.body_mat) > 0, axis=(1, 2)
    )
    moved_body[0] = False
    moved_hose = np.array(
        [
            not (np.array_equal(vs, vd) and np.array_equal(ts, td))
            for vs, vd, ts, td in zip(
                src.hose_vertices, dst.hose_vertices, src.hose_twist, dst.hose_twist, strict=True
            )
        ],
        bool,
    )
    if not np.array_equal(src.T_world_camera, dst.T_world_camera):
        moved_hose[:] = True  # a moving camera makes every visible pixel move
        moved_body[:] = True
    hose_moves = moved_hose[np.maximum(sp.label[sp.is_hose], 0)]
    moving = np.zeros(len(sp.vv), bool)
    moving[sp.is_hose] = hose_moves
    not_hose = ~sp.is_hose
    moving[not_hose] = moved_body[sp.body[not_hose]]

    # static pixels: visible in dst if dst shows the same kind of thing at the same depth
    valid = _visible_in_place(src, dst, sp.depth_tol)
    if not moving.any():
        return GTFlow(flow, valid, normal_flow)

    Td = dst.T_world_camera
    vv, uu = sp.vv[moving], sp.uu[moving]
    hv = sp.is_hose[moving]
    Y = np.zeros((len(vv), 3))
    normals = None
    if hv.any():
        Y[hv] = _carry_hose(src, dst, sp, hose_moves)
        normals = sp.normal[hose_moves]
    bv = ~hv
    if bv.any():
        sel = moving & not_hose
        b = sp.body[sel]
        local = np.einsum("nji,nj->ni", src.body_mat[b], sp.X[sel] - src.body_pos[b])
        Y[bv] = np.einsum("nij,nj->ni", dst.body_mat[b], local) + dst.body_pos[b]
    Q = (Y - Td[:3, 3]) @ Td[:3, :3]
    target_uv = K.project(Q)
    f = (target_uv - np.stack([uu, vv], -1)).astype(np.float32)
    flow[vv, uu] = f
    if normals is not None:
        fh = f[hv]
        nf = np.einsum("ij,ij->i", fh, normals)[:, None] * normals
        normal_flow[vv[hv], uu[hv]] = nf.astype(np.float32)

    tu, tv = target_uv[:, 0], target_uv[:, 1]
    inside = (tu > -0.5) & (tu < w - 0.5) & (tv > -0.5) & (tv < h - 0.5)
    ok = np.zeros(len(vv), bool)
    ui = np.clip(np.rint(tu), 0, w - 1).astype(np.int64)
    vi = np.clip(np.rint(tv), 0, h - 1).astype(np.int64)
    ok[inside] = _visible(
        src.labels[vv[inside], uu[inside]], Q[inside, 2], dst, ui[inside], vi[inside]
    )
    valid[vv, uu] = ok
    return GTFlow(flow, valid, normal_flow)


def _visible_in_place(
    src: SimSnapshot, dst: SimSnapshot, depth_tol: np.ndarray | None = None
) -> np.ndarray:
    """Per pixel: does dst show what src shows at the same pixel (same label, same depth)?"""
    zs, zd = src.depth, dst.depth
    tol = DEPTH_TOL_ABS + DEPTH_TOL_REL * zs if depth_tol is None else depth_tol
    near = np.abs(zd - zs) <= tol
    return (src.labels == dst.labels) & ((near & (zd > 0)) | ((zd == 0) & (zs == 0)))


def _visible(
    labels: np.ndarray, z: np.ndarray, dst: SimSnapshot, u: np.ndarray, v: np.ndarray
) -> np.ndarray:
    dz = dst.depth[v, u]
    same = dst.labels[v, u] == labels
    near = (np.abs(dz - z) <= DEPTH_TOL_ABS + DEPTH_TOL_REL * np.abs(z)) & (dz > 0)
    return same & (near | ((dz == 0) & (z == 0)))


def _carry_hose(
    src: SimSnapshot, dst: SimSnapshot, sp: SourcePixels, moves: np.ndarray
) -> np.ndarray:
    """World points in dst of the hose candidates of ``sp`` selected by ``moves``: each point
    keeps its parameter on its edge and its offset from the axis, rotated with the edge."""
    rs, rd = _rod(src), _rod(dst)
    edge, tau = sp.edge[moves], sp.tau[moves]
    hoses = np.unique(sp.label[sp.is_hose][moves])
    R = edge_rotations(rs, rd, hoses)[edge]
    base_d = rd.a[edge] + tau[:, None] * (rd.b[edge] - rd.a[edge])
    return base_d + np.einsum("nij,nj->ni", R, sp.offset[moves])


def flow_to_target(frame: SimSnapshot, target: SimSnapshot) -> GTFlow:
    """``FrameTruth.flow_to_target`` of ``frame``: in target pixels p, the point that target
    pixel p shows is at p + flow in ``frame`` (``gt_flow(target, frame)``)."""
    return gt_flow(target, frame)
