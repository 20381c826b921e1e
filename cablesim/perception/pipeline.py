"""Stream-level perception: flow for every kept frame, then the per-action methods.

:func:`compute_statistics` runs one pass over a :class:`~cablesim.perception.frames.Stream`:
per action it keeps the samples where the gripper moved >= ``delta_g`` (SPEC 3.5), computes
d_g = (g_k - g_1) . u_a, estimates the flow of every kept frame to the target frame and feeds
the running accumulators.  With ``pipelined=True`` the flow runs in a worker thread (stage 1)
while the accumulators consume the results in order (stage 2) through a bounded queue; errors
in either stage propagate and the results are identical to the sequential path.

Every flow passes the per-sample steps of ``refine`` (:mod:`cablesim.perception.refine`: the
normal flow of image-based back ends, arm masks, optionally a photometric or forward-backward
check; a rejected pixel gets no sample in that frame) and only the target pixels of
``StreamStatistics.support`` (the arm's absence, optionally the depth foreground) may vote:
the remedies against motion bleeding across hose boundaries.  ``refine=None`` means :data:`~cablesim.perception.refine.DEFAULT_REFINE`.  With
``RefineParams.grow`` the masks of the current methods then grow along the target frame's
colour (an option: it relies on the hoses differing in colour).

:func:`segment_stream` turns the statistics into per-action masks and a vote image for one
method (``"correlation"``, ``"segmentation"`` or ``"ablation"``, or the published code's
``"published"``, ``"published-segmentation"`` and ``"published-ablation"`` of
:mod:`cablesim.perception.published`, which keep frames by their own rules; when both kinds
are asked for, each frame's flow is computed once); :func:`masks_from_statistics`
re-thresholds cached statistics cheaply (tuning).

``region`` is where flow is computed (:mod:`cablesim.perception.flow_region`); the default
``"auto"`` takes the crop and scale a stream read from the published layout carries in its
meta (``crop_origin``, ``crop_size``, ``scale_factor``), else the full image.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from cablesim.errors import InputError
from cablesim.perception.actions import (
    action_direction,
    gripper_displacements,
    subsample_by_gripper,
)
from cablesim.perception.correlation import (
    AblationParams,
    CorrelationAccumulator,
    CorrelationParams,
    CorrelationResult,
)
from cablesim.perception.flow import FlowEstimator, make_flow
from cablesim.perception.flow_region import FlowRegion, with_region
from cablesim.perception.frames import Frame, Stream
from cablesim.perception.published import (
    PUBLISHED_METHODS,
    PUBLISHED_THRESHOLDS,
    PublishedAccumulator,
    PublishedParams,
    PublishedResult,
    PublishedSegmentationResult,
    metric_scale,
    plan_published,
)
from cablesim.perception.published import describe as describe_published
from cablesim.perception.refine import (
    DEFAULT_REFINE,
    GrowParams,
    RefineParams,
    SampleFilter,
    colour_guide,
    grow_by_colour,
    support_mask,
)
from cablesim.perception.segmentation import (
    SegmentationAccumulator,
    SegmentationParams,
    SegmentationResult,
)
from cablesim.perception.votes import merge_votes, vote_image

Method = Literal[
    "correlation",
    "segmentation",
    "ablation",
    "published",
    "published-segmentation",
    "published-ablation",
]
CURRENT_METHODS: tuple[str, ...] = ("correlation", "segmentation", "ablation")
METHODS: tuple[str, ...] = CURRENT_METHODS + PUBLISHED_METHODS


@dataclass
class Job:
    """One kept frame: its action, its index among kept samples, d_g and gripper depth."""

    action: int
    index: int
    frame: Frame
    d_g: float
    z: float


@dataclass
class StreamStatistics:
    """Per-action statistics of one stream, enough to threshold any method."""

    shape: tuple[int, int]
    actions: list[int]
    n_samples: dict[int, int]
    correlation: dict[int, CorrelationResult] = field(default_factory=dict)
    segmentation: dict[int, SegmentationResult] = field(default_factory=dict)
    directions: dict[int, np.ndarray] = field(default_factory=dict)
    flow: dict[str, Any] = field(default_factory=dict)
    published: dict[int, PublishedResult] = field(default_factory=dict)
    published_segmentation: dict[int, PublishedSegmentationResult] = field(default_factory=dict)
    published_meta: dict[str, Any] = field(default_factory=dict)
    # target pixels allowed to vote (``cablesim.perception.refine.support_mask``); None: all
    support: np.ndarray | None = None
    # the same for the published methods: only when a refine was asked for explicitly (by
    # default they stay the published code's)
    published_support: np.ndarray | None = None
    refine: dict[str, Any] = field(default_factory=dict)
    # colour growth of the current methods' masks (``RefineParams.grow``): the parameters and
    # the target frame in CIELAB (``cablesim.perception.refine.colour_guide``); None: off
    grow: GrowParams | None = None
    guide: np.ndarray | None = None


@dataclass
class StreamSegmentation:
    """Result of :func:`segment_stream`: per-action masks and their vote image."""

    method: str
    masks: dict[int, np.ndarray]
    votes: np.ndarray  # HxW int16
    stats: StreamStatistics
    c0: dict[int, np.ndarray] = field(default_factory=dict)
    r2: dict[int, np.ndarray] = field(default_factory=dict)

    def mask(self, n: int | str = 1) -> np.ndarray:
        """Merged mask: ``n`` votes (``"union"`` = 1, ``"intersection"`` = all actions)."""
        return merge_votes(self.votes, n, len(self.masks))


def plan_jobs(stream: Stream, delta_g: float = 0.001) -> list[Job]:
    """Kept frames of every action in stream order, with their d_g and gripper depth."""
    jobs: list[Job] = []
    _ = stream.target  # raises if the last frame is not a target frame
    for a in stream.actions:
        frames = stream.action_frames(a)
        kept = subsample_by_gripper(frames, delta_g)
        d_g = gripper_displacements(kept, action_direction(frames))
        for i, (f, d) in enumerate(zip(kept, d_g, strict=True)):
            jobs.append(Job(a, i, f, float(d), float(f.gripper[2])))
    return jobs


def _flows_sequential(
    jobs: Sequence[Job], flow: FlowEstimator, target: Frame, check: SampleFilter | None = None
) -> Iterator[tuple[Job, np.ndarray]]:
    for job in jobs:
        phi = flow.frame_flow(job.frame, target)
        yield job, (phi if check is None else check.apply(phi, job.frame))


_DONE = object()


def _flows_pipelined(
    jobs: Sequence[Job],
    flow: FlowEstimator,
    target: Frame,
    queue_size: int = 4,
    check: SampleFilter | None = None,
) -> Iterator[tuple[Job, np.ndarray]]:
    """Stage 1 in a worker thread; yields (job, flow) in job order."""
    q: queue.Queue = queue.Queue(maxsize=max(1, int(queue_size)))
    stop = threading.Event()

    def put(item: object) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def worker() -> None:
        try:
            for job in jobs:
                if stop.is_set():
                    return
                phi = flow.frame_flow(job.frame, target)
                if check is not None:
                    phi = check.apply(phi, job.frame)
                if not put((job, phi)):
                    return
            put(_DONE)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the consumer
            put(exc)

    t = threading.Thread(target=worker, name="cablesim-flow", daemon=True)
    t.start()
    try:
        while True:
            item = q.get()
            if item is _DONE:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        t.join(timeout=10.0)


def iter_flows(
    stream: Stream,
    flow: FlowEstimator | str = "dis",
    delta_g: float = 0.001,
    pipelined: bool = True,
    queue_size: int = 4,
    refine: RefineParams | None = None,
) -> Iterator[tuple[Job, np.ndarray]]:
    """(job, flow to target) for every kept frame, in stream order; with ``refine`` the
    per-sample steps run (the normal flow; arm masks, photometric and forward-backward checks
    set rejected pixels to NaN)."""
    est = make_flow(flow)
    jobs = plan_jobs(stream, delta_g)
    target = stream.target
    check = None
    if refine is not None and refine.per_sample:
        check = SampleFilter(refine, target, est)
    if pipelined:
        return _flows_pipelined(jobs, est, target, queue_size, check)
    return _flows_sequential(jobs, est, target, check)


def _resolve_region(stream: Stream, region: FlowRegion | str | None) -> FlowRegion | None:
    if region == "auto":
        return FlowRegion.from_meta(stream.meta)
    if region is None or isinstance(region, FlowRegion):
        return region
    raise InputError(f"region must be a FlowRegion, 'auto' or None, got {region!r}")


def compute_statistics(
    stream: Stream,
    flow: FlowEstimator | str = "dis",
    methods: Sequence[str] = CURRENT_METHODS,
    correlation: CorrelationParams | AblationParams | None = None,
    segmentation: SegmentationParams | None = None,
    delta_g: float = 0.001,
    pipelined: bool = True,
    queue_size: int = 4,
    dtype: type = np.float32,
    published: PublishedParams | None = None,
    region: FlowRegion | str | None = "auto",
    refine: RefineParams | None = None,
) -> StreamStatistics:
    """One pass over the stream feeding the accumulators the ``methods`` need.

    ``refine`` (default :data:`~cablesim.perception.refine.DEFAULT_REFINE`) selects the bleed
    remedies of :mod:`cablesim.perception.refine`: per-sample checks on every flow, and the
    target pixels allowed to vote (``StreamStatistics.support``)."""
    if isinstance(stream, Sequence) and not isinstance(stream, Stream):
        stream = Stream(list(stream))
    if not isinstance(stream, Stream):
        raise InputError(f"stream must be a Stream, got {type(stream).__name__}")
    for m in methods:
        if m not in METHODS:
            raise InputError(f"unknown method {m!r}; choose from {METHODS}")
    cparams = correlation if correlation is not None else CorrelationParams()
    if isinstance(cparams, AblationParams):
        cparams = CorrelationParams(
            tau_n=cparams.tau_n, depth_mode=cparams.depth_mode, min_samples=cparams.min_samples
        )
    sparams = segmentation if segmentation is not None else SegmentationParams()
    pparams = published if published is not None else PublishedParams()
    want_corr = "correlation" in methods or "ablation" in methods
    want_seg = "segmentation" in methods
    want_pub_corr = "published" in methods or "published-ablation" in methods
    want_pub_seg = "published-segmentation" in methods
    want_pub = want_pub_corr or want_pub_seg
    target = stream.target
    shape = target.shape
    focal = target.intrinsics.f
    est = with_region(make_flow(flow), _resolve_region(stream, region))
    if not stream.actions:
        raise InputError("the stream has no action frames")
    corr: dict[int, CorrelationAccumulator] = {}
    seg: dict[int, SegmentationAccumulator] = {}
    counts: dict[int, int] = {}
    rp = DEFAULT_REFINE if refine is None else refine
    if not isinstance(rp, RefineParams):
        raise InputError(f"refine must be a RefineParams, got {type(rp).__name__}")

    def feed_current(job: Job, phi: np.ndarray) -> None:
        a = job.action
        if want_corr:
            if a not in corr:
                corr[a] = CorrelationAccumulator(shape, focal, cparams, target.depth, dtype)
            corr[a].update(phi, job.d_g, job.z)
        if want_seg:
            if a not in seg:
                seg[a] = SegmentationAccumulator(shape, sparams)
            seg[a].update(phi)
        counts[a] = counts.get(a, 0) + 1

    pub_meta: dict[str, Any] = {}
    pub_acc: PublishedAccumulator | None = None
    if not want_pub:
        for job, phi in iter_flows(stream, est, delta_g, pipelined, queue_size, rp):
            feed_current(job, phi)
    else:
        z, f, mdtype = metric_scale(stream, pparams)
        pub_meta = describe_published(pparams, z, f)
        pub_acc = PublishedAccumulator(shape, z / f, pparams, want_pub_corr, want_pub_seg, mdtype)
        index_of = {id(fr): i for i, fr in enumerate(stream.frames)}
        want_current = want_corr or want_seg
        cur = {index_of[id(j.frame)]: j for j in plan_jobs(stream, delta_g)} if want_current else {}
        pub = {j.frame_index: j for j in plan_published(stream, pparams.min_gripper_diff)}
        if not pub:
            raise InputError("the stream has no frame with a non-negative action code")
        units = [Job(-1, i, stream.frames[i], 0.0, 0.0) for i in sorted(set(cur) | set(pub))]
        flows = (
            _flows_pipelined(units, est, target, queue_size)
            if pipelined
            else _flows_sequential(units, est, target)
        )
        check = SampleFilter(rp, target, est) if want_current and rp.per_sample else None
        pub_check = None
        if refine is not None and refine.per_sample:
            pub_check = check if check is not None else SampleFilter(refine, target, est)
        for unit, phi in flows:
            # each filter runs at most once per frame (the two kinds may share one)
            checked = phi
            if check is not None and (unit.index in cur or pub_check is check):
                checked = check.apply(phi, unit.frame)
            if unit.index in cur:
                feed_current(cur[unit.index], checked)
            if unit.index in pub:
                if pub_check is None:
                    phi_pub = phi
                elif pub_check is check:
                    phi_pub = checked
                else:
                    phi_pub = pub_check.apply(phi, unit.frame)
                pub_acc.update(pub[unit.index], phi_pub)
    pub_corr, pub_seg = pub_acc.results() if pub_acc is not None else ({}, {})
    actions = sorted(counts) if counts else sorted(set(pub_corr) | set(pub_seg))
    if not counts:
        src = pub_corr or pub_seg
        counts = {a: r.n_samples for a, r in src.items()}
    return StreamStatistics(
        shape=shape,
        actions=actions,
        n_samples=counts,
        correlation={a: acc.result() for a, acc in corr.items()},
        segmentation={a: acc.result() for a, acc in seg.items()},
        directions={a: action_direction(stream.action_frames(a)) for a in actions},
        flow=est.describe(),
        published=pub_corr,
        published_segmentation=pub_seg,
        published_meta=pub_meta,
        support=support_mask(target, rp) if (want_corr or want_seg) else None,
        published_support=(
            support_mask(target, refine) if want_pub and refine is not None else None
        ),
        refine=rp.describe(),
        grow=rp.grow,
        guide=colour_guide(target.rgb) if rp.grow is not None else None,
    )


def masks_from_statistics(
    stats: StreamStatistics,
    method: str,
    params: CorrelationParams | SegmentationParams | AblationParams | PublishedParams | None = None,
) -> dict[int, np.ndarray]:
    """Per-action masks of ``method`` from cached statistics (only where ``stats.support``)."""
    masks = _raw_masks(stats, method, params)
    support = stats.published_support if method in PUBLISHED_METHODS else stats.support
    if support is not None:
        masks = {a: m & support for a, m in masks.items()}
    if method not in PUBLISHED_METHODS and stats.grow is not None and stats.guide is not None:
        masks = {a: grow_by_colour(m, stats.guide, stats.grow, support) for a, m in masks.items()}
    return masks


def _raw_masks(
    stats: StreamStatistics,
    method: str,
    params: CorrelationParams | SegmentationParams | AblationParams | PublishedParams | None = None,
) -> dict[int, np.ndarray]:
    if method == "correlation":
        p = params if params is not None else CorrelationParams()
        if not isinstance(p, CorrelationParams):
            raise InputError("method 'correlation' needs CorrelationParams")
        src = stats.correlation
        if not src:
            raise InputError("statistics were computed without the correlation method")
        return {a: src[a].mask(p.c0_min, p.r2_min) for a in stats.actions}
    if method == "ablation":
        p = params if params is not None else AblationParams()
        if not isinstance(p, AblationParams):
            raise InputError("method 'ablation' needs AblationParams")
        src = stats.correlation
        if not src:
            raise InputError("statistics were computed without the correlation moments")
        return {a: src[a].ablation_mask(p.std_min) for a in stats.actions}
    if method == "segmentation":
        p = params if params is not None else SegmentationParams()
        if not isinstance(p, SegmentationParams):
            raise InputError("method 'segmentation' needs SegmentationParams")
        if not stats.segmentation:
            raise InputError("statistics were computed without the segmentation method")
        return {a: stats.segmentation[a].mask(p.tau_v) for a in stats.actions}
    if method in PUBLISHED_METHODS:
        p = params if params is not None else PublishedParams()
        if not isinstance(p, PublishedParams):
            raise InputError(f"method {method!r} needs PublishedParams")
        if method == "published-segmentation":
            if not stats.published_segmentation:
                raise InputError("statistics were computed without published-segmentation")
            return {a: r.mask(p.vote) for a, r in stats.published_segmentation.items()}
        if not stats.published:
            raise InputError(f"statistics were computed without the {method!r} method")
        if method == "published":
            return {a: r.mask(p.r2, p.c0) for a, r in stats.published.items()}
        return {a: r.ablation_mask(p.std) for a, r in stats.published.items()}
    raise InputError(f"unknown method {method!r}; choose from {METHODS}")


def segment_from_statistics(
    stats: StreamStatistics, method: str = "correlation", params: Any = None
) -> StreamSegmentation:
    masks = masks_from_statistics(stats, method, params)
    votes = vote_image(list(masks.values()))
    out = StreamSegmentation(method=method, masks=masks, votes=votes, stats=stats)
    if method in ("correlation", "ablation"):
        out.c0 = {a: r.c0 for a, r in stats.correlation.items()}
        out.r2 = {a: r.r2 for a, r in stats.correlation.items()}
    elif method in ("published", "published-ablation"):
        f32 = np.float32
        out.c0 = {a: np.nan_to_num(r.c0).astype(f32) for a, r in stats.published.items()}
        out.r2 = {a: np.nan_to_num(r.r2).astype(f32) for a, r in stats.published.items()}
    return out


def segment_stream(
    stream: Stream,
    method: str = "correlation",
    flow: FlowEstimator | str = "dis",
    params: CorrelationParams | SegmentationParams | AblationParams | PublishedParams | None = None,
    delta_g: float = 0.001,
    pipelined: bool = True,
    queue_size: int = 4,
    region: FlowRegion | str | None = "auto",
    refine: RefineParams | None = None,
) -> StreamSegmentation:
    """Segment the grasped hose in the target frame of ``stream`` with one method.

    Returns per-action masks, their vote image, and (correlation, ablation and the published
    correlation) the c0 and R^2 maps.  ``refine``: the bleed remedies
    (:func:`compute_statistics`).
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose from {METHODS}")
    kw: dict[str, Any] = {"region": region}
    if method in PUBLISHED_METHODS:
        if params is not None and not isinstance(params, PublishedParams):
            raise InputError(f"method {method!r} needs PublishedParams")
        kw["published"] = params
    elif method == "segmentation":
        if params is not None and not isinstance(params, SegmentationParams):
            raise InputError("method 'segmentation' needs SegmentationParams")
        kw["segmentation"] = params
    else:
        if params is not None and not isinstance(params, CorrelationParams | AblationParams):
            raise InputError(f"method {method!r} needs CorrelationParams or AblationParams")
        kw["correlation"] = params
    stats = compute_statistics(
        stream,
        flow,
        methods=(method,),
        delta_g=delta_g,
        pipelined=pipelined,
        queue_size=queue_size,
        refine=refine,
        **kw,
    )
    return segment_from_statistics(stats, method, params)


def params_for_beta(
    method: str, beta: float = 0.4
) -> CorrelationParams | SegmentationParams | AblationParams | PublishedParams:
    """The thresholds of SPEC sections 7-8 for ``method`` at ``beta`` (1, 0.5, 0.4, 0.3, 0.2,
    0.1): the published table for every method (R^2, |c0| and vote share as fractions for
    cablesim's own correlation and segmentation); cablesim's ablation, whose statistic differs
    from the published one, keeps its default threshold."""
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose from {METHODS}")
    if beta not in PUBLISHED_THRESHOLDS:
        raise InputError(f"beta must be one of {sorted(PUBLISHED_THRESHOLDS)}, got {beta!r}")
    r2, c0, vote, _ = PUBLISHED_THRESHOLDS[beta]
    if method in PUBLISHED_METHODS:
        return PublishedParams(beta=beta)
    if method == "correlation":
        return CorrelationParams(c0_min=c0 / 100, r2_min=r2 / 100)
    if method == "segmentation":
        return SegmentationParams(tau_v=vote / 100)
    return AblationParams()
