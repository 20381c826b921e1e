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
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from cablesim.errors import InputError

if TYPE_CHECKING:
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
    for h in range(len(src.verts)) if hoses is None else (int(x) for x in hoses):
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
        idx = np.clip(k[:, None] + np.arange(-1, 3)[None, :], 0, len(vs) - 1)  # (n_e, 4)
        ps, pd = vs[idx], vd[idx]
        ps = ps - ps.mean(1, keepdims=True)
        pd = pd - pd.mean(1, keepdims=True)
        H = np.einsum("nki,nkj->nij", ps, pd)
        U, S, Vt = np.linalg.svd(H)
        d = np.sign(np.linalg.det(np.einsum("nij,njk->nik", U, Vt)).T)
        d[d == 0] = 1
        D = np.ones((n_e, 3))
        D[:, 2] = d
        fit = np.einsum("nji,nj,nkj->nik", Vt, D, U)  # V diag(d) U^T
        ts, td = _unit(vs[1:] - vs[:-1]), _unit(vd[1:] - vd[:-1])
        sv_s = np.linalg.svd(ps, compute_uv=False)
        sv_d = np.linalg.svd(pd, compute_uv=False)
        straight = (sv_s[:, 1] <= STRAIGHT_RATIO * np.maximum(sv_s[:, 0], 1e-18)) | (
            sv_d[:, 1] <= STRAIGHT_RATIO * np.maximum(sv_d[:, 0], 1e-18)
        )
        corr = _min_rotation(_unit(np.einsum("nij,nj->ni", fit, ts)), td)
        bend = np.einsum("nij,njk->nik", corr, fit)
        bend[straight] = _min_rotation(ts[straight], td[straight])
        sl = slice(src.edge_start[h], src.edge_start[h + 1])
        twist = _axis_rotation(td, dst.twist[sl] - src.twist[sl])
        R[sl] = np.einsum("nij,njk->nik", twist, bend)
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


def gt_flow(src: SimSnapshot, dst: SimSnapshot) -> GTFlow:
    """Exact flow from ``src`` pixels to ``dst`` (see module docstring)."""
    from cablesim.sim.camera import SimSnapshot

    if not isinstance(src, SimSnapshot) or not isinstance(dst, SimSnapshot):
        raise InputError("gt_flow needs two SimSnapshot objects (from SimCamera.snapshot())")
    _check_pair(src, dst)
    K = src.intrinsics
    h, w = src.shape
    flow = np.zeros((h, w, 2), np.float32)
    normal_flow = np.zeros((h, w, 2), np.float32)
    target_uv = None

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
        ]
        + [False]
    )
    seen = src.depth > 0
    cam_moved = not np.array_equal(src.T_world_camera, dst.T_world_camera)
    if cam_moved:  # a moving camera makes every visible pixel move
        moved_hose[:] = True
        moved_body[:] = True
    # look-up tables indexed by label + 2 (labels >= -2) and body + 1 (body >= -1)
    hose_lut = np.concatenate([[False, False], moved_hose[:-1]])
    body_lut = np.concatenate([[False], moved_body])
    hose_px = hose_lut[src.labels.astype(np.int64) + 2] & seen
    body_px = body_lut[src.body.astype(np.int64) + 1] & seen & (src.labels < 0)
    static_px = ~(hose_px | body_px)

    Ts, Td = src.T_world_camera, dst.T_world_camera
    moving = hose_px | body_px
    vv, uu = np.nonzero(moving)
    Y = np.zeros((len(vv), 3))
    hv = np.zeros(len(vv), bool)
    normals = None
    if len(vv):
        P = K.backproject(np.stack([uu, vv], -1), src.depth[vv, uu])
        X = P @ Ts[:3, :3].T + Ts[:3, 3]
        hv = hose_px[vv, uu]
        if hv.any():
            Y[hv], normals = _carry_hose(src, dst, X[hv], src.labels[vv[hv], uu[hv]])
        bv = ~hv
        if bv.any():
            b = src.body[vv[bv], uu[bv]]
            local = np.einsum("nji,nj->ni", src.body_mat[b], X[bv] - src.body_pos[b])
            Y[bv] = np.einsum("nij,nj->ni", dst.body_mat[b], local) + dst.body_pos[b]
        Q = (Y - Td[:3, 3]) @ Td[:3, :3]
        target_uv = K.project(Q)
        f = (target_uv - np.stack([uu, vv], -1)).astype(np.float32)
        flow[vv, uu] = f
        if normals is not None:
            fh = f[hv]
            nf = np.einsum("ij,ij->i", fh, normals)[:, None] * normals
            normal_flow[vv[hv], uu[hv]] = nf.astype(np.float32)

    # static pixels: visible in dst if dst shows the same kind of thing at the same depth
    valid = _visible_in_place(src, dst) & static_px
    if len(vv):
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


def _visible_in_place(src: SimSnapshot, dst: SimSnapshot) -> np.ndarray:
    """Per pixel: does dst show what src shows at the same pixel (same label, same depth)?"""
    zs, zd = src.depth, dst.depth
    near = np.abs(zd - zs) <= DEPTH_TOL_ABS + DEPTH_TOL_REL * zs
    return (src.labels == dst.labels) & ((near & (zd > 0)) | ((zd == 0) & (zs == 0)))


def _visible(
    labels: np.ndarray, z: np.ndarray, dst: SimSnapshot, u: np.ndarray, v: np.ndarray
) -> np.ndarray:
    dz = dst.depth[v, u]
    same = dst.labels[v, u] == labels
    near = (np.abs(dz - z) <= DEPTH_TOL_ABS + DEPTH_TOL_REL * np.abs(z)) & (dz > 0)
    return same & (near | ((dz == 0) & (z == 0)))


def _carry_hose(
    src: SimSnapshot, dst: SimSnapshot, X: np.ndarray, hose: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World points in dst of hose surface points ``X`` of src, and src image-space boundary
    normals (unit, (N, 2)) at them."""
    rs, rd = src.rod, dst.rod
    edge, tau = rs.nearest_edges(X, hose)
    R = edge_rotations(rs, rd, np.unique(hose))[edge]
    base_s = rs.a[edge] + tau[:, None] * (rs.b[edge] - rs.a[edge])
    base_d = rd.a[edge] + tau[:, None] * (rd.b[edge] - rd.a[edge])
    Y = base_d + np.einsum("nij,nj->ni", R, X - base_s)
    # image-space tangent of the edge at the point: d/ds of the projection of base + s * t
    T = src.T_world_camera
    K = src.intrinsics
    Pc = (base_s - T[:3, 3]) @ T[:3, :3]
    tc = (rs.b[edge] - rs.a[edge]) @ T[:3, :3]
    z = np.maximum(Pc[:, 2], 1e-9)
    du = K.fx * (tc[:, 0] * z - Pc[:, 0] * tc[:, 2]) / z**2
    dv = K.fy * (tc[:, 1] * z - Pc[:, 1] * tc[:, 2]) / z**2
    n = _unit(np.stack([-dv, du], -1))
    return Y, n


def flow_to_target(frame: SimSnapshot, target: SimSnapshot) -> GTFlow:
    """``FrameTruth.flow_to_target`` of ``frame``: in target pixels p, the point that target
    pixel p shows is at p + flow in ``frame`` (``gt_flow(target, frame)``)."""
    return gt_flow(target, frame)
