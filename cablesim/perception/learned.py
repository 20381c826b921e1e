"""A learned flow back end: DIS, kept where a small network trained on cablesim's exact flow
sees motion.

The network does not search for correspondences itself.  DIS (OpenCV, CPU) gives a first flow;
the network sees what that flow explains and what it does not:

- the working image: both images resized so that their width is ``work_width`` px (never
  enlarged), DIS ``dis_preset`` from image1 to image2 at that size;
- the network's input (13 channels at the working size): image1 and image2 (RGB), image2
  warped back by the DIS flow (RGB: where the flow is right it reproduces image1), the DIS
  flow divided by ``flow_norm``, and the photometric errors ``mean_c |image1 - warped
  image2|`` and ``mean_c |image1 - image2|`` (what no motion would leave: on a plain board
  DIS reports motion that the warp explains no better than standing still);
- a small U-Net (a stride-2 encoder of ``widths`` channels at 1/2 .. 1/16 of the working
  size, a decoder back to 1/2 with ``decoder`` channels, a head at the working size) returns a
  correction of the flow (times ``flow_norm``; DIS plus it is the network's estimate of the
  normal flow, or of the full flow for a model of ``target="flow"``) and a moving logit per
  pixel;
- the flow returned is :class:`LearnedFlow`'s ``base``: by default DIS medium at the input size
  (``"dis-medium"``), or DIS plus the network's correction (``"network"``), or the
  working-size DIS flow (``"dis"``); where the moving probability is below ``gate`` (``None``:
  nowhere) it is zero, so a still background gives no motion.

Why this design rather than a RAFT- or PWC-like network: it trains on a 2-core CPU in
minutes from a few thousand simulated pairs, where a network that learns correspondences from
scratch does not (``benchmarks.raft_cost``).  The hope was that DIS solves the large
displacements and that what is left to learn is where DIS fails on cables.  Measured since
(``benchmarks.flow_by_motion``): DIS loses most hose motion beyond a few pixels, and the
network's own flow does not recover it; it shrinks DIS's flow where that is mostly wrong
(reporting about a tenth of the true motion on moving pixels), which lowers its error towards
that of no motion at all.  What it does learn is where things move: its moving probability
gating DIS medium scores best on the simulated validation clips, so that is the default
(``docs/perception.md`` has the measurements, on held-out simulated clips and on the real
MovingCables clips, where it does not beat DIS).  A variant that also sees local correlations
of learned features (``arch="corr"``) learned no better in the same steps at 2.5 times the
cost.  ``target`` chooses what the network's flow is trained to be: the normal flow (the
MovingCables evaluation's ground truth, the default) or the full optical flow, whose component
along a plain hose no image shows (the weights shipped until 2026-12-06).

Weights are a ``torch.save`` dict ``{"format": "cablesim-learned-flow", "version": 1,
"config": {...LearnedFlowConfig...}, "state_dict": {...}, "meta": {...}}``, loaded with
``weights_only=True``; a missing, truncated or mismatched file is refused with an
:class:`~cablesim.errors.InputError` naming it.  The default weights ship inside the package
(:data:`DEFAULT_WEIGHTS`, made by ``cablesim train`` from ``configs/learned_flow.json``);
nothing is ever downloaded.  torch is imported on first use (``pip install 'cablesim[torch]'``).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np

from cablesim.config import Config, check_int, check_positive, is_int, is_real
from cablesim.errors import ConfigError, InputError
from cablesim.perception.flow import (
    DIS_PRESETS,
    FlowEstimator,
    _check_pair,
    check_flow,
    make_flow,
)
from cablesim.perception.raft import RaftConfig, build_raft
from cablesim.perception.torchfile import import_torch, load_torch_file

WEIGHTS_FORMAT = "cablesim-learned-flow"
WEIGHTS_VERSION = 1
#: the shipped default model (``cablesim train``'s export of ``configs/learned_flow.json``)
DEFAULT_WEIGHTS = Path(__file__).with_name("weights") / "learned_flow.pt"
#: other shipped models, by the name ``weights=`` takes for them: ``"raft"``, the RAFT design
#: (``configs/learned_flow_raft.json``: finds the motion DIS loses, at about a second a flow)
SHIPPED_WEIGHTS = {"raft": Path(__file__).with_name("weights") / "learned_flow_raft.pt"}
#: input channels: image1 RGB, image2 RGB, image2 warped by DIS RGB, DIS flow (2), the
#: photometric errors of the warped and of the unwarped image2
IN_CHANNELS = 13
#: the network designs (:class:`LearnedFlowConfig`'s ``arch``) and training targets
ARCHS = ("unet", "corr", "raft")
TARGETS = ("normal", "flow")
#: what the moving probability gates by default (:class:`LearnedFlow`'s ``base``)
BASE_DEFAULT = "dis-medium"


def _torch() -> Any:
    return import_torch("the learned flow back end")


@dataclass(frozen=True)
class LearnedFlowConfig(Config):
    """The architecture and the pre-processing of a learned flow model (stored in its
    weights file, so a file always rebuilds the network it was trained as)."""

    SECTION: ClassVar[str] = "model"

    widths: tuple[int, int, int, int] = (16, 32, 48, 64)  # encoder at 1/2, 1/4, 1/8, 1/16
    decoder: tuple[int, int, int] = (48, 32, 16)  # decoder channels at 1/8, 1/4, 1/2
    work_width: int = 276  # images are resized to this width (never enlarged)
    dis_preset: str = "medium"  # DIS at the working size (no texture gate)
    flow_norm: float = 10.0  # flows in and out of the network are in units of this (px)
    # "unet": the U-Net alone; "corr": the U-Net also sees local correlations of image1's
    # and the DIS-warped image2's learned features (at 1/2 and 1/4 of the working size,
    # within ``corr_radius`` cells).  Trained alike for 400 steps, both reached the same
    # validation error (docs/perception.md), "corr" at 2.5 times the inference time
    arch: str = "unet"
    features: tuple[int, int] = (16, 24)  # "corr": feature channels at 1/2 and 1/4
    corr_radius: tuple[int, int] = (4, 3)  # "corr": search radius in cells at 1/2 and 1/4
    # "raft": RAFT-small (cablesim.perception.raft) on image1 and image2, its iterations
    # started from the DIS flow: an all-pairs correlation volume that can find motion DIS
    # lost; feature, hidden and context channels, and the update iterations
    raft_dims: tuple[int, int, int] = (128, 96, 64)
    raft_iters: int = 12
    # what the network's flow is trained to be: "normal" (the normal flow, the MovingCables
    # evaluation's ground truth: what the images show of a hose's motion, its component
    # along the hose being invisible on a plain hose) or "flow" (the full optical flow)
    target: str = "normal"

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """A model written before ``arch`` and ``target`` existed is a U-Net trained on the
        full flow."""
        data.setdefault("arch", "unet")
        data.setdefault("target", "flow")
        return data

    def _validate(self) -> None:
        for name in ("widths", "decoder", "features", "raft_dims"):
            for i, w in enumerate(getattr(self, name)):
                check_int(f"{self.SECTION}.{name}[{i}]", w, 1)
        for i, r in enumerate(self.corr_radius):
            check_int(f"{self.SECTION}.corr_radius[{i}]", r, 1)
            if int(r) > 8:
                raise ConfigError(f"{self.SECTION}.corr_radius[{i}]", f"must be <= 8, got {r}")
        check_int(f"{self.SECTION}.raft_iters", self.raft_iters, 1)
        if int(self.raft_iters) > 32:
            raise ConfigError(f"{self.SECTION}.raft_iters", f"must be <= 32, got {self.raft_iters}")
        if self.arch not in ARCHS:
            raise ConfigError(f"{self.SECTION}.arch", f"must be one of {ARCHS}, got {self.arch!r}")
        if self.target not in TARGETS:
            raise ConfigError(
                f"{self.SECTION}.target", f"must be one of {TARGETS}, got {self.target!r}"
            )
        check_int(f"{self.SECTION}.work_width", self.work_width, 64)
        if self.dis_preset not in ("ultrafast", "fast", "medium"):
            raise ConfigError(
                f"{self.SECTION}.dis_preset",
                f"must be ultrafast, fast or medium, got {self.dis_preset!r}",
            )
        check_positive(f"{self.SECTION}.flow_norm", self.flow_norm)


@lru_cache(maxsize=1)
def _classes() -> dict[str, Any]:
    """Define the torch module on first use (keeps torch out of import time)."""
    torch = _torch()
    nn = torch.nn
    F = torch.nn.functional

    def block(cin: int, cout: int, stride: int = 1) -> Any:
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1), nn.LeakyReLU(0.1, inplace=True))

    class RefineNet(nn.Module):
        """DIS-refining U-Net (module docstring); ``forward(x)`` -> (B, 3, H, W): the flow
        correction (2, in ``flow_norm`` units) and the moving logit.  A design may join
        tensors of its own to the encoder's output at 1/2 and 1/4 (:meth:`joined`; their
        channels from :meth:`_build_joined`), which the next encoder stage and the decoder's
        skips then see."""

        def __init__(self, cfg: LearnedFlowConfig) -> None:
            super().__init__()
            self.cfg = cfg
            w, d = cfg.widths, cfg.decoder
            e = self._build_joined()  # before the U-Net: its modules are drawn first
            ins = (IN_CHANNELS, w[0] + e[0], w[1] + e[1], w[2])
            self.enc = nn.ModuleList(
                [
                    nn.Sequential(block(cin, cout, 2), block(cout, cout))
                    for cin, cout in zip(ins, w, strict=True)
                ]
            )
            self.dec = nn.ModuleList(
                [
                    block(w[3] + w[2], d[0]),
                    block(d[0] + w[1] + e[1], d[1]),
                    block(d[1] + w[0] + e[0], d[2]),
                ]
            )
            self.head = nn.Conv2d(d[2] + IN_CHANNELS, 3, 3, 1, 1)
            nn.init.zeros_(self.head.weight)  # starts as DIS itself, probability 1/2
            nn.init.zeros_(self.head.bias)

        def _build_joined(self) -> tuple[int, int]:
            """Build the modules of what :meth:`joined` returns; its channels at 1/2, 1/4."""
            return 0, 0

        def joined(self, x: Any) -> list[Any]:
            """The tensors joined to the encoder's output at 1/2 and 1/4 (none here)."""
            return []

        def forward(self, x: Any) -> Any:
            extra = self.joined(x)
            skips = []
            y = x
            for i, enc in enumerate(self.enc):
                y = enc(y)
                if i < len(extra):
                    y = torch.cat([y, extra[i]], 1)
                skips.append(y)
            for dec, skip in zip(self.dec, skips[-2::-1], strict=True):
                y = F.interpolate(y, size=skip.shape[-2:], mode="bilinear", align_corners=False)
                y = dec(torch.cat([y, skip], 1))
            y = F.interpolate(y, size=x.shape[-2:], mode="bilinear", align_corners=False)
            return self.head(torch.cat([y, x], 1))

    def correlation(f1: Any, f2: Any, r: int) -> Any:
        """(B, (2r+1)^2, H, W): the channel mean of f1(p) * f2(p + d) for every d in the
        (2r+1)^2 window (zero beyond the border), rows then columns."""
        h, w = f1.shape[-2:]
        p = F.pad(f2, (r, r, r, r))
        return torch.cat(
            [
                (f1 * p[:, :, dy : dy + h, dx : dx + w]).mean(1, keepdim=True)
                for dy in range(2 * r + 1)
                for dx in range(2 * r + 1)
            ],
            1,
        )

    class CorrNet(RefineNet):
        """The U-Net of :class:`RefineNet` with local correlations: a small feature encoder
        (shared) on image1 and on image2 warped by DIS, their correlation at 1/2 and 1/4 of
        the working size joined to the U-Net's skips there.  Where DIS is right the warped
        image matches at zero displacement; where it is off by a few pixels (a thin hose
        whose motion DIS smoothed away) the correlation shows by how much."""

        def _build_joined(self) -> tuple[int, int]:
            fw = self.cfg.features
            self.feat = nn.ModuleList(
                [
                    nn.Sequential(block(3, fw[0], 2), block(fw[0], fw[0])),
                    nn.Sequential(block(fw[0], fw[1], 2), block(fw[1], fw[1])),
                ]
            )
            r0, r1 = self.cfg.corr_radius
            return (2 * r0 + 1) ** 2, (2 * r1 + 1) ** 2

        def joined(self, x: Any) -> list[Any]:
            a, b = x[:, 0:3], x[:, 6:9]  # image1 and image2 warped by DIS
            corrs = []
            for feat, r in zip(self.feat, self.cfg.corr_radius, strict=True):
                a, b = feat(a), feat(b)
                corrs.append(F.leaky_relu(correlation(a, b, int(r)), 0.1))
            return corrs

    class RaftRefine(nn.Module):
        """RAFT-small (:mod:`cablesim.perception.raft`) on image1 and image2, its iterations
        started from the DIS flow of the input (averaged to 1/8), with its last flow layer at
        zero so that it starts as that DIS flow (smoothed); a two-layer head on the input and
        the RAFT flow gives the moving logit.  Same input and output as :class:`RefineNet`:
        the correction of the DIS flow (in ``flow_norm`` units) and the logit."""

        def __init__(self, cfg: LearnedFlowConfig) -> None:
            super().__init__()
            self.cfg = cfg
            f, h, c = (int(v) for v in cfg.raft_dims)
            rc = RaftConfig(feature_dim=f, hidden_dim=h, context_dim=c, iters=cfg.raft_iters)
            self.raft = build_raft(rc)
            last = self.raft.update.flow_head[-1]
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)
            self.prob = nn.Sequential(block(IN_CHANNELS + 2, 16), nn.Conv2d(16, 1, 3, 1, 1))
            nn.init.zeros_(self.prob[-1].weight)  # probability 1/2 at the start, as the U-Net
            nn.init.zeros_(self.prob[-1].bias)

        def forward(self, x: Any, start: Any = None, iters: int | None = None) -> Any:
            """``start`` (B, 2, H, W, px at the working size): a flow to start the
            iterations from instead of the input's DIS flow (a warm start: the flow found
            for the image before in a sequence); ``iters``: update iterations (default:
            the trained ``raft_iters``)."""
            norm = float(self.cfg.flow_norm)
            h, w = x.shape[-2:]
            pad = (0, (-w) % 8, 0, (-h) % 8)
            xp = F.pad(x, pad, mode="replicate")
            a, b = 2.0 * xp[:, 0:3], 2.0 * xp[:, 3:6]  # image - 1/2 -> [-1, 1]
            first = xp[:, 9:11] * norm if start is None else F.pad(start, pad, mode="replicate")
            init = F.avg_pool2d(first, 8) / 8.0
            flow = self.raft(a, b, iters=iters, flow_init=init)[:, :, :h, :w]
            logit = self.prob(torch.cat([x, flow / norm], 1))
            return torch.cat([flow / norm - x[:, 9:11], logit], 1)

    return {"unet": RefineNet, "corr": CorrNet, "raft": RaftRefine, "correlation": correlation}


def build_model(config: LearnedFlowConfig | None = None) -> Any:
    """A randomly initialised network of ``config`` (a ``torch.nn.Module``)."""
    cfg = config or LearnedFlowConfig()
    return _classes()[cfg.arch](cfg)  # arch is checked: one of ARCHS


# ----------------------------------------------------------------------------- inputs
def work_size(width: int, height: int, work_width: int, enlarge: bool = False) -> tuple[int, int]:
    """(w, h) of the working images: ``width`` scaled to ``work_width`` (a narrower image
    enlarged only with ``enlarge``), the aspect kept."""
    if width == work_width or (width < work_width and not enlarge):
        return width, height
    s = work_width / width
    return work_width, max(1, round(height * s))


def warp(image: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """``image`` sampled at ``p + flow(p)`` (bilinear, borders replicated)."""
    h, w = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(
        image,
        gx + flow[..., 0],
        gy + flow[..., 1],
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )


def dis_flow(gray1: np.ndarray, gray2: np.ndarray, preset: str) -> np.ndarray:
    """Ungated DIS flow of ``preset`` between two grey working images."""
    dis = cv2.DISOpticalFlow_create(DIS_PRESETS[preset])
    return np.ascontiguousarray(dis.calc(gray1, gray2, None), np.float32)


def network_input(
    rgb1: np.ndarray, rgb2: np.ndarray, flow: np.ndarray, flow_norm: float
) -> np.ndarray:
    """The 13xHxW float32 input of the network from two working-size RGB images and the DIS
    flow between them (module docstring)."""
    a = rgb1.astype(np.float32) / 255.0
    b = rgb2.astype(np.float32) / 255.0
    w = warp(rgb2, flow).astype(np.float32) / 255.0
    err = np.abs(a - w).mean(axis=2, keepdims=True)
    still = np.abs(a - b).mean(axis=2, keepdims=True)
    x = np.concatenate([a - 0.5, b - 0.5, w - 0.5, flow / np.float32(flow_norm), err, still], 2)
    return np.ascontiguousarray(x.transpose(2, 0, 1), np.float32)


def prepare(
    rgb1: np.ndarray, rgb2: np.ndarray, cfg: LearnedFlowConfig, enlarge: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """(network input, DIS flow at the working size, scale) for two full-size RGB images; the
    same steps at training and at inference time (``enlarge``: images narrower than the
    working width are enlarged to it, bicubic)."""
    h, w = rgb1.shape[:2]
    ww, wh = work_size(w, h, cfg.work_width, enlarge)
    if (ww, wh) != (w, h):
        how = cv2.INTER_AREA if ww < w else cv2.INTER_CUBIC
        rgb1 = cv2.resize(rgb1, (ww, wh), interpolation=how)
        rgb2 = cv2.resize(rgb2, (ww, wh), interpolation=how)
    g1 = cv2.cvtColor(rgb1, cv2.COLOR_RGB2GRAY)
    g2 = cv2.cvtColor(rgb2, cv2.COLOR_RGB2GRAY)
    flow = dis_flow(g1, g2, cfg.dis_preset)
    return network_input(rgb1, rgb2, flow, cfg.flow_norm), flow, ww / w


# ----------------------------------------------------------------------------- weights
def save_weights(
    path: str | Path, model: Any, meta: dict[str, Any] | None = None, half: bool = False
) -> Path:
    """Write ``model``'s weights file (``half``: float16 tensors, half the size)."""
    torch = _torch()
    state = {
        k: (v.detach().cpu().half() if half and v.is_floating_point() else v.detach().cpu())
        for k, v in model.state_dict().items()
    }
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    cfg = model.cfg.to_dict()
    torch.save(
        {
            "format": WEIGHTS_FORMAT,
            "version": WEIGHTS_VERSION,
            "config": cfg,
            "state_dict": state,
            "meta": dict(meta or {}),
        },
        tmp,
    )
    os.replace(tmp, path)
    return path


def weights_path(weights: str | Path | None) -> Path:
    """The file ``weights`` names: the shipped default for None, a shipped model by its name
    (:data:`SHIPPED_WEIGHTS`), else the path itself."""
    if weights is None:
        return DEFAULT_WEIGHTS
    if isinstance(weights, str) and weights in SHIPPED_WEIGHTS:
        return SHIPPED_WEIGHTS[weights]
    return Path(weights)


def read_weights(path: str | Path) -> dict[str, Any]:
    """The checked contents of a weights file; ``InputError`` naming the file otherwise."""
    if path is None or str(path).strip() == "":
        raise InputError("no learned flow weights file given (weights are never downloaded)")
    path = Path(path)
    if not path.is_file():
        hint = (
            " (the package ships it: reinstall cablesim, or make it with `cablesim train`)"
            if path == DEFAULT_WEIGHTS or path in SHIPPED_WEIGHTS.values()
            else " (weights are never downloaded: make them with `cablesim train`)"
        )
        raise InputError(f"learned flow weights not found: {path}{hint}")
    ckpt = load_torch_file(path, "learned flow weights")
    if not isinstance(ckpt, dict) or ckpt.get("format") != WEIGHTS_FORMAT:
        got = ckpt.get("format") if isinstance(ckpt, dict) else type(ckpt).__name__
        raise InputError(f"{path} is not a cablesim learned flow weights file (format {got!r})")
    if ckpt.get("version") != WEIGHTS_VERSION:
        raise InputError(f"{path}: unsupported weights version {ckpt.get('version')!r}")
    if not isinstance(ckpt.get("state_dict"), dict):
        raise InputError(f"{path}: no state_dict")
    try:
        ckpt["config"] = LearnedFlowConfig.from_dict(ckpt.get("config"))
    except (ConfigError, TypeError, AttributeError) as e:
        raise InputError(f"{path}: bad model config: {e}") from e
    return ckpt


def load_model(path: str | Path) -> tuple[Any, dict[str, Any]]:
    """(network in eval mode on the CPU, the file's meta) from a weights file."""
    ckpt = read_weights(path)
    model = build_model(ckpt["config"])
    state = {k: v.float() if v.is_floating_point() else v for k, v in ckpt["state_dict"].items()}
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as e:
        raise InputError(f"{path}: the weights do not match the network of its config: {e}") from e
    return model.eval(), dict(ckpt.get("meta") or {})


# ----------------------------------------------------------------------------- estimator
class LearnedFlow(FlowEstimator):
    """DIS gated (or refined) by a network trained on cablesim's ground truth (module docstring).

    ``weights``: a weights file, or the name of another shipped model
    (:data:`SHIPPED_WEIGHTS`: ``"raft"``) (default: the shipped model, :data:`DEFAULT_WEIGHTS`);
    ``gate``: the moving probability below which the flow is zero (``None``: never zeroed);
    ``threads``: torch's intra-op threads (default: leave torch's setting alone);
    ``work_width``: run at this working width instead of the model's (the network is
    convolutional and trained across scales: a smaller width is the faster variant);
    ``base``: the flow the moving probability gates: ``"network"`` (DIS plus the network's
    correction), ``"dis"`` (the working-size DIS flow the network was given, the network only
    deciding where things move: no extra cost) or any other flow back-end spec, computed at
    the input size (e.g. ``"dis-medium"``);
    ``iters``: the RAFT design's update iterations (default: as trained);
    ``warm``: the RAFT design on a sequence against one reference image (a clip's images to
    its first, a stream's frames to its target): each flow starts from the flow found for the
    image before it against the same reference (the same bytes), not from DIS, so motion
    that grows a little per image is followed beyond what DIS finds.  The flow then depends
    on the images computed before it; a new reference (or :meth:`reset`) starts from DIS;
    ``enlarge``: images narrower than the working width are enlarged to it (bicubic) and the
    flow and probability brought back, so that a hose is as many pixels wide as in training
    (the MovingCables panels are 275 px wide, the RAFT design's working width 640).
    """

    name = "learned"

    def __init__(
        self,
        weights: str | Path | None = None,
        gate: float | None = 0.5,
        threads: int | None = None,
        work_width: int | None = None,
        base: str = BASE_DEFAULT,
        iters: int | None = None,
        warm: bool = False,
        enlarge: bool = False,
    ) -> None:
        if not isinstance(base, str) or not base.strip():
            raise InputError(
                f"learned flow base must be 'network', 'dis' or a flow spec, got {base!r}"
            )
        if base not in ("network", "dis"):
            if base.partition(",")[0] == "learned":
                raise InputError("learned flow base cannot be the learned flow itself")
            check_flow(base)  # an unknown back end is refused here, before any weights load
        if gate is not None and not (is_real(gate) and 0.0 <= float(gate) < 1.0):
            raise InputError(f"learned flow gate must be in [0, 1) or None, got {gate!r}")
        if threads is not None and not (is_int(threads) and int(threads) >= 1):
            raise InputError(f"learned flow threads must be an integer >= 1, got {threads!r}")
        self.weights = weights_path(weights)
        self.gate = None if gate is None else float(gate)
        self.threads = None if threads is None else int(threads)
        self.base = base
        self._base = None if base in ("network", "dis") else make_flow(base)
        if iters is not None and not (is_int(iters) and 1 <= int(iters) <= 32):
            raise InputError(f"learned flow iters must be an integer in [1, 32], got {iters!r}")
        for name, value in (("warm", warm), ("enlarge", enlarge)):
            if not isinstance(value, bool):
                raise InputError(f"learned flow {name} must be true or false, got {value!r}")
        self.model, self.meta = load_model(self.weights)
        self.cfg: LearnedFlowConfig = self.model.cfg
        if (iters is not None or warm) and self.cfg.arch != "raft":
            raise InputError(
                f"learned flow iters and warm need a model of arch 'raft'; {self.weights} "
                f"holds arch {self.cfg.arch!r}"
            )
        self.iters = None if iters is None else int(iters)
        self.warm = warm
        self.enlarge = enlarge
        self._last: tuple[bytes, tuple[int, ...], np.ndarray] | None = None
        if work_width is not None:
            try:
                self.cfg = self.cfg.replace(work_width=work_width)
            except ConfigError as e:
                raise InputError(f"learned flow work_width: {e}") from e

    def predict(self, image1: np.ndarray, image2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(flow HxWx2 float32 before the gate, moving probability HxW float32) in image1's
        pixels at the input size."""
        torch = _torch()
        _check_pair(image1, image2)
        rgb1, rgb2 = (_rgb(image1), _rgb(image2))
        h, w = rgb1.shape[:2]
        x, dis, scale = prepare(rgb1, rgb2, self.cfg, self.enlarge)
        old = torch.get_num_threads()
        if self.threads is not None:
            torch.set_num_threads(self.threads)
        start, key = None, b""
        if self.warm:  # the reference image by its bytes
            key = hashlib.blake2b(np.ascontiguousarray(image2).data, digest_size=16).digest()
            if self._last is not None and self._last[:2] == (key, x.shape):
                start = torch.from_numpy(self._last[2])[None]
        try:
            with torch.inference_mode():
                if self.cfg.arch == "raft":
                    out = self.model(torch.from_numpy(x)[None], start, self.iters)[0].numpy()
                else:
                    out = self.model(torch.from_numpy(x)[None])[0].numpy()
        finally:
            if self.threads is not None:
                torch.set_num_threads(old)
        if self.warm:  # the network's flow at the working size, before any gate
            own = (x[9:11] + out[:2]) * np.float32(self.cfg.flow_norm)
            self._last = (key, x.shape, np.ascontiguousarray(own, np.float32))
        prob = 0.5 + 0.5 * np.tanh(0.5 * out[2])  # the logistic function, without overflow
        if self._base is not None:
            flow = self._base.compute(image1, image2)
        elif self.base == "dis":
            flow = dis
        else:
            flow = dis + out[:2].transpose(1, 2, 0) * np.float32(self.cfg.flow_norm)
        if scale != 1.0:
            if self._base is None:
                flow = cv2.resize(flow, (w, h), interpolation=cv2.INTER_LINEAR) / np.float32(scale)
            prob = cv2.resize(prob, (w, h), interpolation=cv2.INTER_LINEAR)
        return np.ascontiguousarray(flow, np.float32), np.ascontiguousarray(prob, np.float32)

    def reset(self) -> None:
        """Forget the sequence (``warm``): the next flow starts from DIS."""
        self._last = None

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        flow, prob = self.predict(image1, image2)
        if self.gate is not None:
            flow[prob < self.gate] = 0.0
        return flow

    def describe(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "weights": str(self.weights),
            "gate": self.gate,
            "base": self.base,
            "iters": self.iters,
            "warm": self.warm,
            "enlarge": self.enlarge,
            "config": self.cfg.to_dict(),
            "trained": {k: self.meta[k] for k in ("commit", "run", "steps") if k in self.meta},
        }


def _rgb(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return np.ascontiguousarray(np.repeat(img[..., None], 3, axis=2))
    return np.ascontiguousarray(img[..., :3])
