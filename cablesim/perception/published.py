"""The published motion correlation (holesond/cmcor), a variant beside SPEC section 4's wording.

It reproduces ``cmcor.motion_correlation.compute_correlation_images`` and
``cmcor.motion_segmentation.compute_segmentation_images`` and the way the published evaluation
thresholds their stored maps (SPEC section 8):

- frames with a negative action code are skipped; the last frame is the target whatever its
  code (a stream read from the published layout keeps that code in ``meta["target_action"]``;
  a non-negative one makes the target also a sample of that action);
- a *block* is a run of frames with the same action code (codes that come back start a new
  block whose samples add to the same action's moments); its first frame is the reference:
  a sample with displacement 0; u_a and the reference position come from all frames of the
  action (principal axis, reference = its first frame); a frame is kept when its 1-D
  displacement d_g = (g - g_ref) . u_a changed by >= 1 mm since the last kept one;
- flow is metric: phi * Z / f with one Z per stream (the camera z of the first action frame's
  gripper) and f = fx; the metric flow is float64 when Z comes from a gripper point (the
  published code then multiplies by a NumPy scalar) and float32 when it is a number of the
  sequence file or the fallback (``meta["gripper_depth_source"]`` of a stream read from the
  published layout) or ``PublishedParams.gripper_depth``;
- per sample: relative flow r = phi_k - phi_ref; where |r| > 1.33 px its uncentred 2x2
  covariance grows and psi (its leading eigenvector) is re-solved; d_phi = r . psi where psi
  exists, else 0; |d_phi| < 0.67 px becomes 0; every kept sample enters every pixel's moments;
- fit d_phi = c0 d_g + c1 from the moments: R^2 and c0 where |det| > 1e-6 and var(d_phi) > 1e-8,
  NaN elsewhere; the ablation's map is std(d_phi) with the zeros;
- maps are stored as uint8: R^2 and |c0| x 100 (clipped at 2), std x 1e4 (clipped at 0.024 m),
  segmentation vote share x 100; masks: |c0| >= c0 % and R^2 >= R^2 %, std > threshold,
  share > vote %; per-beta thresholds in :data:`PUBLISHED_THRESHOLDS`.

Departures, all numerically negligible or defensive: the principal axis comes from NumPy's SVD
instead of scikit-learn's PCA (the same axis up to rounding and sign; the sign does not matter
to |c0|); products of d_g and float32 flow are formed in float64 (NumPy 2 semantics);
negative rounding residues of R^2 or var(d_phi), on which the published code stops with an
assertion, are read as 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.checks import as_flow
from cablesim.errors import InputError
from cablesim.frames import Stream

# beta -> (R^2 %, |c0| %, segmentation vote share %, flow std in 1e-4 m), as published
PUBLISHED_THRESHOLDS: dict[float, tuple[int, int, int, int]] = {
    1.0: (66, 17, 31, 26),
    0.5: (77, 20, 47, 32),
    0.4: (86, 18, 47, 34),
    0.3: (92, 36, 47, 35),
    0.2: (92, 48, 50, 38),
    0.1: (94, 50, 52, 47),
}
DEFAULT_FOCAL = 644.3  # px, the published code's fallback
DEFAULT_GRIPPER_DEPTH = 1.1  # m, the published code's fallback
PUBLISHED_METHODS: tuple[str, ...] = ("published", "published-segmentation", "published-ablation")


@dataclass(frozen=True)
class PublishedParams:
    """Thresholds of the published variant; ``None`` takes the ``beta`` row of the table."""

    beta: float = 0.4
    r2_pct: int | None = None  # mask: R^2 x 100 (truncated) >= r2_pct
    c0_pct: int | None = None  # and |c0| x 100 (truncated) >= c0_pct
    vote_pct: int | None = None  # segmentation: vote share x 100 (truncated) > vote_pct
    std_thr: int | None = None  # ablation: std(d_phi) x 1e4 (truncated) > std_thr
    thr_static_px: float = 0.67
    thr_moving_px: float = 1.33
    seg_moving_px: float = 2.0
    min_gripper_diff: float = 0.001  # m
    gripper_depth: float | None = None  # Z override (m)
    focal: float | None = None  # f override (px)

    def __post_init__(self) -> None:
        explicit = (self.r2_pct, self.c0_pct, self.vote_pct, self.std_thr)
        if None in explicit and self.beta not in PUBLISHED_THRESHOLDS:
            raise InputError(
                f"beta {self.beta} has no published thresholds; choose from "
                f"{sorted(PUBLISHED_THRESHOLDS)} or give all four thresholds"
            )
        for name, lo, hi in (
            ("r2_pct", 0, 255),
            ("c0_pct", 0, 255),
            ("vote_pct", 0, 255),
            ("std_thr", 0, 255),
        ):
            v = getattr(self, name)
            if v is not None and (int(v) != v or not lo <= v <= hi):
                raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {v!r}")
        for name in ("thr_static_px", "thr_moving_px", "seg_moving_px", "min_gripper_diff"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise InputError(f"{name} must be >= 0, got {v!r}")
        for name in ("gripper_depth", "focal"):
            v = getattr(self, name)
            if v is not None and (not np.isfinite(v) or v <= 0):
                raise InputError(f"{name} must be positive, got {v!r}")

    def _row(self, i: int, own: int | None) -> int:
        return int(own) if own is not None else PUBLISHED_THRESHOLDS[self.beta][i]

    @property
    def r2(self) -> int:
        return self._row(0, self.r2_pct)

    @property
    def c0(self) -> int:
        return self._row(1, self.c0_pct)

    @property
    def vote(self) -> int:
        return self._row(2, self.vote_pct)

    @property
    def std(self) -> int:
        return self._row(3, self.std_thr)


def quantise(x: np.ndarray, max_value: float, multiplier: float) -> np.ndarray:
    """The published ``image_to_uint8``: NaN -> 0, clip to [0, max_value], x * multiplier,
    truncated to uint8."""
    v = np.nan_to_num(np.asarray(x, np.float64), nan=0.0)
    v = np.clip(v, 0.0, max_value)
    return (v * multiplier).astype(np.uint8)


@dataclass
class PublishedResult:
    """Per-pixel maps of one action (float64; NaN where the fit is undefined)."""

    r2: np.ndarray
    c0: np.ndarray
    std_dphi: np.ndarray  # metres
    n_samples: int

    @property
    def r2_u8(self) -> np.ndarray:
        return quantise(self.r2, 2.0, 100)

    @property
    def abs_c0_u8(self) -> np.ndarray:
        return quantise(np.abs(self.c0), 2.0, 100)

    @property
    def std_u8(self) -> np.ndarray:
        return quantise(self.std_dphi, 0.024, 1e4)

    def mask(self, r2_pct: int, c0_pct: int) -> np.ndarray:
        return (self.abs_c0_u8 >= c0_pct) & (self.r2_u8 >= r2_pct)

    def ablation_mask(self, std_thr: int) -> np.ndarray:
        return self.std_u8 > std_thr


@dataclass
class PublishedSegmentationResult:
    votes: np.ndarray  # HxW float32 vote count
    n_samples: int

    @property
    def share_u8(self) -> np.ndarray:
        share = (np.float32(100) * self.votes) / max(self.n_samples, 1)
        return np.minimum(share, 255).astype(np.uint8)

    def mask(self, vote_pct: int) -> np.ndarray:
        return self.share_u8 > vote_pct


# --------------------------------------------------------------------------- sampling
@dataclass
class PublishedJob:
    """One kept frame: its index in the stream, action code, block number and d_g."""

    frame_index: int
    action: int
    block: int
    d_g: float

    @property
    def index(self) -> int:
        return self.frame_index


def published_action_codes(stream: Stream) -> list[int]:
    """Action code per frame; the target's own code from ``meta["target_action"]`` if given."""
    codes = [int(f.action) for f in stream.frames]
    t = stream.meta.get("target_action")
    if t is not None:
        codes[-1] = int(t)
    return codes


def reference_position(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first point, unit first principal axis) of an action's gripper positions."""
    g = np.asarray(points, np.float64)
    ref = g[0]
    c = g - g.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return ref, vt[0]


def plan_published(stream: Stream, min_gripper_diff: float = 0.001) -> list[PublishedJob]:
    """Kept frames in stream order, following the published sampling rules."""
    _ = stream.target
    codes = published_action_codes(stream)
    pos = np.array([f.gripper for f in stream.frames], np.float64)
    code_arr = np.asarray(codes)
    jobs: list[PublishedJob] = []
    last_action, block = -1, -1
    ref = v = None
    last_d: float | None = None
    for i, a in enumerate(codes):
        if a < 0:
            continue
        if a != last_action:
            ref, v = reference_position(pos[code_arr == a])
            last_action, block, last_d = a, block + 1, None
        d = float((pos[i] - ref) @ v)
        if last_d is not None and abs(d - last_d) < min_gripper_diff:
            continue
        last_d = d
        jobs.append(PublishedJob(i, a, block, d))
    return jobs


def metric_scale(
    stream: Stream, params: PublishedParams | None = None
) -> tuple[float, float, type]:
    """(Z, f, dtype of the metric flow): camera z of the first action frame's gripper and fx,
    unless overridden (module docstring)."""
    params = params or PublishedParams()
    z = params.gripper_depth
    dtype: type = np.float32
    if z is None and stream.meta.get("gripper_depth_source") in ("gripper_depth", "default"):
        z = float(stream.meta["gripper_depth"])
    elif z is None:
        dtype = np.float64
        codes = published_action_codes(stream)
        first = next((i for i, a in enumerate(codes) if a >= 0), None)
        z = DEFAULT_GRIPPER_DEPTH if first is None else float(stream.frames[first].gripper[2])
    f = params.focal if params.focal is not None else float(stream.target.intrinsics.fx)
    if not np.isfinite(z) or z <= 0:
        raise InputError(f"the gripper depth Z must be positive, got {z!r}")
    return float(z), float(f), dtype


# --------------------------------------------------------------------------- accumulation
@dataclass
class _Block:
    ref_metric: np.ndarray  # HxWx2 float32
    ref_px: np.ndarray
    v_flow: np.ndarray  # HxWx2 float32, NaN = no direction yet
    cxx: np.ndarray
    cyy: np.ndarray
    cxy: np.ndarray


@dataclass
class _Moments:
    sf: np.ndarray
    sf2: np.ndarray
    sfg: np.ndarray
    sg: float = 0.0
    sg2: float = 0.0
    n: int = 0


@dataclass
class _Votes:
    votes: np.ndarray
    n: int = 0


@dataclass
class PublishedAccumulator:
    """Moments and votes of every action of one stream; feed jobs in stream order."""

    shape: tuple[int, int]
    meters_per_pixel: float
    params: PublishedParams = field(default_factory=PublishedParams)
    correlation: bool = True
    segmentation: bool = True
    metric_dtype: type = np.float32  # see the module docstring

    def __post_init__(self) -> None:
        self._block_id: int | None = None
        self._block: _Block | None = None
        self._moments: dict[int, _Moments] = {}
        self._votes: dict[int, _Votes] = {}
        mpp = float(self.meters_per_pixel)
        if not np.isfinite(mpp) or mpp <= 0:
            raise InputError(f"meters per pixel must be positive, got {mpp!r}")
        self._thr_static = self.params.thr_static_px * mpp
        self._thr_moving = self.params.thr_moving_px * mpp

    def update(self, job: PublishedJob, flow_px: np.ndarray) -> None:
        flow_px = as_flow(flow_px, self.shape)
        if self.metric_dtype == np.float64:
            metric = flow_px * np.float64(self.meters_per_pixel)
        else:
            metric = flow_px * float(self.meters_per_pixel)
        if job.block != self._block_id:
            nanv = np.full((*self.shape, 2), np.nan, np.float32)
            z = np.zeros(self.shape, np.float64)
            self._block = _Block(metric.copy(), flow_px.copy(), nanv, z, z.copy(), z.copy())
            self._block_id = job.block
        b = self._block
        assert b is not None
        if self.correlation:
            d_flow = self._d_flow(metric, b)
            m = self._moments.get(job.action)
            if m is None:
                z = np.zeros(self.shape, np.float64)
                m = self._moments[job.action] = _Moments(z, z.copy(), z.copy())
            g = np.float64(job.d_g)
            m.sf += d_flow
            m.sf2 += d_flow * d_flow
            m.sfg += g * d_flow.astype(np.float64)
            m.sg += g
            m.sg2 += g * g
            m.n += 1
        if self.segmentation:
            rel = flow_px - b.ref_px
            moving = np.sqrt(rel[..., 0] ** 2 + rel[..., 1] ** 2) > self.params.seg_moving_px
            vt = self._votes.get(job.action)
            if vt is None:
                vt = self._votes[job.action] = _Votes(np.zeros(self.shape, np.float32))
            vt.votes[moving] += 1
            vt.n += 1

    def _d_flow(self, metric: np.ndarray, b: _Block) -> np.ndarray:
        """``compute_d_flow_pca``: project on psi, re-solved where this sample moves."""
        rel = metric - b.ref_metric
        d = np.sqrt(rel[..., 0] ** 2 + rel[..., 1] ** 2)
        moving = d > self._thr_moving
        rx, ry = rel[moving, 0], rel[moving, 1]
        b.cxx[moving] += rx**2
        b.cyy[moving] += ry**2
        b.cxy[moving] += rx * ry
        # leading eigenvector of [[a, c], [c, dd]] at the moving pixels (update_v_flow_pca)
        a, c, dd = b.cxx[moving], b.cxy[moving], b.cyy[moving]
        det = (a + dd) ** 2 - 4 * (a * dd - c * c)
        ok = det >= 0
        lam = 0.5 * (a[ok] + dd[ok] + np.sqrt(det[ok]))
        v1 = np.zeros((lam.size, 2), np.float32)
        v2 = np.zeros((lam.size, 2), np.float32)
        v1[:, 0] = lam - dd[ok]
        v1[:, 1] = c[ok]
        v2[:, 0] = c[ok]
        v2[:, 1] = lam - a[ok]
        n1 = np.sqrt(v1[:, 0] ** 2 + v1[:, 1] ** 2)
        n2 = np.sqrt(v2[:, 0] ** 2 + v2[:, 1] ** 2)
        sel = n2 > n1
        n1[sel] = n2[sel]
        v1[sel] = v2[sel]
        good = n1 > 1e-10
        rows, cols = np.nonzero(moving)
        rows, cols = rows[ok][good], cols[ok][good]
        b.v_flow[rows, cols] = v1[good] / n1[good, None]
        valid = np.isfinite(b.v_flow[..., 0])
        prod = b.v_flow[valid] * rel[valid]
        d[valid] = prod[:, 0] + prod[:, 1]
        d[~valid] = 0
        d[np.abs(d) < self._thr_static] = 0
        return d

    def results(self) -> tuple[dict[int, PublishedResult], dict[int, PublishedSegmentationResult]]:
        corr = {a: _fit(m) for a, m in sorted(self._moments.items())}
        seg = {
            a: PublishedSegmentationResult(v.votes.copy(), v.n)
            for a, v in sorted(self._votes.items())
        }
        return corr, seg


def _fit(m: _Moments) -> PublishedResult:
    """``linear_cod_from_moments`` of one action."""
    n = m.n
    det = n * m.sg2 - m.sg**2
    var_f = (1.0 / n) * m.sf2 - ((1.0 / n) * m.sf) ** 2
    std_f = np.sqrt(np.maximum(var_f, 0.0))
    valid = (abs(det) > 1e-6) & (var_f > 1e-8)
    a_nom = n * m.sfg - m.sg * m.sf
    b_nom = -m.sg * m.sfg + m.sg2 * m.sf
    a = a_nom[valid] / det
    b = b_nom[valid] / det
    sse = m.sf2[valid]
    sse = sse - 2 * a * m.sfg[valid]
    sse = sse - 2 * b * m.sf[valid]
    sse = sse + (a**2) * m.sg2
    sse = sse + 2 * a * b * m.sg
    sse = sse + n * b**2
    r2 = np.full(m.sf.shape, np.nan)
    r2[valid] = 1.0 - np.maximum(sse, 0.0) / (n * var_f[valid])
    c0 = np.full(m.sf.shape, np.nan)
    c0[valid] = a
    return PublishedResult(r2=r2, c0=c0, std_dphi=std_f, n_samples=n)


def describe(params: PublishedParams, z: float, f: float) -> dict[str, Any]:
    return {
        "beta": params.beta,
        "r2_pct": params.r2,
        "c0_pct": params.c0,
        "vote_pct": params.vote,
        "std_thr": params.std,
        "gripper_depth": z,
        "focal": f,
    }
