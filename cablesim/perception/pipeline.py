"""Stream-level perception: flow for every kept frame, then the per-action methods.

:func:`compute_statistics` runs one pass over a :class:`~cablesim.frames.Stream`:
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
:mod:`cablesim.perception.published`, which keep frames by their own rules, or a user's method:
any spec of :data:`~cablesim.perception.methods.SEGMENTATION_METHODS`).  Methods are objects
(:class:`~cablesim.perception.methods.SegmentationMethod`): :func:`compute_statistics` makes
one accumulator per statistic the methods need and feeds each the frames it plans; a frame
several methods plan has its flow computed once.  :func:`masks_from_statistics` re-thresholds
cached statistics cheaply (tuning).

``region`` is where flow is computed (:mod:`cablesim.perception.flow_region`); the default
``"auto"`` takes the crop and scale a stream read from the published layout carries in its
meta (``crop_origin``, ``crop_size``, ``scale_factor``), else the full image.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Frame, Stream
from cablesim.perception.actions import action_direction
from cablesim.perception.correlation import AblationParams, CorrelationParams
from cablesim.perception.flow import FlowEstimator, make_flow
from cablesim.perception.flow_region import FlowRegion, with_region
from cablesim.perception.methods import (
    CURRENT_METHODS,
    METHODS,
    SegmentationMethod,
    StreamContext,
    make_method,
    method_label,
)
from cablesim.perception.published import PUBLISHED_METHODS, PUBLISHED_THRESHOLDS, PublishedParams
from cablesim.perception.refine import (
    DEFAULT_REFINE,
    RefineParams,
    SampleFilter,
    colour_guide,
    grow_by_colour,
    support_mask,
)
from cablesim.perception.segmentation import SegmentationParams
from cablesim.perception.stats import Job, StreamStatistics, plan_jobs
from cablesim.perception.votes import merge_votes, vote_image

Method = Literal[
    "correlation",
    "segmentation",
    "ablation",
    "published",
    "published-segmentation",
    "published-ablation",
]

__all__ = [
    "CURRENT_METHODS",
    "METHODS",
    "PUBLISHED_METHODS",
    "Job",
    "StreamSegmentation",
    "StreamStatistics",
    "compute_statistics",
    "iter_flows",
    "masks_from_statistics",
    "params_for_beta",
    "plan_jobs",
    "segment_from_statistics",
    "segment_stream",
]


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


_DONE = object()


def _pipelined(items: Iterable[Any], work: Callable[[Any], Any], queue_size: int) -> Iterator[Any]:
    """``work(item)`` for every item in a worker thread (stage 1); yields the results in
    order while the caller consumes them (stage 2); an error of either stage propagates."""
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
            for item in items:
                if stop.is_set():
                    return
                if not put(work(item)):
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


def _run(
    items: Sequence[Any], work: Callable[[Any], Any], pipelined: bool, queue_size: int
) -> Iterator[Any]:
    if pipelined:
        return _pipelined(items, work, queue_size)
    return (work(item) for item in items)


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

    def work(job: Job) -> tuple[Job, np.ndarray]:
        phi = est.frame_flow(job.frame, target)
        return job, (phi if check is None else check.apply(phi, job.frame))

    return _run(jobs, work, pipelined, queue_size)


def _resolve_region(stream: Stream, region: FlowRegion | str | None) -> FlowRegion | None:
    if region == "auto":
        return FlowRegion.from_meta(stream.meta)
    if region is None or isinstance(region, FlowRegion):
        return region
    raise InputError(f"region must be a FlowRegion, 'auto' or None, got {region!r}")


@dataclass
class _Group:
    """The methods sharing one statistic: one accumulator, its plan, its flow filter."""

    method: SegmentationMethod  # the first of them: it makes and stores the accumulator
    params: Any
    filtered: bool  # fed the flow after the per-sample checks
    acc: Any = None
    plan: list[tuple[int, Any]] = field(default_factory=list)


def _methods(methods: Sequence[str | SegmentationMethod]) -> list[SegmentationMethod]:
    if isinstance(methods, str | SegmentationMethod):
        methods = (methods,)
    objs = [make_method(m) for m in methods]
    if not objs:
        raise InputError("no method given: name at least one (e.g. 'correlation')")
    return objs


def compute_statistics(
    stream: Stream,
    flow: FlowEstimator | str = "dis",
    methods: Sequence[str | SegmentationMethod] = CURRENT_METHODS,
    correlation: CorrelationParams | AblationParams | None = None,
    segmentation: SegmentationParams | None = None,
    delta_g: float = 0.001,
    pipelined: bool = True,
    queue_size: int = 4,
    dtype: type = np.float32,
    published: PublishedParams | None = None,
    region: FlowRegion | str | None = "auto",
    refine: RefineParams | None = None,
    params: Mapping[str, Any] | None = None,
) -> StreamStatistics:
    """One pass over the stream feeding the accumulators the ``methods`` need.

    ``methods``: specs or :class:`~cablesim.perception.methods.SegmentationMethod` objects.
    Each statistic's accumulator gets the parameters of its method's ``params_key``: the
    built-ins' ``correlation``, ``segmentation`` and ``published`` keywords, any other
    method's entry in ``params`` (by its ``params_key``, by default its name).
    ``refine`` (default :data:`~cablesim.perception.refine.DEFAULT_REFINE`) selects the bleed
    remedies of :mod:`cablesim.perception.refine`: per-sample checks on every flow, and the
    target pixels allowed to vote (``StreamStatistics.support``)."""
    if isinstance(stream, Sequence) and not isinstance(stream, Stream):
        stream = Stream(list(stream))
    if not isinstance(stream, Stream):
        raise InputError(f"stream must be a Stream, got {type(stream).__name__}")
    objs = _methods(methods)
    given: dict[str, Any] = {
        "correlation": correlation,
        "segmentation": segmentation,
        "published": published,
        **(params or {}),
    }
    target = stream.target
    est = with_region(make_flow(flow), _resolve_region(stream, region))
    if not stream.actions:
        raise InputError("the stream has no action frames")
    rp = DEFAULT_REFINE if refine is None else refine
    if not isinstance(rp, RefineParams):
        raise InputError(f"refine must be a RefineParams, got {type(rp).__name__}")
    check = SampleFilter(rp, target, est) if rp.per_sample else None
    ctx = StreamContext(stream, target, target.shape, target.intrinsics.f, dtype, delta_g)
    groups: dict[str, _Group] = {}
    for m in objs:
        if m.key in groups:
            continue
        p = given.get(m.accumulation_key)
        filtered = check is not None and (m.refine_by_default or refine is not None)
        g = groups[m.key] = _Group(m, p, filtered)
        g.acc = m.accumulator(ctx, p)
        g.plan = m.plan(stream, p, delta_g)
    feeds = _feeds(groups.values())
    units = [(i, stream.frames[i], any(g.filtered for g, _ in feeds[i])) for i in feeds]

    def work(unit: tuple[int, Frame, bool]) -> tuple[int, np.ndarray, np.ndarray]:
        i, frame, want = unit
        phi = est.frame_flow(frame, target)
        # each filter runs at most once per frame (the methods planning it share the result)
        return i, phi, (check.apply(phi, frame) if want and check is not None else phi)

    for i, phi, checked in _run(units, work, pipelined, queue_size):
        for g, job in feeds[i]:
            g.acc.update(job, checked if g.filtered else phi)
    return _statistics(stream, objs, groups, est, rp, refine)


def _feeds(groups: Iterable[_Group]) -> dict[int, list[tuple[_Group, Any]]]:
    """Stream index -> the (group, job) pairs fed its flow, in the order flows are computed:
    the one plan's order when every group plans the same frames, else stream order."""
    groups = list(groups)
    orders = [[i for i, _ in g.plan] for g in groups]
    same = all(o == orders[0] for o in orders)
    order = orders[0] if same else sorted({i for o in orders for i in o})
    feeds: dict[int, list[tuple[_Group, Any]]] = {i: [] for i in order}
    for g in groups:
        for i, job in g.plan:
            feeds[i].append((g, job))
    return feeds


def _statistics(
    stream: Stream,
    objs: Sequence[SegmentationMethod],
    groups: dict[str, _Group],
    est: FlowEstimator,
    rp: RefineParams,
    refine: RefineParams | None,
) -> StreamStatistics:
    target = stream.target
    default_plan = [g for g in groups.values() if type(g.method).plan is SegmentationMethod.plan]
    by_default = any(m.refine_by_default for m in objs)
    stats = StreamStatistics(
        shape=target.shape,
        actions=[],
        n_samples={},
        flow=est.describe(),
        support=support_mask(target, rp) if by_default else None,
        published_support=(
            support_mask(target, refine)
            if refine is not None and not all(m.refine_by_default for m in objs)
            else None
        ),
        refine=rp.describe(),
        grow=rp.grow,
        guide=colour_guide(target.rgb) if rp.grow is not None else None,
    )
    for g in groups.values():
        g.method.store(stats, g.acc.result())
    first = default_plan[0] if default_plan else next(iter(groups.values()))
    stats.n_samples = first.method.n_samples(stats, first.plan)
    stats.actions = sorted(stats.n_samples)
    stats.directions = {a: action_direction(stream.action_frames(a)) for a in stats.actions}
    return stats


def masks_from_statistics(
    stats: StreamStatistics,
    method: str | SegmentationMethod,
    params: Any = None,
) -> dict[int, np.ndarray]:
    """Per-action masks of ``method`` from cached statistics (only where the method's
    support allows; grown along the colour for the methods the default remedies apply to)."""
    m = make_method(method)
    masks = m.masks(stats, params)
    support = m.support(stats)
    if support is not None:
        masks = {a: mk & support for a, mk in masks.items()}
    if m.refine_by_default and stats.grow is not None and stats.guide is not None:
        masks = {a: grow_by_colour(mk, stats.guide, stats.grow, support) for a, mk in masks.items()}
    return masks


def segment_from_statistics(
    stats: StreamStatistics, method: str | SegmentationMethod = "correlation", params: Any = None
) -> StreamSegmentation:
    m = make_method(method)
    masks = masks_from_statistics(stats, m, params)
    votes = vote_image(list(masks.values()))
    out = StreamSegmentation(method=method_label(method), masks=masks, votes=votes, stats=stats)
    out.c0, out.r2 = m.maps(stats)
    return out


def segment_stream(
    stream: Stream,
    method: str | SegmentationMethod = "correlation",
    flow: FlowEstimator | str = "dis",
    params: Any = None,
    delta_g: float = 0.001,
    pipelined: bool = True,
    queue_size: int = 4,
    region: FlowRegion | str | None = "auto",
    refine: RefineParams | None = None,
) -> StreamSegmentation:
    """Segment the grasped hose in the target frame of ``stream`` with one method.

    ``method``: a built-in's name, an installed plug-in's name, ``MODULE:CLASS`` or a
    :class:`~cablesim.perception.methods.SegmentationMethod`; ``flow`` likewise a flow back
    end's spec or a :class:`~cablesim.perception.flow.FlowEstimator`.  ``params`` go to both
    the pass and the thresholds (e.g. ``CorrelationParams`` for ``"correlation"``).

    Returns per-action masks, their vote image, and (correlation, ablation and the published
    correlation) the c0 and R^2 maps.  ``refine``: the bleed remedies
    (:func:`compute_statistics`).
    """
    m = make_method(method)
    if params is not None and not m.accepts(params):
        raise InputError(f"method {m.name!r} needs {_needs(m)}")
    stats = compute_statistics(
        stream,
        flow,
        methods=(m,),
        delta_g=delta_g,
        pipelined=pipelined,
        queue_size=queue_size,
        region=region,
        refine=refine,
        params={m.accumulation_key: params},
    )
    out = segment_from_statistics(stats, m, params)
    out.method = method_label(method)
    return out


def _needs(m: SegmentationMethod) -> str:
    if m.accumulation_key == "correlation":
        return "CorrelationParams or AblationParams"
    return m.params_type.__name__ if m.params_type is not None else "no parameters"


def params_for_beta(method: str | SegmentationMethod, beta: float = 0.4) -> Any:
    """The thresholds of SPEC sections 7-8 for ``method`` at ``beta`` (1, 0.5, 0.4, 0.3, 0.2,
    0.1): the published table for every method (R^2, |c0| and vote share as fractions for
    cablesim's own correlation and segmentation); cablesim's ablation, whose statistic differs
    from the published one, keeps its default threshold, and so does a method without a
    table of its own (:meth:`~cablesim.perception.methods.SegmentationMethod.params_for_beta`)."""
    m = make_method(method)
    if beta not in PUBLISHED_THRESHOLDS:
        raise InputError(f"beta must be one of {sorted(PUBLISHED_THRESHOLDS)}, got {beta!r}")
    return m.params_for_beta(beta)
