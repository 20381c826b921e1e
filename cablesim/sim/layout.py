"""Seeded scene layout: which connectors each hose uses, its length, colour, stiffness and
start shape.  Pure NumPy, independent of MuJoCo, so it is cheap to test and to print.

The board's layout is here; the table's (``SceneConfig.surface = "table"``) is in
:mod:`cablesim.sim.table`: :func:`sample_hoses` draws what both share and asks the surface
where each cable goes.

A hose is attached at its first end to the coupling on connector ``ends[0]`` and, when
``len(ends) == 2``, at its far end to connector ``ends[1]``.  Start shapes hang in front of the
board, each hose bulging out by its own distance (so no two start shapes intersect); what
would fall below the table is laid on it, each hose at its own height.

``SceneConfig.draw`` selects the draw: 0 takes the hoses from the seed's ``hoses`` stream,
k > 0 from child k of its ``scene_resample`` stream (a re-draw, see :mod:`cablesim.sim.session`).

Clutter: :func:`crossing_pairs` tells which hoses cross each other in the camera image (their
projected rods intersect inside the frame); the session requires the hose of interest to
cross at least one other hose (the thesis's clutter), re-drawing the scene when none does.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from cablesim.cables import GARDEN_HOSE, CableKind
from cablesim.seeding import stream
from cablesim.sim.config import SceneConfig, hose_vertex_count
from cablesim.sim.table import place_on_table, separate, socket_point

FEMALE_LENGTH = 0.05  # the female coupling on a hose end (mesh length)
FEMALE_OVERLAP = 0.014  # how far the coupling overlaps the male thread


@dataclass(frozen=True)
class HoseSpec:
    index: int
    name: str
    length: float
    n_vertices: int
    rgb: tuple[float, float, float]
    young: float
    ends: tuple[int, ...]  # connector indices
    bulge: float  # metres in front of the connector tips
    floor: float  # height at which the part that reaches the table lies
    cable: CableKind = GARDEN_HOSE  # its kind's parameters, with the config's overrides
    # the start shape where the surface draws it whole (the table), (n_vertices, 3); None:
    # computed from the ends, bulge and floor (the board)
    shape: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def both_ends(self) -> bool:
        return len(self.ends) == 2

    @property
    def kind(self) -> str:
        return self.cable.name

    @property
    def radius(self) -> float:
        return self.cable.radius


@dataclass(frozen=True)
class CameraPose:
    position: np.ndarray  # (3,) world
    look_at: np.ndarray  # (3,) world


def attach_point(cfg: SceneConfig, connector: int) -> np.ndarray:
    """World position where a hose end sits on a connector (the coupling's outer end; on the
    table, the plug's front end)."""
    if cfg.surface == "table":
        return socket_point(cfg, connector)
    y, z = cfg.board.connectors[connector]
    x = cfg.board.x - cfg.board.connector_length + FEMALE_OVERLAP - FEMALE_LENGTH
    return np.array([x, y, z])


def layout_rng(cfg: SceneConfig) -> np.random.Generator:
    """The generator of the hose layout of ``cfg``'s seed and draw."""
    if cfg.draw == 0:
        return stream(cfg.seed, "hoses")
    return stream(cfg.seed, "scene_resample", cfg.draw)


def sample_hoses(cfg: SceneConfig) -> list[HoseSpec]:
    """Each cable's kind parameters, length, stiffness, colour, connectors and start-shape
    offsets, drawn from the layout stream.  Cables of one kind draw exactly what the hoses
    drew before kinds existed (the same numbers from the same stream); mixed kinds space the
    start shapes by the thickest cable."""
    h = cfg.hoses
    cables = [h.cable(i) for i in range(h.count)]
    rng = layout_rng(cfg)
    free = list(range(cfg.connector_count()))
    colour_order = rng.permutation(max(len(c.colors) for c in cables))
    specs = []
    lengths = rng.uniform(h.length[0], h.length[1], h.count)
    ranges = {c.young for c in cables}
    if len(ranges) == 1:
        (lo, hi) = ranges.pop()
        youngs = np.exp(rng.uniform(np.log(lo), np.log(hi), h.count))
    else:
        u = rng.random(h.count)
        youngs = np.array(
            [
                np.exp(np.log(c.young[0]) + (np.log(c.young[1]) - np.log(c.young[0])) * u[i])
                for i, c in enumerate(cables)
            ]
        )
    bulge_rank = rng.permutation(h.count)
    r_max = max(c.radius for c in cables)
    for i in range(h.count):
        cable = cables[i]
        rank = int(bulge_rank[i])
        shape = None
        if cfg.surface == "table":
            ends, bulge, floor, shape = place_on_table(
                cfg, rng, free, float(lengths[i]), cable, rank, r_max, h.count - i - 1,
                [s.shape for s in specs if s.shape is not None],
            )  # fmt: skip
        else:
            ends, bulge, floor = _place_on_board(
                cfg, rng, free, float(lengths[i]), cable, rank, r_max, h.count - i - 1
            )
        # ``same_colour``: the colour the first cable draws, whatever this one's kind
        palette = cables[0].colors if h.same_colour else cable.colors
        slot = 0 if h.same_colour else i % len(colour_order)
        base = np.array(palette[int(colour_order[slot]) % len(palette)], float)
        jitter = cable.color_jitter
        rgb = np.clip(base + rng.uniform(-jitter, jitter, 3), 0, 1)
        n_vert = hose_vertex_count(float(lengths[i]), cable.segment_length)
        specs.append(
            HoseSpec(
                index=i,
                name=f"hose{i}",
                length=float(lengths[i]),
                n_vertices=n_vert,
                rgb=(float(rgb[0]), float(rgb[1]), float(rgb[2])),
                young=float(youngs[i]),
                ends=ends,
                bulge=bulge,
                floor=floor,
                cable=cable,
                shape=shape,
            )
        )
    if cfg.surface == "table":  # lift one cable over another where their start shapes touch
        shapes = separate(
            [s.shape for s in specs],  # type: ignore[misc]
            [s.radius for s in specs],
            [(True, s.both_ends) for s in specs],
        )
        specs = [replace(s, shape=p) for s, p in zip(specs, shapes, strict=True)]
    return specs


def _place_on_board(
    cfg: SceneConfig,
    rng: np.random.Generator,
    free: list[int],
    length: float,
    cable: CableKind,
    rank: int,
    r_max: float,
    to_come: int,
) -> tuple[tuple[int, ...], float, float]:
    """A hanging cable's connectors (taken from ``free``), its bulge out of the board and the
    height at which what reaches the table lies, by its ``rank`` among the cables."""
    a = free.pop(int(rng.integers(0, len(free))))
    ends: tuple[int, ...] = (a,)
    want_both = rng.random() < cfg.hoses.both_ends_probability
    bulge = 0.012 + (2.4 * r_max + 0.004) * rank
    floor = cable.radius + 0.004 + 2.6 * r_max * rank
    if want_both:
        pa = attach_point(cfg, a)
        # side by side (a hose cannot hang as a loop between two connectors one above the
        # other) and with some slack
        ok = [
            c
            for c in free
            if abs(attach_point(cfg, c)[1] - pa[1]) >= 0.12
            and np.linalg.norm(attach_point(cfg, c) - pa) < 0.8 * length
        ]
        # a hose attached at both ends must hang clear of the table
        ok = [
            c for c in ok if _lowest_point(pa, attach_point(cfg, c), length, bulge) > floor + 0.02
        ]
        # leave enough connectors for the hoses still to come
        if ok and len(free) - 1 >= to_come:
            b = ok[int(rng.integers(0, len(ok)))]
            free.remove(b)
            ends = (a, b)
    return ends, bulge, floor


def sample_camera(cfg: SceneConfig) -> CameraPose:
    rng = stream(cfg.seed, "camera")
    c = cfg.camera
    position, look_at = cfg.view()
    pos = np.asarray(position, float) + rng.uniform(-1, 1, 3) * c.position_jitter
    look = np.asarray(look_at, float) + rng.uniform(-1, 1, 3) * c.look_at_jitter
    return CameraPose(pos, look)


def _resample(points: np.ndarray, n: int) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n)
    return np.stack([np.interp(t, s, points[:, k]) for k in range(3)], 1)


def _arc_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _smooth_ramp(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0, 1)
    return u * u * (3 - 2 * u)


def _equalise_chords(pts: np.ndarray, chord: float, iterations: int = 300) -> np.ndarray:
    """Nudge a chain towards equal edge lengths, both ends fixed (position-based projection)."""
    p = pts.copy()
    for _ in range(iterations):
        d = np.diff(p, axis=0)
        length = np.linalg.norm(d, axis=1, keepdims=True)
        corr = 0.5 * (1 - chord / np.maximum(length, 1e-12)) * d
        p[:-1] += corr
        p[1:] -= corr
        p[0], p[-1] = pts[0], pts[-1]
    return p


def _hanging_curve(
    pa: np.ndarray, pb: np.ndarray, length: float, bulge: float, n: int = 400
) -> np.ndarray:
    """``n`` points from ``pa`` to ``pb`` (connectors side by side on the board) with chords of
    (nearly) ``length / (n - 1)``, bulging out of the board by ``bulge`` (smoothly, within ~5 cm
    of each end).  A hose much longer than the gap hangs as a U (two drops joined by a half
    circle as wide as the gap), a shorter one as a parabola under the line between the ends."""
    span = abs(pb[1] - pa[1])
    drop = length - np.pi * span / 2 - abs(pa[2] - pb[2])
    if drop > 0:
        r = span / 2
        bottom = min(pa[2], pb[2]) - drop / 2  # where the drops meet the half circle
        side = np.sign(pb[1] - pa[1]) or 1.0
        arc = np.linspace(np.pi, 2 * np.pi, 200)
        ya = pa[1] + r * side
        circle = np.stack(
            [np.full_like(arc, pa[0]), ya + side * r * np.cos(arc), bottom + r * np.sin(arc)], 1
        )
        p = np.vstack(
            [
                np.linspace(pa, [pa[0], pa[1], bottom], 100)[:-1],
                circle,
                np.linspace([pb[0], pb[1], bottom], pb, 100)[1:],
            ]
        )
    else:
        t = np.linspace(0, 1, 1200)

        def sagging(sag: float) -> np.ndarray:
            q = pa[None] * (1 - t[:, None]) + pb[None] * t[:, None]
            q[:, 2] -= sag * 4 * t * (1 - t)
            return q

        lo, hi = 0.0, 3.0
        for _ in range(50):  # the sag at which the curve has the hose's length
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _arc_length(sagging(mid)) < length else (lo, mid)
        p = sagging(0.5 * (lo + hi))
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    u = np.concatenate([[0], np.cumsum(seg)]) / seg.sum()
    p = p.copy()
    p[:, 0] -= bulge * _smooth_ramp(np.minimum(u, 1 - u) * seg.sum() / 0.05)
    return _equalise_chords(_resample(p, n), length / (n - 1))


def _lowest_point(pa: np.ndarray, pb: np.ndarray, length: float, bulge: float) -> float:
    return float(_hanging_curve(pa, pb, length, bulge)[:, 2].min())


def start_shape(cfg: SceneConfig, spec: HoseSpec) -> np.ndarray:
    """(n_vertices, 3) start positions with (nearly) the hose's arc length between vertices."""
    if spec.shape is not None:
        return spec.shape.copy()
    pa = attach_point(cfg, spec.ends[0])
    if spec.both_ends:
        return _hanging_curve(
            pa, attach_point(cfg, spec.ends[1]), spec.length, spec.bulge, spec.n_vertices
        )
    s = np.linspace(0, 1.5 * spec.length, 900)
    pts = np.stack(
        [pa[0] - spec.bulge * np.minimum(1, s / 0.05), np.full_like(s, pa[1]), pa[2] - s], 1
    )
    # what would go through the table is laid on it, running towards the robot (-x)
    below = pts[:, 2] < spec.floor
    if below.any():
        drop = spec.floor - pts[below, 2]
        pts[below, 2] = spec.floor
        pts[below, 0] -= drop
    # cut the path at the hose's length
    cum = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    end = np.array([np.interp(spec.length, cum, pts[:, k]) for k in range(3)])
    pts = _resample(np.vstack([pts[cum < spec.length], end]), spec.n_vertices)
    pts = _equalise_chords(pts, spec.length / (spec.n_vertices - 1))
    pts[:, 2] = np.maximum(pts[:, 2], spec.floor)  # the nudge may have dipped into the table
    return pts


# ---------------------------------------------------------------------- clutter
def project_points(
    points: np.ndarray, T_world_camera: np.ndarray, f: float, cx: float, cy: float
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) pixel coordinates (u, v) and (N,) depths of world ``points`` in a pinhole camera
    (OpenCV axes in ``T_world_camera``, focal length ``f`` px, principal point ``cx, cy``)."""
    T = np.asarray(T_world_camera, float)
    p = (np.asarray(points, float) - T[:3, 3]) @ T[:3, :3]
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([f * p[:, 0] / z + cx, f * p[:, 1] / z + cy], 1)
    return uv, z


def _segments_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n-1, m-1) bool: segment i of polyline ``a`` (n, 2) properly crosses segment j of ``b``;
    also returns nothing about touching end points (a crossing through a shared vertex counts
    on one of its segments)."""
    p, r = a[:-1, None], (a[1:] - a[:-1])[:, None]
    q, s = b[None, :-1], (b[1:] - b[:-1])[None]

    def cross(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]

    denom = cross(r, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(q - p, s) / denom
        w = cross(q - p, r) / denom
    return (np.abs(denom) > 1e-12) & (t >= 0) & (t < 1) & (w >= 0) & (w < 1)


def crossing_pairs(
    polylines: list[np.ndarray],
    T_world_camera: np.ndarray,
    f: float,
    cx: float,
    cy: float,
    width: int,
    height: int,
) -> set[tuple[int, int]]:
    """Pairs ``(i, j)``, i < j, of hoses whose rods (world polylines) cross in the image: their
    projections intersect at a point inside the ``width`` x ``height`` frame, both in front of
    the camera.  One hose passing in front of another is the clutter of the thesis."""
    uvs = []
    for pts in polylines:
        uv, z = project_points(pts, T_world_camera, f, cx, cy)
        uvs.append(np.where((z > 1e-6)[:, None], uv, np.nan))
    pairs = set()
    for i in range(len(uvs)):
        for j in range(i + 1, len(uvs)):
            a, b = uvs[i], uvs[j]
            hit = _segments_cross(a, b)
            for si, sj in zip(*np.nonzero(hit), strict=True):
                # the crossing point must lie in the frame
                r = a[si + 1] - a[si]
                s = b[sj + 1] - b[sj]
                qp = b[sj] - a[si]
                t = (qp[0] * s[1] - qp[1] * s[0]) / (r[0] * s[1] - r[1] * s[0])
                x = a[si] + t * r
                if 0 <= x[0] < width and 0 <= x[1] < height:
                    pairs.add((i, j))
                    break
    return pairs


def crossed_by(pairs: set[tuple[int, int]], hose: int) -> list[int]:
    """The hoses that cross ``hose`` (from :func:`crossing_pairs`), in index order."""
    return sorted({j if i == hose else i for i, j in pairs if hose in (i, j)})
