"""A compact RAFT-style optical-flow network in torch, loaded from a user checkpoint.

torch is imported lazily (``pip install cablesim[torch]``); nothing is ever downloaded.  The
architecture follows RAFT-small (Teed & Deng, 2020): residual feature and context encoders
at 1/8 resolution, an all-pairs correlation volume with a 4-level pyramid looked up within a
radius around the current estimate, a convolutional GRU update operator and convex
upsampling to full resolution.

Checkpoint format (``torch.save`` of a dict, loaded with ``weights_only=True``)::

    {"format": "cablesim-raft", "version": 1, "config": {...RaftConfig fields...},
     "state_dict": {...}}

:func:`save_raft_checkpoint` writes one (randomly initialised unless a model is given);
:class:`RaftFlow` is the :class:`~cablesim.perception.flow.FlowEstimator`.  No pretrained
weights for this architecture are installable offline: train or convert your own.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, fields
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from cablesim.errors import InputError
from cablesim.perception.flow import FlowEstimator, _check_pair
from cablesim.perception.torchfile import import_torch, load_torch_file

CHECKPOINT_FORMAT = "cablesim-raft"
CHECKPOINT_VERSION = 1


def _torch() -> Any:
    return import_torch("the RAFT back end")


@dataclass(frozen=True)
class RaftConfig:
    feature_dim: int = 128
    hidden_dim: int = 96
    context_dim: int = 64
    corr_levels: int = 4
    corr_radius: int = 3
    iters: int = 12


@lru_cache(maxsize=1)
def _classes() -> dict[str, type]:
    """Define the torch modules on first use (keeps torch out of import time)."""
    torch = _torch()
    nn = torch.nn
    F = torch.nn.functional

    class ResidualBlock(nn.Module):
        def __init__(self, cin: int, cout: int, stride: int, norm: bool) -> None:
            super().__init__()
            self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1)
            self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1)
            mk = (lambda c: nn.InstanceNorm2d(c)) if norm else (lambda c: nn.Identity())
            self.n1, self.n2 = mk(cout), mk(cout)
            self.down = None
            if stride != 1 or cin != cout:
                self.down = nn.Sequential(nn.Conv2d(cin, cout, 1, stride), mk(cout))

        def forward(self, x):
            y = F.relu(self.n1(self.conv1(x)))
            y = F.relu(self.n2(self.conv2(y)))
            return F.relu((x if self.down is None else self.down(x)) + y)

    class Encoder(nn.Module):
        """Stride-8 residual encoder."""

        def __init__(self, out_dim: int, norm: bool) -> None:
            super().__init__()
            self.conv1 = nn.Conv2d(3, 32, 7, 2, 3)
            self.layers = nn.Sequential(
                ResidualBlock(32, 32, 1, norm),
                ResidualBlock(32, 64, 2, norm),
                ResidualBlock(64, 96, 2, norm),
            )
            self.out = nn.Conv2d(96, out_dim, 1)

        def forward(self, x):
            return self.out(self.layers(F.relu(self.conv1(x))))

    class ConvGRU(nn.Module):
        def __init__(self, hidden: int, inp: int) -> None:
            super().__init__()
            self.convz = nn.Conv2d(hidden + inp, hidden, 3, padding=1)
            self.convr = nn.Conv2d(hidden + inp, hidden, 3, padding=1)
            self.convq = nn.Conv2d(hidden + inp, hidden, 3, padding=1)

        def forward(self, h, x):
            hx = torch.cat([h, x], 1)
            z = torch.sigmoid(self.convz(hx))
            r = torch.sigmoid(self.convr(hx))
            q = torch.tanh(self.convq(torch.cat([r * h, x], 1)))
            return (1 - z) * h + z * q

    class UpdateBlock(nn.Module):
        def __init__(self, cfg: RaftConfig) -> None:
            super().__init__()
            cor_planes = cfg.corr_levels * (2 * cfg.corr_radius + 1) ** 2
            self.convc = nn.Conv2d(cor_planes, 96, 1)
            self.convf1 = nn.Conv2d(2, 64, 7, padding=3)
            self.convf2 = nn.Conv2d(64, 32, 3, padding=1)
            self.conv = nn.Conv2d(96 + 32, 80, 3, padding=1)
            self.gru = ConvGRU(cfg.hidden_dim, 80 + 2 + cfg.context_dim)
            self.flow_head = nn.Sequential(
                nn.Conv2d(cfg.hidden_dim, 128, 3, padding=1),
                nn.ReLU(),
                nn.Conv2d(128, 2, 3, padding=1),
            )
            self.mask_head = nn.Sequential(
                nn.Conv2d(cfg.hidden_dim, 128, 3, padding=1), nn.ReLU(), nn.Conv2d(128, 64 * 9, 1)
            )

        def forward(self, h, ctx, corr, flow):
            c = F.relu(self.convc(corr))
            f = F.relu(self.convf2(F.relu(self.convf1(flow))))
            motion = torch.cat([F.relu(self.conv(torch.cat([c, f], 1))), flow], 1)
            h = self.gru(h, torch.cat([ctx, motion], 1))
            return h, self.flow_head(h), 0.25 * self.mask_head(h)

    class RAFT(nn.Module):
        def __init__(self, cfg: RaftConfig) -> None:
            super().__init__()
            self.cfg = cfg
            self.fnet = Encoder(cfg.feature_dim, norm=True)
            self.cnet = Encoder(cfg.hidden_dim + cfg.context_dim, norm=False)
            self.update = UpdateBlock(cfg)

        def _pyramid(self, f1, f2):
            b, d, h, w = f1.shape
            corr = torch.einsum("bdn,bdm->bnm", f1.flatten(2), f2.flatten(2)) / d**0.5
            corr = corr.reshape(b * h * w, 1, h, w)
            pyr = [corr]
            for _ in range(self.cfg.corr_levels - 1):
                corr = F.avg_pool2d(corr, 2, stride=2, ceil_mode=True)
                pyr.append(corr)
            return pyr

        def _lookup(self, pyr, coords):
            b, _, h, w = coords.shape
            r = self.cfg.corr_radius
            d = torch.linspace(-r, r, 2 * r + 1, device=coords.device)
            delta = torch.stack(torch.meshgrid(d, d, indexing="ij"), -1).flip(-1)  # (dx, dy)
            centre = coords.permute(0, 2, 3, 1).reshape(b * h * w, 1, 1, 2)
            out = []
            for lvl, corr in enumerate(pyr):
                pts = centre / 2**lvl + delta.view(1, 2 * r + 1, 2 * r + 1, 2)
                hh, ww = corr.shape[-2:]
                gx = 2 * pts[..., 0] / max(ww - 1, 1) - 1
                gy = 2 * pts[..., 1] / max(hh - 1, 1) - 1
                s = F.grid_sample(corr, torch.stack([gx, gy], -1), align_corners=True)
                out.append(s.view(b, h, w, -1))
            return torch.cat(out, -1).permute(0, 3, 1, 2).contiguous()

        @staticmethod
        def _upsample(flow, mask):
            b, _, h, w = flow.shape
            mask = torch.softmax(mask.view(b, 1, 9, 8, 8, h, w), dim=2)
            up = F.unfold(8 * flow, [3, 3], padding=1).view(b, 2, 9, 1, 1, h, w)
            up = torch.sum(mask * up, dim=2).permute(0, 1, 4, 2, 5, 3)
            return up.reshape(b, 2, 8 * h, 8 * w)

        def forward(self, im1, im2, iters: int | None = None, flow_init=None):
            """The flow from ``im1`` to ``im2`` (B, 2, H, W; images in [-1, 1], H and W
            multiples of 8); ``flow_init`` (B, 2, H/8, W/8, in 1/8-resolution pixels) starts
            the iterations from a flow instead of zero."""
            iters = self.cfg.iters if iters is None else iters
            f1, f2 = self.fnet(im1), self.fnet(im2)
            pyr = self._pyramid(f1, f2)
            c = self.cnet(im1)
            h, ctx = torch.split(c, [self.cfg.hidden_dim, self.cfg.context_dim], 1)
            h, ctx = torch.tanh(h), F.relu(ctx)
            b, _, hh, ww = f1.shape
            ys, xs = torch.meshgrid(
                torch.arange(hh, device=im1.device),
                torch.arange(ww, device=im1.device),
                indexing="ij",
            )
            coords0 = torch.stack([xs, ys], 0).float()[None].repeat(b, 1, 1, 1)
            coords1 = coords0.clone() if flow_init is None else coords0 + flow_init
            up = None
            for _ in range(iters):
                corr = self._lookup(pyr, coords1)
                h, delta, mask = self.update(h, ctx, corr, coords1 - coords0)
                coords1 = coords1 + delta
                up = self._upsample(coords1 - coords0, mask)
            return up

    return {"RAFT": RAFT}


def build_raft(config: RaftConfig | None = None) -> Any:
    """A RAFT-style ``torch.nn.Module`` (randomly initialised)."""
    return _classes()["RAFT"](config or RaftConfig())


def save_raft_checkpoint(
    path: str | Path, model: Any = None, config: RaftConfig | None = None, seed: int = 0
) -> Path:
    """Write a checkpoint of ``model`` (a fresh randomly initialised one if None)."""
    torch = _torch()
    if model is None:
        torch.manual_seed(seed)
        model = build_raft(config)
    cfg = model.cfg
    path = Path(path)
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "version": CHECKPOINT_VERSION,
            "config": asdict(cfg),
            "state_dict": model.state_dict(),
        },
        path,
    )
    return path


def check_checkpoint_file(path: str | Path) -> Path:
    """``InputError`` unless ``path`` is a readable file (checked before torch is needed)."""
    if path is None or str(path).strip() == "":
        raise InputError("no RAFT checkpoint given (weights are never downloaded)")
    path = Path(path)
    if not path.is_file():
        raise InputError(
            f"RAFT checkpoint not found: {path} (weights are never downloaded; "
            "supply a checkpoint file)"
        )
    if not os.access(path, os.R_OK):
        raise InputError(f"RAFT checkpoint {path} is not readable")
    return path


def load_raft(path: str | Path, device: str = "cpu") -> Any:
    """Load a checkpoint written by :func:`save_raft_checkpoint`; clear errors otherwise."""
    path = check_checkpoint_file(path)
    ckpt = load_torch_file(path, "RAFT checkpoint")
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise InputError(
            f"{path} is not a cablesim RAFT checkpoint (format "
            f"{ckpt.get('format') if isinstance(ckpt, dict) else type(ckpt)!r})"
        )
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise InputError(f"{path}: unsupported checkpoint version {ckpt.get('version')!r}")
    known = {f.name for f in fields(RaftConfig)}
    cfg_d = ckpt.get("config", {})
    if not isinstance(cfg_d, dict) or set(cfg_d) - known:
        raise InputError(f"{path}: bad config {cfg_d!r}")
    model = build_raft(RaftConfig(**cfg_d))
    try:
        model.load_state_dict(ckpt["state_dict"], strict=True)
    except (KeyError, RuntimeError) as e:
        raise InputError(f"{path}: weights do not match the architecture: {e}") from e
    return model.to(device).eval()


def _device(device: str) -> str:
    torch = _torch()
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise InputError("device 'cuda' requested but CUDA is not available to torch")
    return device


class RaftFlow(FlowEstimator):
    """RAFT-style network flow (OpenCV convention), CPU or GPU, from a checkpoint file."""

    name = "raft"

    def __init__(
        self, checkpoint: str | Path, device: str = "auto", iters: int | None = None
    ) -> None:
        self.checkpoint = check_checkpoint_file(checkpoint)
        self.device = _device(device)
        self.model = load_raft(self.checkpoint, self.device)
        self.iters = iters

    def _tensor(self, img: np.ndarray) -> Any:
        torch = _torch()
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, 2)
        t = torch.from_numpy(np.ascontiguousarray(img)).to(self.device)
        return (t.permute(2, 0, 1)[None].float() / 127.5) - 1.0

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        torch = _torch()
        _check_pair(image1, image2)
        h, w = image1.shape[:2]
        ph, pw = (-h) % 8, (-w) % 8
        pad = (0, pw, 0, ph)
        F = torch.nn.functional
        a = F.pad(self._tensor(image1), pad, mode="replicate")
        b = F.pad(self._tensor(image2), pad, mode="replicate")
        with torch.inference_mode():
            flow = self.model(a, b, self.iters)
        out = flow[0, :, :h, :w].permute(1, 2, 0).float().cpu().numpy()
        return np.ascontiguousarray(out, np.float32)

    def describe(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "checkpoint": str(self.checkpoint),
            "device": self.device,
            "iters": self.iters,
        }
