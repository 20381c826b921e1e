"""Optical-flow back ends behind one interface (SPEC section 4).

Convention (OpenCV's): ``estimator.compute(image1, image2)`` returns an HxWx2 float32 flow in
the pixels of ``image1`` such that ``image1(p) ~ image2(p + flow(p))``; channel 0 is the x
(column) component, channel 1 the y (row) component.

Perception needs, for every kept frame I_{a,k}, the flow *to the target frame expressed in
target-frame pixels*: phi with ``I_{a,k}(p + phi(p)) = I_target(p)``.  In OpenCV's convention that
is ``compute(target.rgb, frame.rgb)`` -- the **target is the first image**.  ``frame_flow(frame,
target)`` does exactly that, and is what the pipeline calls.

Back ends: :class:`OracleFlow` (simulator ground truth, evaluation/upper bound),
:class:`DISFlow` (CPU default, with a low-texture gate), :class:`FarnebackFlow`, and
``cablesim.perception.raft.RaftFlow`` (torch, user-supplied checkpoint).  They register
themselves in :data:`FLOW_BACKENDS` by name; :func:`make_flow` builds one from a spec, which may
also name an installed package's entry point (group ``cablesim.flows``) or ``MODULE:CLASS``.
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cablesim.checks import as_flow, as_image, as_mask, check_params
from cablesim.errors import InputError
from cablesim.frames import Frame
from cablesim.perception.registry import Registry

DIS_PRESETS = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
    "fine": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,  # with the overrides of DIS_FINE
}
#: ``fine``: OpenCV's medium preset with 8 px patches every 4 px at half resolution (medium's
#: are 12 px every 8 px): patches of 16 full-resolution pixels instead of 24, so a 6-7 px
#: hose drags its motion less far onto the board beside it (``benchmarks/experiments/
#: realistic_flow/``).  Since issue 21 the variational refinement runs 1 iteration per level
#: (the preset's 5): 12 ms instead of 18 per 640x480 pair on one core, with the default
#: perception's validation F_0.4 0.853 against 0.855 (``results/realistic_flow_dis_speed.md``).
DIS_FINE = {
    "finest_scale": 1,
    "patch_size": 8,
    "patch_stride": 4,
    "variational_refinement_iters": 1,
}


def to_gray(img: np.ndarray, name: str = "image") -> np.ndarray:
    """RGB (HxWx3 uint8) or gray (HxW uint8) -> gray uint8."""
    img = as_image(img, name)
    if img.ndim == 3:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.shape[2] == 3 else img[..., 0]
    return img


def _check_pair(image1: np.ndarray, image2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    g1, g2 = to_gray(image1, "image1"), to_gray(image2, "image2")
    if g1.shape != g2.shape:
        raise InputError(f"image sizes differ: {g1.shape} vs {g2.shape}")
    return np.ascontiguousarray(g1), np.ascontiguousarray(g2)


def texture_mask(gray: np.ndarray, window: int = 7, threshold: float = 6.0) -> np.ndarray:
    """Pixels with enough local image gradient for flow to be trusted.

    The Sobel gradient energy ``gx^2 + gy^2`` (3x3 Sobel, scaled by 1/8 so a unit-per-pixel
    ramp of grey levels gives 1) is averaged over a ``window`` x ``window`` box; a pixel is
    textured where the root of that mean (grey levels per pixel, 0..255 image) is at least
    ``threshold``.  This is the trace of the structure tensor.
    """
    gray = to_gray(gray, "gray")
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
        raise InputError(f"texture window must be an integer >= 1, got {window!r}")
    g = gray.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    energy = cv2.boxFilter(gx * gx + gy * gy, -1, (window, window))
    return energy >= threshold * threshold


class FlowEstimator(ABC):
    """One optical-flow back end.  Subclasses implement :meth:`compute`."""

    name: str = "flow"
    #: whether the flow is estimated from the images (and so sees only the motion normal to
    #: an edge, the aperture problem); ground truth is not
    image_based: bool = True

    @abstractmethod
    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        """HxWx2 float32 flow in image1's pixels with image1(p) ~ image2(p + flow(p))."""

    def frame_flow(self, frame: Frame, target: Frame) -> np.ndarray:
        """Flow phi of ``frame`` to ``target`` in target pixels: frame(p + phi) = target(p).

        Equals ``compute(target.rgb, frame.rgb)`` (the target is OpenCV's first image).
        """
        if frame.shape != target.shape:
            raise InputError(f"frame size {frame.shape} differs from target size {target.shape}")
        return self.compute(target.rgb, frame.rgb)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name}


class OracleFlow(FlowEstimator):
    """Ground-truth flow from a simulated stream (``frame.truth.flow_to_target``).

    The simulator stores, per frame k, ``flow_to_target`` HxWx2 in **target-frame pixels** such
    that target pixel p shows the surface point that was at ``p + flow`` in frame k (the SPEC's
    phi) and ``flow_valid`` HxW bool.  Invalid pixels (occluded, unknown) are returned as zero
    flow (``invalid_value=0.0``, the default, so they never vote) or NaN if requested.  The
    target frame itself has zero flow.  Only evaluation may use this back end.
    """

    name = "oracle"
    image_based = False

    def __init__(self, invalid_value: float = 0.0) -> None:
        self.invalid_value = float(invalid_value)

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        raise InputError("the oracle flow needs frames with ground truth; call frame_flow()")

    def frame_flow(self, frame: Frame, target: Frame) -> np.ndarray:
        h, w = target.shape
        if frame is target:
            return np.zeros((h, w, 2), np.float32)
        if frame.truth is None or frame.truth.flow_to_target is None:
            raise InputError(
                f"frame (action {frame.action}, sample {frame.sample}) has no ground-truth flow; "
                "the oracle back end needs a simulated stream with every frame labelled "
                "(interaction.capture.truth_every 1; the default labels every 8th)"
            )
        flow = np.asarray(frame.truth.flow_to_target)
        if flow.shape != (h, w, 2):
            raise InputError(f"truth.flow_to_target has shape {flow.shape}, expected {(h, w, 2)}")
        flow = np.array(flow, dtype=np.float32, copy=True)
        valid = frame.truth.flow_valid
        if valid is not None:
            valid = np.asarray(valid, bool)
            if valid.shape != (h, w):
                raise InputError(f"truth.flow_valid has shape {valid.shape}, expected {(h, w)}")
            flow[~valid] = self.invalid_value
        bad = ~np.isfinite(flow)
        if self.invalid_value == 0.0 and bad.any():
            flow[bad] = 0.0
        return flow


@dataclass
class GateParams:
    """Zero flow where the first image (the target) lacks texture (see :func:`texture_mask`)."""

    enabled: bool = True
    window: int = 7
    threshold: float = 6.0

    def __post_init__(self) -> None:
        check_params(self, "gate.")
        if self.window < 1:
            raise InputError(f"gate.window must be >= 1, got {self.window}")
        if self.threshold < 0:
            raise InputError(f"gate.threshold must be >= 0, got {self.threshold}")


class DISFlow(FlowEstimator):
    """OpenCV DIS optical flow (CPU default) with a low-texture gate.

    The default preset is ``fine`` (before issue 10 it was ``medium``): on the realistic-flow
    validation scenes it bleeds less onto the board beside a hose at about the same cost.

    ``preset`` is one of ``ultrafast``, ``fast``, ``medium``, ``fine`` (:data:`DIS_FINE`);
    ``finest_scale``, ``patch_size``, ``patch_stride``, ``gradient_descent_iters`` and
    ``variational_refinement_iters`` override the preset's.  Without the gate DIS reports
    motion on most of a plain background (SPEC section 9: ~70%; with it ~3%); the gate zeroes
    the flow wherever the *first* image (the target frame, whose pixels the flow is in) has
    too little local gradient.
    """

    name = "dis"

    def __init__(
        self,
        preset: str = "fine",
        gate: GateParams | None = None,
        variational_refinement_iters: int | None = None,
        finest_scale: int | None = None,
        patch_size: int | None = None,
        patch_stride: int | None = None,
        gradient_descent_iters: int | None = None,
    ) -> None:
        if preset not in DIS_PRESETS:
            raise InputError(f"unknown DIS preset {preset!r}; choose one of {sorted(DIS_PRESETS)}")
        self.preset = preset
        self.gate = gate if gate is not None else GateParams()
        self._dis = cv2.DISOpticalFlow_create(DIS_PRESETS[preset])
        # optional overrides of the preset (None keeps the preset's value)
        self.overrides: dict[str, int] = {}
        if preset == "fine":
            finest_scale = DIS_FINE["finest_scale"] if finest_scale is None else finest_scale
            patch_size = DIS_FINE["patch_size"] if patch_size is None else patch_size
            patch_stride = DIS_FINE["patch_stride"] if patch_stride is None else patch_stride
            if variational_refinement_iters is None:
                variational_refinement_iters = DIS_FINE["variational_refinement_iters"]
        for name, value, setter, lo in (
            (
                "variational_refinement_iters",
                variational_refinement_iters,
                "VariationalRefinementIterations",
                0,
            ),
            ("finest_scale", finest_scale, "FinestScale", 0),
            ("patch_size", patch_size, "PatchSize", 2),
            ("patch_stride", patch_stride, "PatchStride", 1),
            ("gradient_descent_iters", gradient_descent_iters, "GradientDescentIterations", 1),
        ):
            if value is None:
                continue
            if isinstance(value, bool) or int(value) != value or value < lo:
                raise InputError(f"DIS {name} must be an integer >= {lo}, got {value!r}")
            getattr(self._dis, "set" + setter)(int(value))
            self.overrides[name] = int(value)
        if patch_stride is not None and patch_stride > self._dis.getPatchSize():
            raise InputError(
                f"DIS patch_stride {patch_stride} exceeds the patch size {self._dis.getPatchSize()}"
            )
        self._gate_cache: tuple[int, np.ndarray] | None = None  # (hash of shape and pixels, gate)
        # (gate, ~gate as uint8, a zero flow): the masked copy's operands, kept per target
        self._holes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def check_size(self, width: int, height: int) -> None:
        """``InputError`` unless DIS can work on a ``width`` x ``height`` image.

        DIS picks its coarsest pyramid level from the image size (the rule of OpenCV's
        ``DISOpticalFlowImpl::calc``); below the preset's finest level OpenCV raises or, for
        some sizes, crashes the process, so such sizes are refused here.
        """
        patch, finest = self._dis.getPatchSize(), self._dis.getFinestScale()
        lo, hi = min(width, height), max(width, height)
        ok = (
            lo > 0
            and min(
                math.trunc(math.log2(hi / (4.0 * patch)) + 0.5), math.trunc(math.log2(lo / patch))
            )
            >= finest
        )
        if not ok:
            need_lo = patch * 2**finest
            need_hi = math.ceil(4 * patch * 2 ** (finest - 0.5))
            raise InputError(
                f"the image ({width}x{height} px) is too small for DIS preset {self.preset!r}: "
                f"it needs at least {need_lo} px on the short side and {need_hi} px on the long"
            )

    def _gate(self, gray1: np.ndarray) -> np.ndarray:
        # the target image is the first image of every call: cache its gate
        key = hash((gray1.shape, gray1.tobytes()))
        if self._gate_cache is not None and self._gate_cache[0] == key:
            return self._gate_cache[1]
        m = texture_mask(gray1, self.gate.window, self.gate.threshold)
        self._gate_cache = (key, m)
        return m

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        g1, g2 = _check_pair(image1, image2)
        self.check_size(g1.shape[1], g1.shape[0])
        flow = self._dis.calc(g1, g2, None)
        flow = np.ascontiguousarray(flow, np.float32)
        if self.gate.enabled:
            gate = self._gate(g1)
            if self._holes is None or self._holes[0] is not gate:
                self._holes = (gate, (~gate).view(np.uint8), np.zeros_like(flow))
            # zero where the target has too little texture: the values of a boolean-mask
            # assignment, by OpenCV's masked copy with the inverted mask kept per target (a
            # fifth of the time of NumPy's broadcast copy)
            holes, zeros = self._holes[1], self._holes[2]
            cv2.copyTo(zeros, holes, flow)
        return flow

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "preset": self.preset, **self.overrides, "gate": vars(self.gate)}


class FarnebackFlow(FlowEstimator):
    """OpenCV Farneback dense flow (optionally with the same texture gate, off by default)."""

    name = "farneback"

    def __init__(
        self,
        pyr_scale: float = 0.5,
        levels: int = 4,
        winsize: int = 15,
        iterations: int = 3,
        poly_n: int = 5,
        poly_sigma: float = 1.1,
        gate: GateParams | None = None,
    ) -> None:
        self.params = dict(
            pyr_scale=pyr_scale,
            levels=levels,
            winsize=winsize,
            iterations=iterations,
            poly_n=poly_n,
            poly_sigma=poly_sigma,
        )
        self.gate = gate if gate is not None else GateParams(enabled=False)

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        g1, g2 = _check_pair(image1, image2)
        p = self.params
        flow = cv2.calcOpticalFlowFarneback(
            g1,
            g2,
            None,
            p["pyr_scale"],
            p["levels"],
            p["winsize"],
            p["iterations"],
            p["poly_n"],
            p["poly_sigma"],
            0,
        )
        flow = np.ascontiguousarray(flow, np.float32)
        if self.gate.enabled:
            flow[~texture_mask(g1, self.gate.window, self.gate.threshold)] = 0.0
        return flow

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, **self.params, "gate": vars(self.gate)}


#: every flow back end by name: the built-ins below, installed packages' entry points of the
#: group ``cablesim.flows``, or ``MODULE:CLASS`` (a :class:`FlowEstimator` subclass) in a spec
#: (:mod:`cablesim.perception.registry`: ``"dis,preset=fast"``, ``"my_flow:MyFlow,scale=2"``)
FLOW_BACKENDS: Registry[FlowEstimator] = Registry("flow back end", FlowEstimator, "cablesim.flows")
FLOW_BACKENDS.register("dis", DISFlow, "OpenCV DIS with the low-texture gate (the CPU default)")
for _preset in DIS_PRESETS:
    FLOW_BACKENDS.register(f"dis-{_preset}", DISFlow, f"DIS, preset {_preset}", preset=_preset)
FLOW_BACKENDS.register("farneback", FarnebackFlow, "OpenCV Farneback dense flow")
FLOW_BACKENDS.register(
    "raft",
    "cablesim.perception.raft:RaftFlow",
    "RAFT-style network from a checkpoint (torch; raft,checkpoint=FILE)",
)
FLOW_BACKENDS.register(
    "learned",
    "cablesim.perception.learned:LearnedFlow",
    "DIS medium gated by a network trained on cablesim's exact flow (torch; weights=FILE|raft, "
    "gate=P, base=network|dis|SPEC, work_width=W, enlarge=true; the RAFT design: iters=N, "
    "warm=true)",
)
FLOW_BACKENDS.register(
    "oracle", OracleFlow, "the simulator's ground-truth flow (simulated streams only)"
)


def make_flow(name: str | FlowEstimator = "dis", **kwargs: Any) -> FlowEstimator:
    """A flow back end from a spec (:data:`FLOW_BACKENDS`): ``oracle``, ``dis`` (or
    ``dis-<preset>``), ``farneback``, ``raft`` (needs ``checkpoint=``), an installed entry
    point's name or ``MODULE:CLASS``, each optionally with ``,key=value`` parameters;
    ``kwargs`` add to them.  An estimator instance is returned unchanged."""
    if isinstance(name, FlowEstimator):
        return name
    return FLOW_BACKENDS.create(name, **kwargs)


def check_flow(spec: str | FlowEstimator) -> None:
    """``InputError`` (listing the choices) unless ``spec`` names a flow back end; imports a
    ``MODULE:CLASS`` target's module but builds nothing."""
    if not isinstance(spec, FlowEstimator):
        FLOW_BACKENDS.check(spec)


def reads_ground_truth(spec: str | FlowEstimator) -> bool:
    """Whether the flow back end ``spec`` reads the frames' ground-truth flow rather than
    their images (``image_based`` False: the oracle), so every frame must carry it.  Builds
    nothing; an unknown spec is an ``InputError`` as in :func:`check_flow`."""
    if isinstance(spec, FlowEstimator):
        return not spec.image_based
    factory = FLOW_BACKENDS.resolve(spec).factory
    return inspect.isclass(factory) and not getattr(factory, "image_based", True)


def flow_names() -> list[str]:
    """Every registered flow back end's name (built-ins, then installed entry points)."""
    return FLOW_BACKENDS.names()


def endpoint_error(flow: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean endpoint error |flow - truth| over ``mask`` (all pixels if None); NaN if empty."""

    flow = as_flow(flow, name="flow")
    truth = as_flow(truth, flow.shape[:2], name="truth")
    e = np.linalg.norm(flow - truth, axis=-1)
    if mask is not None:
        mask = as_mask(mask, flow.shape[:2])
        e = e[mask]
    e = e[np.isfinite(e)]
    return float(e.mean()) if e.size else float("nan")
