"""The table-top scene (``SceneConfig.surface = "table"``): cables lying and crossing on a mat
on the table, the first end of each plugged into a socket on the table, the far end plugged
into another socket or free.  Pure NumPy, like :mod:`cablesim.sim.layout`, which calls
:func:`place_on_table` for each cable, :func:`separate` on their start shapes and
:func:`socket_point` for each end (the MJCF of the mat and the sockets is built in
:mod:`cablesim.sim.world`).

A start shape leaves its socket along the socket's yaw, climbs within the first few
centimetres to its own height (cable ``rank`` r lies at ``radius + 2 mm + r (2.2 r_max + 2 mm)``
above the table, so that no two start shapes touch) and wanders through two to four points
drawn in ``table.region``, smoothed; a cable plugged at both ends is given a lateral wave
whose amplitude makes the path exactly as long as the cable.  No start shape bends tighter
than ``MIN_BEND_RADIUS`` in plan view (:func:`unkink` rounds the corners).  A path that
crosses itself (a flex does not collide with itself) or passes within 5 cm of an earlier
cable's plugged end (where that cable climbs from the socket's height to its own) is drawn
again, and a cable takes a socket no earlier cable passes within 5 cm of.  Settling lets the
upper cables fall onto the lower ones: the crossings of the settled scene are real contacts.
"""

from __future__ import annotations

import math

import numpy as np

from cablesim.cables import CableKind
from cablesim.sim.config import SceneConfig, TableConfig, hose_vertex_count

LEAD = 0.06  # m: a start shape leaves its socket straight for this long
CLIMB = 0.04  # m: and reaches its own height within this arc length
PLUG_LENGTH = 0.03  # m: the plug on a cable end, inside the socket's mouth
SOCKET_HALF = (0.025, 0.03)  # m: half-sizes of a socket box along and across its yaw
MAX_REDRAWS = 50  # path draws before the least flawed one is taken
SOCKET_CLEARANCE = 0.05  # m kept between a path and another cable's plugged end
MAT_TOP = 0.0005  # m: the mat's top above the table (cablesim.episode.surface.TABLE.height)
#: m: how far the mat's box reaches down into the table top.  A mat only 0.5 mm thick trapped a
#: cable pressed through it (the settling cables fall onto one another): with its centre below
#: the mat's middle, the mat pushed it down and the table up, and it jittered at 2-80 mm/s
#: for good (table seeds 9102, 9213, 9219 and 9227 never settled).  Its top stays at MAT_TOP.
MAT_DEPTH = 0.015
#: m: the tightest bend of a start shape in plan view.  Smoothed random waypoints alone turned
#: by 90-130 degrees between two neighbouring vertices on most cables (a waypoint behind a
#: socket, a free end reversing at a spare point, a wave on a curved path); the first step's
#: bending forces then stretched an edge by 25-45 %, and the dense-Newton rescue of those
#: steps cost 8-28 s of CPU per scene.
MIN_BEND_RADIUS = 0.06


def socket_direction(table: TableConfig, connector: int) -> np.ndarray:
    """Unit world direction (x, y, 0) in which a cable leaves socket ``connector``."""
    yaw = table.connectors[connector][2]
    return np.array([math.cos(yaw), math.sin(yaw), 0.0])


def socket_point(cfg: SceneConfig, connector: int) -> np.ndarray:
    """World position of a plugged cable end: the front of the plug in socket ``connector``."""
    x, y, _ = cfg.table.connectors[connector]
    d = socket_direction(cfg.table, connector)
    return np.array([x, y, cfg.table.socket_height]) + d * PLUG_LENGTH


def cable_height(cable: CableKind, rank: int, r_max: float) -> float:
    """The height of the centre line of the cable of ``rank`` in its start shape."""
    return cable.radius + 0.002 + rank * (2.2 * r_max + 0.002)


def place_on_table(
    cfg: SceneConfig,
    rng: np.random.Generator,
    free: list[int],
    length: float,
    cable: CableKind,
    rank: int,
    r_max: float,
    to_come: int,
    earlier: list[np.ndarray] | None = None,
) -> tuple[tuple[int, ...], float, float, np.ndarray]:
    """A lying cable's sockets (taken from ``free``), bulge (0), height and start shape
    (``n_vertices`` x 3), all drawn from ``rng``.  ``earlier``: the start shapes placed before
    it; a socket they pass within 5 cm of is taken only when no other is free, and this
    cable's path keeps 5 cm from their sockets (where they climb to their heights)."""
    t = cfg.table
    earlier = earlier or []
    used = [(float(p[0, 0]), float(p[0, 1])) for p in earlier]
    used += [(float(p[-1, 0]), float(p[-1, 1])) for p in earlier]

    def clear(c: int) -> bool:
        q = socket_point(cfg, c)[:2]
        return all(np.linalg.norm(p[:, :2] - q, axis=1).min() >= SOCKET_CLEARANCE for p in earlier)

    pool = [c for c in free if clear(c)] or free
    a = pool[int(rng.integers(0, len(pool)))]
    free.remove(a)
    want_both = rng.random() < cfg.hoses.both_ends_probability
    z = cable_height(cable, rank, r_max)
    n = hose_vertex_count(length, cable.segment_length)
    pa = socket_point(cfg, a)
    b = None
    if want_both and len(free) - 1 >= to_come:
        # another socket the cable reaches with some slack, not right beside this one
        ok = [
            c
            for c in free
            if 0.15 <= np.linalg.norm(socket_point(cfg, c)[:2] - pa[:2]) <= 0.7 * length - 2 * LEAD
            and clear(c)
        ]
        if ok:
            b = ok[int(rng.integers(0, len(ok)))]
    path, best = None, None
    for _ in range(MAX_REDRAWS):
        k = 2 + int(rng.integers(0, 3))
        x0, x1, y0, y1 = t.region
        points = np.stack([rng.uniform(x0, x1, k + 12), rng.uniform(y0, y1, k + 12)], 1)
        waypoints, spare = points[:k], points[k:]
        phase = float(rng.uniform(0.0, 2 * math.pi))
        waves = 1 + int(rng.integers(0, 3))
        path = _path(cfg, a, b, waypoints, length, phase, waves, spare)
        if path is None:
            continue
        path = unkink(path, n, keep_end=b is not None)
        # a path that crosses itself is worse than one that passes a socket
        flaws = 2 * _crosses_itself(path) + _near(path, used)
        if best is None or flaws < best[0]:
            best = (flaws, path)
        if flaws == 0:
            break
    if best is None:  # the far socket is out of the cable's reach on every draw: leave it free
        b = None
        path = _path(cfg, a, None, waypoints, length, phase, waves, np.tile(spare, (4, 1)))
        assert path is not None
        path = unkink(path, n, keep_end=False)
    else:
        path = best[1]
    free_end = b is None
    if not free_end:
        free.remove(b)
    shape = _lift(path, length, n, pa[2], z, both=not free_end)
    ends = (a,) if free_end else (a, b)
    return ends, 0.0, z, shape


def _path(
    cfg: SceneConfig,
    a: int,
    b: int | None,
    waypoints: np.ndarray,
    length: float,
    phase: float,
    waves: int,
    spare: np.ndarray,
) -> np.ndarray | None:
    """(N, 2) plan-view path of ``length`` from socket ``a`` (to socket ``b``) through
    ``waypoints`` (a free end goes on through the ``spare`` points as far as it needs); None
    when a path cannot be made that long (or, to ``b``, that short)."""
    pa = socket_point(cfg, a)[:2]
    da = socket_direction(cfg.table, a)[:2]
    pts = [pa, pa + LEAD * da, *waypoints]
    if b is not None:
        pb = socket_point(cfg, b)[:2]
        db = socket_direction(cfg.table, b)[:2]
        pts += [pb + LEAD * db, pb]
    smooth = _chaikin(np.asarray(pts), keep=(2, 2 if b is not None else 1))
    fine = _resample2(smooth, 0.002)
    if b is None:
        # a free end: on through the spare points (in the region) until long enough, then cut
        for extra in spare:
            if _arc(fine) >= length:
                break
            pts.append(extra)
            fine = _resample2(_chaikin(np.asarray(pts), keep=(2, 1)), 0.002)
        if _arc(fine) < length:
            return None
        return _cut(fine, length)
    base = _arc(fine)
    if base > length:
        return None
    s = _arc_positions(fine)
    tangent = np.gradient(fine, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], 1)
    # the wave spares the straight leads at both ends
    taper = np.clip(np.minimum(s - LEAD, s[-1] - LEAD - s) / 0.05, 0.0, 1.0)
    taper = taper * taper * (3 - 2 * taper)
    wave = np.sin(math.pi * waves * s / s[-1] + phase) * taper

    def waved(amp: float) -> np.ndarray:
        return fine + (amp * wave)[:, None] * normal

    lo, hi = 0.0, 0.4
    if _arc(waved(hi)) < length:
        return None
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _arc(waved(mid)) < length else (lo, mid)
    return waved(0.5 * (lo + hi))


def turn_angles(p: np.ndarray) -> np.ndarray:
    """The angle (rad) between each pair of neighbouring chords of polyline ``p``."""
    d = np.diff(p, axis=0)
    t = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    return np.arccos(np.clip((t[1:] * t[:-1]).sum(1), -1.0, 1.0))


def unkink(path: np.ndarray, n: int, keep_end: bool, radius: float = MIN_BEND_RADIUS) -> np.ndarray:
    """Plan-view ``path`` with no bend tighter than ``radius``, densified again (2 mm).

    The path is resampled to the cable's ``n`` vertices (chord c) and described by the turn at
    each vertex.  A turn beyond c / ``radius`` gives its excess, half each, to its neighbours
    until none exceeds it: a corner becomes an arc with the same total turn, and the path its
    length.  The chords on the plugged end's straight lead stay as they are.  Where
    ``keep_end`` (plugged at both ends) those on the far lead too: the turns are then
    corrected, within the same bound, until the path ends on it again (a planar chain's
    closure, by damped least squares)."""
    length = _arc(path)
    p = _resample_count(path, n)
    chord = length / (n - 1)
    limit = chord / radius
    # chords 0..lead-1 lie on the straight lead (within floating-point rounding)
    lead = min(max(1, int(math.floor(LEAD / chord + 1e-6))), (n - 1) // 2)
    d = np.diff(p, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    turn = np.diff(heading)  # turn[i]: at vertex i + 1, between chords i and i + 1
    lo = lead - 1  # the first turn that may change: where the lead ends
    hi = len(turn) - lead + 1 if keep_end else len(turn)  # exclusive: the far lead's start
    if hi - lo < 3:
        return _resample2(p, 0.002)
    turn[lo:hi] = _spread(turn[lo:hi], limit, keep_end)

    def chain(turns: np.ndarray) -> np.ndarray:
        h = np.concatenate([[heading[0]], heading[0] + np.cumsum(turns)])
        steps = chord * np.column_stack([np.cos(h), np.sin(h)])
        return np.vstack([p[:1], p[0] + np.cumsum(steps, 0)])

    q = chain(turn)
    if keep_end:
        total = float(turn.sum())  # the far lead's heading
        for _ in range(100):
            err = np.array([*(p[-1] - q[-1]), total - turn.sum()])
            if np.abs(err).max() < 1e-7:
                break
            r = q[-1] - q[lo + 1 : hi + 1]  # turning at vertex i + 1 swings the end about it
            jac = np.vstack([-r[:, 1], r[:, 0], np.ones(hi - lo)])
            step = jac.T @ np.linalg.solve(jac @ jac.T + 1e-9 * np.eye(3), err)
            step *= min(1.0, 0.2 / max(np.abs(step).max(), 1e-12))
            turn[lo:hi] = np.clip(turn[lo:hi] + step, -limit, limit)
            q = chain(turn)
        q[-1] = p[-1]  # exactly in the socket (the closure is within 0.1 um or so)
    return _resample2(q, 0.002)


def _spread(turn: np.ndarray, limit: float, keep_end: bool) -> np.ndarray:
    """:func:`unkink`'s corner rounding: each turn beyond ``limit`` passes its excess, half
    each, to its neighbours until none exceeds it (the sum stays the same)."""
    seg = turn.copy()
    for _ in range(500):
        excess = np.sign(seg) * np.maximum(np.abs(seg) - limit, 0.0)
        if not excess.any():
            break
        seg -= excess
        half = 0.5 * excess
        seg[1:] += half[:-1]  # to the next vertex
        seg[:-1] += half[1:]  # to the previous one
        seg[1] += half[0]  # the ends of the range pass their share inwards
        if keep_end:
            seg[-2] += half[-1]
        else:  # a free end's last turn may keep its share: the cable just ends there
            seg[-1] += half[-1]
    return seg


def _lift(
    path: np.ndarray, length: float, n: int, z_socket: float, z: float, both: bool
) -> np.ndarray:
    """The 3D start shape: ``n`` vertices along ``path`` at height ``z``, climbing from the
    socket's height within ``CLIMB`` of each plugged end; chords of (nearly) length/(n-1)."""
    s = _arc_positions(path)
    u = np.clip(s / CLIMB, 0.0, 1.0)
    ramp = u * u * (3 - 2 * u)
    if both:
        v = np.clip((s[-1] - s) / CLIMB, 0.0, 1.0)
        ramp = np.minimum(ramp, v * v * (3 - 2 * v))
    heights = z_socket + (z - z_socket) * ramp
    pts = np.column_stack([path, heights])
    # resample by 3D arc length to n vertices, then even out the chords (both ends fixed)
    return _even_chords(_resample_count(pts, n), length, both)


def _even_chords(p: np.ndarray, length: float, both: bool, iterations: int = 300) -> np.ndarray:
    """``p`` nudged to chords of ``length / (n - 1)`` (position-based projection), the first
    end held, and the last where ``both``."""
    out = p.copy()
    chord = length / (len(p) - 1)
    first, last = p[0].copy(), p[-1].copy()
    for _ in range(iterations):
        d = np.diff(out, axis=0)
        size = np.linalg.norm(d, axis=1, keepdims=True)
        corr = 0.5 * (1 - chord / np.maximum(size, 1e-12)) * d
        out[:-1] += corr
        out[1:] -= corr
        out[0] = first
        if both:
            out[-1] = last
    return out


def _chaikin(pts: np.ndarray, keep: tuple[int, int], iterations: int = 4) -> np.ndarray:
    """Corner-cutting smoothing that keeps the first ``keep[0]`` and last ``keep[1]`` points
    (the straight leads out of the sockets)."""
    head, tail = pts[: keep[0] - 1], pts[len(pts) - keep[1] + 1 :]
    mid = pts[keep[0] - 1 : len(pts) - keep[1] + 1]
    for _ in range(iterations):
        q = 0.75 * mid[:-1] + 0.25 * mid[1:]
        r = 0.25 * mid[:-1] + 0.75 * mid[1:]
        inner = np.empty((2 * len(q), 2))
        inner[0::2], inner[1::2] = q, r
        mid = np.vstack([mid[:1], inner, mid[-1:]])
    return np.vstack([head, mid, tail])


def _arc(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def _resample2(p: np.ndarray, step: float) -> np.ndarray:
    """Polyline ``p`` resampled evenly by arc length, at most ``step`` apart."""
    s = _arc_positions(p)
    return _at_arc(p, s, np.linspace(0.0, s[-1], max(2, int(math.ceil(s[-1] / step)) + 1)))


def _resample_count(p: np.ndarray, n: int) -> np.ndarray:
    """Polyline ``p`` resampled to ``n`` points evenly spaced by arc length (ends kept)."""
    s = _arc_positions(p)
    return _at_arc(p, s, np.linspace(0.0, s[-1], n))


def _at_arc(p: np.ndarray, s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The points of polyline ``p`` (arc positions ``s``) at arc positions ``t``."""
    return np.stack([np.interp(t, s, p[:, k]) for k in range(p.shape[1])], 1)


def _cut(p: np.ndarray, length: float) -> np.ndarray:
    s = _arc_positions(p)
    keep = s < length
    end = np.array([np.interp(length, s, p[:, k]) for k in range(p.shape[1])])
    return np.vstack([p[keep], end])


def _crosses_itself(path: np.ndarray, step: float = 0.01) -> bool:
    """Whether the plan-view path comes closer to itself than a cable's thickness away from
    its neighbourhood along it (a crossing or a near touch), on a coarse resampling."""
    q = _resample2(path, step)
    d = np.linalg.norm(q[:, None] - q[None], axis=2)
    idx = np.arange(len(q))
    apart = np.abs(idx[:, None] - idx[None]) * step > 0.06
    return bool((d[apart] < 0.025).any())


def separate(
    shapes: list[np.ndarray],
    radii: list[float],
    plugged: list[tuple[bool, bool]],
    gap: float = 0.003,
) -> list[np.ndarray]:
    """The start shapes with every place where two of them would touch (within the sum of
    their radii and ``gap``, on the rods densified to 5 mm) resolved by lifting one over the
    other, smoothly over 12 cm: the one placed later, unless it is climbing out of its socket
    there (its first or last 10 cm, plugged), then the earlier one bridges over the plug.  Such
    places remain where a socket had to be taken near an earlier cable (every free one was).
    A lifted shape's chords are evened out again to its length (plugged ends held)."""
    out = [p.copy() for p in shapes]
    lengths = [_arc(p) for p in shapes]
    for _ in range(3):  # lift, even the chords out, and again where that undid a lift
        for _ in range(6):  # a lift may meet a third cable
            if not _lift_clashes(out, radii, plugged, lengths, gap):
                break
        for k, p in enumerate(out):
            if abs(_arc(p) - lengths[k]) > 1e-3 * lengths[k]:
                out[k] = _even_chords(p, lengths[k], plugged[k][1])
    return out


def _lift_clashes(
    out: list[np.ndarray],
    radii: list[float],
    plugged: list[tuple[bool, bool]],
    lengths: list[float],
    gap: float,
) -> bool:
    """One pass of :func:`separate`'s lifts, in place; whether anything was lifted."""
    moved = False
    dense = [_dense(p) for p in out]
    for j in range(len(out)):
        for i in range(j):
            need = radii[i] + radii[j] + gap
            (a, va), (b, vb) = dense[i], dense[j]
            lo, hi = np.maximum(a.min(0), b.min(0)), np.minimum(a.max(0), b.max(0))
            if (lo - hi > need).any():  # bounding boxes apart
                continue
            d = np.linalg.norm(a[:, None] - b[None], axis=2)
            ki, kj = np.nonzero(d < need)
            if len(ki) == 0:
                continue
            ki, kj = va[ki], vb[kj]  # the nearest vertices
            s_j = _arc_positions(out[j])[kj]
            near = LEAD + CLIMB  # near its socket: the plug holds it, lift the other one
            climbing = (plugged[j][0] & (s_j < near)) | (plugged[j][1] & (s_j > lengths[j] - near))
            pairs = ((j, i, kj[~climbing], ki[~climbing]), (i, j, ki[climbing], kj[climbing]))
            for lift, over, k_l, k_o in pairs:
                rises: dict[int, float] = {}
                for kl, ko in zip(k_l.tolist(), k_o.tolist(), strict=True):
                    rise = out[over][ko, 2] + need - out[lift][kl, 2]
                    rises[kl] = max(rises.get(kl, 0.0), rise)
                for kl, rise in rises.items():
                    if rise > 0:
                        _bump(out[lift], kl, rise, plugged[lift])
                        moved = True
            if moved:
                dense[i], dense[j] = _dense(out[i]), _dense(out[j])
    return moved


def _dense(p: np.ndarray, step: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """Points along polyline ``p`` at most ``step`` apart, and the nearest vertex of each."""
    pts, owner = [p[:1]], [np.array([0])]
    for k in range(len(p) - 1):
        n = max(1, int(np.ceil(np.linalg.norm(p[k + 1] - p[k]) / step)))
        t = np.arange(1, n + 1)[:, None] / n
        pts.append(p[k] + t * (p[k + 1] - p[k]))
        owner.append(np.where(t[:, 0] < 0.5, k, k + 1))
    return np.concatenate(pts), np.concatenate(owner)


def _arc_positions(p: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def _bump(p: np.ndarray, k: int, rise: float, plugged: tuple[bool, bool]) -> None:
    """Raise shape ``p`` around vertex ``k`` by ``rise`` (smoothly to nothing 6 cm away along
    it), leaving a plugged end where it is."""
    if rise <= 0:
        return
    s = _arc_positions(p)
    u = np.clip(1 - np.abs(s - s[k]) / 0.06, 0.0, 1.0)
    w = u * u * (3 - 2 * u)
    if plugged[0]:
        w[0] = 0.0
    if plugged[1]:
        w[-1] = 0.0
    p[:, 2] = np.maximum(p[:, 2], p[:, 2] + rise * w)


def _near(path: np.ndarray, points: list[tuple[float, float]]) -> bool:
    """Whether the plan-view path passes within ``SOCKET_CLEARANCE`` of one of ``points`` (the
    plugged ends of the cables placed before, which climb from their sockets' height)."""
    if not points:
        return False
    q = _resample2(path, 0.005)
    p = np.asarray(points, float)
    return bool((np.linalg.norm(q[:, None] - p[None], axis=2) < SOCKET_CLEARANCE).any())
