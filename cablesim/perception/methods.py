"""Motion-segmentation methods behind one small interface, in a registry (SPEC sections 4, 7, 8).

A :class:`SegmentationMethod` has two halves:

1. **the pass** (:func:`~cablesim.perception.pipeline.compute_statistics`): for each stream it
   makes an accumulator (:meth:`~SegmentationMethod.accumulator`) which is fed, in stream
   order, the flow to the target frame of every frame the method plans
   (:meth:`~SegmentationMethod.plan`; by default the frames where the gripper moved at least
   ``delta_g``, SPEC 3.5, as :class:`~cablesim.perception.stats.Job`); what the accumulator's
   ``result()`` returns is kept in the :class:`~cablesim.perception.stats.StreamStatistics`;
2. **the thresholds**: :meth:`~SegmentationMethod.masks` turns those statistics and the
   method's parameters into one boolean mask per action.  The pipeline then keeps only the
   target pixels that may vote and, optionally, grows the masks along the target's colour.

Methods that share a statistic :attr:`~SegmentationMethod.key` share one accumulator in a
pass (motion correlation and its ablation threshold the same moments).  For tuning (SPEC 7,
:mod:`cablesim.perception.tuning`, the thesis benchmark) a method gives a per-pixel score per
action with ``mask = score > t`` and a grid of thresholds t; a method that gives none is
tuned over its own fixed mask (one grid point).

The built-ins register themselves in :data:`SEGMENTATION_METHODS`: ``correlation``,
``segmentation``, ``ablation`` and the published code's ``published``,
``published-segmentation`` and ``published-ablation``.  A user's method is reached by an
installed package's entry point (group ``cablesim.methods``) or as ``MODULE:CLASS`` in any
spec (:mod:`cablesim.perception.registry`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Frame, Stream
from cablesim.perception.correlation import (
    AblationParams,
    CorrelationAccumulator,
    CorrelationParams,
)
from cablesim.perception.published import (
    PUBLISHED_METHODS,
    PUBLISHED_THRESHOLDS,
    PublishedAccumulator,
    PublishedJob,
    PublishedParams,
    metric_scale,
    plan_published,
)
from cablesim.perception.published import describe as describe_published
from cablesim.perception.registry import Registry
from cablesim.perception.segmentation import SegmentationAccumulator, SegmentationParams
from cablesim.perception.stats import StreamStatistics, plan_jobs

CURRENT_METHODS: tuple[str, ...] = ("correlation", "segmentation", "ablation")
#: the built-in methods' names (cablesim's own, then the published code's)
METHODS: tuple[str, ...] = CURRENT_METHODS + PUBLISHED_METHODS


@dataclass(frozen=True)
class StreamContext:
    """What an accumulator may know of its stream before the first flow arrives."""

    stream: Stream
    target: Frame
    shape: tuple[int, int]  # the target frame's (H, W)
    focal: float  # the target's focal length (px)
    dtype: type  # float type of the running sums
    delta_g: float  # m, the gripper motion that keeps a frame (SPEC 3.5)


class Accumulator(Protocol):
    """Running statistics of one stream: ``update`` per planned frame, then ``result``."""

    def update(self, job: Any, flow: np.ndarray) -> None: ...

    def result(self) -> Any: ...


class PerActionAccumulator:
    """One accumulator per action, made by ``make()`` on the action's first frame and fed by
    ``feed(accumulator, job, flow)``; ``result()`` is ``{action: accumulator.result()}``."""

    def __init__(
        self, make: Callable[[], Any], feed: Callable[[Any, Any, np.ndarray], None]
    ) -> None:
        self.make, self.feed = make, feed
        self.accumulators: dict[int, Any] = {}

    def update(self, job: Any, flow: np.ndarray) -> None:
        acc = self.accumulators.get(job.action)
        if acc is None:
            acc = self.accumulators[job.action] = self.make()
        self.feed(acc, job, flow)

    def result(self) -> dict[int, Any]:
        return {a: acc.result() for a, acc in self.accumulators.items()}


def _nth_largest(stack: np.ndarray, n: int) -> np.ndarray:
    """n-th largest value along axis 0 (-inf where fewer than n)."""
    if n > stack.shape[0]:
        return np.full(stack.shape[1:], -np.inf)
    return np.sort(stack, axis=0)[stack.shape[0] - n]


class SegmentationMethod(ABC):
    """One motion-segmentation method (module docstring).  Subclasses implement
    :meth:`accumulator` and :meth:`masks`; the rest has defaults.

    A method object holds no per-stream state (its accumulator does): the pipeline may build
    a new one from the same spec whenever it needs it.
    """

    #: the method's name in tables and summaries (the registry's name or spec is used instead
    #: where the method was reached by one)
    name: str = "method"
    #: the key of what it accumulates (default: the class and its constructor's attributes,
    #: :attr:`key`); methods with the same key share one accumulator in a pass, so they must
    #: accumulate the same thing (motion correlation and its ablation do)
    statistic: str | None = None
    #: the keyword of :func:`~cablesim.perception.pipeline.compute_statistics` (or key of its
    #: ``params``) whose value is handed to :meth:`accumulator` (default: ``name``)
    params_key: str | None = None
    #: the class of :meth:`masks`' parameters (None: the method takes none)
    params_type: type | None = None
    #: whether the default bleed remedies (:data:`~cablesim.perception.refine.DEFAULT_REFINE`:
    #: per-sample checks, the support mask, colour growth) apply unless the caller passes a
    #: refine explicitly; the published variants keep the published code's flow
    refine_by_default: bool = True
    #: tuning: the threshold t of ``mask = score > t`` and, optionally, a second threshold
    #: the score depends on (motion correlation's score is R^2 where |c0| > c0_min)
    threshold: str = "mask"
    outer_threshold: str | None = None

    @property
    def key(self) -> str:
        """What the method accumulates: ``statistic``, else its class (and the attributes its
        constructor set), so that two methods share an accumulator only when they must."""
        if self.statistic:
            return self.statistic
        own = ",".join(f"{k}={v!r}" for k, v in sorted(vars(self).items()))
        cls = type(self)
        return f"{cls.__module__}:{cls.__qualname__}" + (f"({own})" if own else "")

    @property
    def accumulation_key(self) -> str:
        """The key of the pass's parameters (``params_key``, else the name)."""
        return self.params_key or self.name

    # ------------------------------------------------------------------ parameters
    def default_params(self) -> Any:
        """The parameters :meth:`masks` uses when given None."""
        return self.params_type() if self.params_type is not None else None

    def check_params(self, params: Any) -> Any:
        """``params``, or the defaults for None; ``InputError`` if of the wrong type."""
        if params is None:
            return self.default_params()
        if self.params_type is not None and not isinstance(params, self.params_type):
            raise InputError(f"method {self.name!r} needs {self.params_type.__name__}")
        return params

    def accepts(self, params: Any) -> bool:
        """Whether :func:`~cablesim.perception.pipeline.segment_stream` may be given
        ``params`` (for both the pass and the thresholds)."""
        return self.params_type is None or isinstance(params, self.params_type)

    def params_for_beta(self, beta: float) -> Any:
        """The thresholds tuned for ``beta`` (SPEC sections 7-8); default: the defaults."""
        return self.default_params()

    # ------------------------------------------------------------------ the pass
    def plan(self, stream: Stream, params: Any, delta_g: float) -> list[tuple[int, Any]]:
        """(stream index, job) of every frame the accumulator is fed, in stream order; by
        default the kept frames (:func:`~cablesim.perception.stats.plan_jobs`)."""
        index_of = {id(f): i for i, f in enumerate(stream.frames)}
        return [(index_of[id(j.frame)], j) for j in plan_jobs(stream, delta_g)]

    @abstractmethod
    def accumulator(self, ctx: StreamContext, params: Any) -> Accumulator:
        """A new accumulator for one stream (``params``: the pass's parameters or None)."""

    def store(self, stats: StreamStatistics, result: Any) -> None:
        """Keep the accumulator's result in ``stats`` (default: ``stats.results[key]``)."""
        stats.results[self.key] = result

    def result(self, stats: StreamStatistics) -> Any:
        """What :meth:`store` kept; ``InputError`` if the pass did not compute it."""
        if self.key not in stats.results:
            raise InputError(f"statistics were computed without the {self.name!r} method")
        return stats.results[self.key]

    def n_samples(self, stats: StreamStatistics, plan: Sequence[tuple[int, Any]]) -> dict[int, int]:
        """Frames per action the method used (``StreamStatistics.n_samples``)."""
        return dict(Counter(int(job.action) for _, job in plan))

    # ------------------------------------------------------------------ the thresholds
    @abstractmethod
    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        """One HxW bool mask per action of ``stats`` (before support and colour growth)."""

    def maps(self, stats: StreamStatistics) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
        """(c0, R^2) maps per action for pictures; none by default."""
        return {}, {}

    def support(self, stats: StreamStatistics) -> np.ndarray | None:
        """The target pixels that may vote (None: all)."""
        return stats.support if self.refine_by_default else stats.published_support

    # ------------------------------------------------------------------ tuning
    def grid(self) -> dict[str, np.ndarray]:
        """The thresholds tuning tries (``threshold``, and ``outer_threshold`` if any)."""
        return {self.threshold: np.array([0.5])}

    def action_scores(self, stats: StreamStatistics, outer: float | None) -> list[np.ndarray]:
        """Per action (in ``stats.actions`` order) an HxW score with ``mask = score > t``;
        by default the method's own mask at its default parameters as 0/1."""
        masks = self.masks(stats, self.default_params())
        return [masks[a].astype(np.float64) for a in stats.actions]

    def score(self, stats: StreamStatistics, n: int, outer: float | None = None) -> np.ndarray:
        """HxW float64: the n-th largest action score (n = action threshold of the vote
        merge; 1 = union), -inf where the pixel may not vote."""
        stack = np.stack(self.action_scores(stats, outer))
        score = _nth_largest(stack.astype(np.float64), n)
        support = self.support(stats)
        if support is not None:  # pixels that may not vote never pass a threshold
            score = np.where(support, score, -np.inf)
        return score

    def params_for(self, thresholds: dict[str, float]) -> Any:
        """The method's parameters at tuned ``thresholds`` (default: the defaults)."""
        return self.default_params()


# ---------------------------------------------------------------------- cablesim's methods
_FRACTIONS = np.round(np.arange(0.0, 1.0, 0.02), 4)


def _correlation_pass(params: Any) -> CorrelationParams:
    cparams = params if params is not None else CorrelationParams()
    if isinstance(cparams, AblationParams):
        cparams = CorrelationParams(
            tau_n=cparams.tau_n, depth_mode=cparams.depth_mode, min_samples=cparams.min_samples
        )
    if not isinstance(cparams, CorrelationParams):
        raise InputError(f"correlation needs CorrelationParams, got {type(params).__name__}")
    return cparams


class _Moments(SegmentationMethod):
    """The moments of motion correlation (SPEC section 4), shared with its ablation."""

    statistic = "correlation"
    params_key = "correlation"

    def accepts(self, params: Any) -> bool:
        return isinstance(params, CorrelationParams | AblationParams)

    def accumulator(self, ctx: StreamContext, params: Any) -> Accumulator:
        cparams = _correlation_pass(params)
        return PerActionAccumulator(
            lambda: CorrelationAccumulator(
                ctx.shape, ctx.focal, cparams, ctx.target.depth, ctx.dtype
            ),
            lambda acc, job, phi: acc.update(phi, job.d_g, job.z),
        )

    def store(self, stats: StreamStatistics, result: Any) -> None:
        stats.correlation = result

    def maps(self, stats: StreamStatistics) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
        return (
            {a: r.c0 for a, r in stats.correlation.items()},
            {a: r.r2 for a, r in stats.correlation.items()},
        )


class CorrelationMethod(_Moments):
    """Motion correlation: |c0| > c0_min and R^2 > r2_min (SPEC section 4)."""

    name = "correlation"
    params_type = CorrelationParams
    threshold, outer_threshold = "r2_min", "c0_min"

    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        p = self.check_params(params)
        if not stats.correlation:
            raise InputError("statistics were computed without the correlation method")
        return {a: stats.correlation[a].mask(p.c0_min, p.r2_min) for a in stats.actions}

    def params_for_beta(self, beta: float) -> CorrelationParams:
        r2, c0, _, _ = PUBLISHED_THRESHOLDS[beta]
        return CorrelationParams(c0_min=c0 / 100, r2_min=r2 / 100)

    def grid(self) -> dict[str, np.ndarray]:
        return {"c0_min": _FRACTIONS.copy(), "r2_min": _FRACTIONS.copy()}

    def action_scores(self, stats: StreamStatistics, outer: float | None) -> list[np.ndarray]:
        src = stats.correlation
        return [np.where(np.abs(src[a].c0) > outer, src[a].r2, -np.inf) for a in stats.actions]

    def params_for(self, thresholds: dict[str, float]) -> CorrelationParams:
        return CorrelationParams(c0_min=thresholds["c0_min"], r2_min=thresholds["r2_min"])


class AblationMethod(_Moments):
    """The no-gripper ablation: std(d_phi) > std_min (thesis 6.1.2)."""

    name = "ablation"
    params_type = AblationParams
    threshold = "std_min"

    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        p = self.check_params(params)
        if not stats.correlation:
            raise InputError("statistics were computed without the correlation moments")
        return {a: stats.correlation[a].ablation_mask(p.std_min) for a in stats.actions}

    def grid(self) -> dict[str, np.ndarray]:
        return {"std_min": np.round(np.arange(0.0, 0.02, 0.0005), 6)}

    def action_scores(self, stats: StreamStatistics, outer: float | None) -> list[np.ndarray]:
        return [stats.correlation[a].std_dphi for a in stats.actions]

    def params_for(self, thresholds: dict[str, float]) -> AblationParams:
        return AblationParams(std_min=thresholds["std_min"])


class SegmentationVotes(SegmentationMethod):
    """Motion segmentation: the share of samples moving against the reference (thesis 6.1.1)."""

    name = "segmentation"
    params_type = SegmentationParams
    threshold = "tau_v"

    def accumulator(self, ctx: StreamContext, params: Any) -> Accumulator:
        sparams = params if params is not None else SegmentationParams()
        return PerActionAccumulator(
            lambda: SegmentationAccumulator(ctx.shape, sparams),
            lambda acc, job, phi: acc.update(phi),
        )

    def store(self, stats: StreamStatistics, result: Any) -> None:
        stats.segmentation = result

    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        p = self.check_params(params)
        if not stats.segmentation:
            raise InputError("statistics were computed without the segmentation method")
        return {a: stats.segmentation[a].mask(p.tau_v) for a in stats.actions}

    def params_for_beta(self, beta: float) -> SegmentationParams:
        return SegmentationParams(tau_v=PUBLISHED_THRESHOLDS[beta][2] / 100)

    def grid(self) -> dict[str, np.ndarray]:
        return {"tau_v": _FRACTIONS.copy()}

    def action_scores(self, stats: StreamStatistics, outer: float | None) -> list[np.ndarray]:
        if not stats.segmentation:
            raise InputError("statistics lack the segmentation method")
        return [stats.segmentation[a].fraction for a in stats.actions]

    def params_for(self, thresholds: dict[str, float]) -> SegmentationParams:
        return SegmentationParams(tau_v=thresholds["tau_v"])


# ---------------------------------------------------------------------- the published code's
class _PublishedPass:
    """A :class:`~cablesim.perception.published.PublishedAccumulator` and the metric scale."""

    def __init__(self, acc: PublishedAccumulator, meta: dict[str, Any]) -> None:
        self.acc, self.meta = acc, meta

    def update(self, job: PublishedJob, flow: np.ndarray) -> None:
        self.acc.update(job, flow)

    def result(self) -> tuple[dict[int, Any], dict[int, Any], dict[str, Any]]:
        corr, seg = self.acc.results()
        return corr, seg, self.meta


class _Published(SegmentationMethod):
    """The published code's sampling and statistics (:mod:`cablesim.perception.published`)."""

    params_key = "published"
    params_type = PublishedParams
    refine_by_default = False
    correlation = True  # which half of the published accumulator this method needs

    def plan(self, stream: Stream, params: Any, delta_g: float) -> list[tuple[int, Any]]:
        p = params if params is not None else PublishedParams()
        jobs = plan_published(stream, p.min_gripper_diff)
        if not jobs:
            raise InputError("the stream has no frame with a non-negative action code")
        return [(j.frame_index, j) for j in jobs]

    def accumulator(self, ctx: StreamContext, params: Any) -> Accumulator:
        p = params if params is not None else PublishedParams()
        z, f, mdtype = metric_scale(ctx.stream, p)
        acc = PublishedAccumulator(
            ctx.shape, z / f, p, self.correlation, not self.correlation, mdtype
        )
        return _PublishedPass(acc, describe_published(p, z, f))

    def store(self, stats: StreamStatistics, result: Any) -> None:
        corr, seg, stats.published_meta = result
        if self.correlation:
            stats.published = corr
        else:
            stats.published_segmentation = seg

    def _results(self, stats: StreamStatistics) -> dict[int, Any]:
        return stats.published if self.correlation else stats.published_segmentation

    def n_samples(self, stats: StreamStatistics, plan: Sequence[tuple[int, Any]]) -> dict[int, int]:
        return {a: r.n_samples for a, r in self._results(stats).items()}

    def params_for_beta(self, beta: float) -> PublishedParams:
        return PublishedParams(beta=beta)

    def maps(self, stats: StreamStatistics) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
        if not self.correlation:
            return {}, {}
        f32 = np.float32
        return (
            {a: np.nan_to_num(r.c0).astype(f32) for a, r in stats.published.items()},
            {a: np.nan_to_num(r.r2).astype(f32) for a, r in stats.published.items()},
        )


class PublishedCorrelation(_Published):
    """The published motion correlation: |c0| % >= c0 and R^2 % >= r2 (SPEC section 8)."""

    name = "published"
    statistic = "published"

    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        p = self.check_params(params)
        if not stats.published:
            raise InputError(f"statistics were computed without the {self.name!r} method")
        return {a: r.mask(p.r2, p.c0) for a, r in stats.published.items()}


class PublishedAblation(_Published):
    """The published no-gripper ablation: std(d_phi) x 1e4 > std."""

    name = "published-ablation"
    statistic = "published"

    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        p = self.check_params(params)
        if not stats.published:
            raise InputError(f"statistics were computed without the {self.name!r} method")
        return {a: r.ablation_mask(p.std) for a, r in stats.published.items()}


class PublishedSegmentation(_Published):
    """The published motion segmentation: vote share % > vote."""

    name = "published-segmentation"
    statistic = "published-segmentation"
    correlation = False

    def masks(self, stats: StreamStatistics, params: Any) -> dict[int, np.ndarray]:
        p = self.check_params(params)
        if not stats.published_segmentation:
            raise InputError("statistics were computed without published-segmentation")
        return {a: r.mask(p.vote) for a, r in stats.published_segmentation.items()}


# ---------------------------------------------------------------------- the registry
#: every segmentation method by name: the built-ins, installed packages' entry points of the
#: group ``cablesim.methods``, or ``MODULE:CLASS`` (a :class:`SegmentationMethod` subclass)
SEGMENTATION_METHODS: Registry[SegmentationMethod] = Registry(
    "segmentation method", SegmentationMethod, "cablesim.methods"
)
for _cls in (
    CorrelationMethod,
    SegmentationVotes,
    AblationMethod,
    PublishedCorrelation,
    PublishedSegmentation,
    PublishedAblation,
):
    SEGMENTATION_METHODS.register(_cls.name, _cls, (_cls.__doc__ or "").split("\n")[0])


def make_method(spec: str | SegmentationMethod, **kwargs: Any) -> SegmentationMethod:
    """A method from a spec (a registered name, an entry point's name or ``MODULE:CLASS``,
    optionally with ``,key=value`` constructor parameters); an instance is returned as is."""
    if isinstance(spec, SegmentationMethod):
        return spec
    return SEGMENTATION_METHODS.create(spec, **kwargs)


def check_method(spec: str | SegmentationMethod) -> None:
    """``InputError`` (listing the choices) unless ``spec`` names a method; builds nothing."""
    if not isinstance(spec, SegmentationMethod):
        SEGMENTATION_METHODS.check(spec)


def method_names() -> list[str]:
    """Every registered method's name (built-ins, then installed entry points)."""
    return SEGMENTATION_METHODS.names()


def method_label(spec: str | SegmentationMethod) -> str:
    """The name a method goes by in tables: its spec, or an instance's ``name``."""
    return spec if isinstance(spec, str) else spec.name
