"""Motion correlation (SPEC section 4) and its no-gripper ablation, from running moments.

One :class:`CorrelationAccumulator` per action.  The first ``update`` of an action gives the
reference flow phi_{a,1}; every update adds, at each pixel p where the relative flow
r = phi_k - phi_1 satisfies |r| > tau_n (pixels), one sample to running sums

    n, S_x, S_y, S_xx, S_yy, S_xy, S_g, S_gg, S_xg, S_yg

of s = scale_k * r and of the gripper displacement d_g.  Memory is 10 HxW arrays whatever the
sequence length.  At the end (:meth:`CorrelationAccumulator.result`):

- psi(p) = leading eigenvector of the 2x2 covariance of the used s vectors;
- d_phi = post(p) * s . psi, linear in s, so its moments follow from those of s;
- least squares d_phi = c0 d_g + c1, R^2 = cov(d_phi, d_g)^2 / (var(d_phi) var(d_g));
- std(d_phi) for the ablation.

Depth modes (d_phi = Z/f * r . psi):
- ``"gripper"``: Z = gripper depth of sample k, so ``scale_k = Z_k / f`` and ``post = 1``;
  psi is then the principal direction of the metric relative flow (the same direction as that
  of r when Z is constant over the action, as it nearly is);
- ``"pixel"``: Z = target-frame depth at p (the flow lives in target pixels), ``scale_k = 1``
  and ``post(p) = Z(p)/f``; pixels without valid target depth use the action's mean gripper
  depth.

Pixels with fewer than ``min_samples`` used samples (or no spread in d_g or d_phi) get
c0 = c1 = R^2 = 0.  psi's sign is arbitrary, so c0's sign is too: masks use |c0|.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from cablesim.checks import (
    as_depth,
    as_flow,
    as_real,
    check_params,
    check_positive,
    valid_depth,
)
from cablesim.errors import InputError

DepthMode = Literal["gripper", "pixel"]


@dataclass(frozen=True)
class CorrelationParams:
    """Motion correlation thresholds; defaults from SPEC (beta = 0.4 row)."""

    tau_n: float = 0.67  # px, noise suppression on |r|
    c0_min: float = 0.18  # interactivity threshold on |c0|
    r2_min: float = 0.86  # coefficient of determination threshold
    depth_mode: DepthMode = "gripper"
    min_samples: int = 3  # used samples needed at a pixel for a fit

    def __post_init__(self) -> None:
        check_params(self)
        if self.tau_n < 0:
            raise InputError(f"tau_n must be >= 0, got {self.tau_n}")
        if self.depth_mode not in ("gripper", "pixel"):
            raise InputError(f"depth_mode must be 'gripper' or 'pixel', got {self.depth_mode!r}")
        if self.min_samples < 2:
            raise InputError(f"min_samples must be >= 2, got {self.min_samples}")


@dataclass(frozen=True)
class AblationParams:
    """No-gripper ablation: M = std(d_phi) > std_min (metres)."""

    tau_n: float = 0.67
    std_min: float = 0.004
    depth_mode: DepthMode = "gripper"
    min_samples: int = 3

    def __post_init__(self) -> None:
        check_params(self)
        if self.tau_n < 0:
            raise InputError(f"tau_n must be >= 0, got {self.tau_n}")
        if self.std_min < 0:
            raise InputError(f"std_min must be >= 0, got {self.std_min}")
        if self.depth_mode not in ("gripper", "pixel"):
            raise InputError(f"depth_mode must be 'gripper' or 'pixel', got {self.depth_mode!r}")
        if self.min_samples < 2:
            raise InputError(f"min_samples must be >= 2, got {self.min_samples}")


@dataclass
class CorrelationResult:
    """Per-pixel results of one action (float32 HxW maps; psi is HxWx2)."""

    n: np.ndarray  # used samples
    c0: np.ndarray
    c1: np.ndarray
    r2: np.ndarray
    psi: np.ndarray
    std_dphi: np.ndarray  # metres
    n_samples: int  # samples (frames) seen in the action, reference included

    def mask(self, c0_min: float, r2_min: float) -> np.ndarray:
        return (np.abs(self.c0) > c0_min) & (self.r2 > r2_min)

    def ablation_mask(self, std_min: float) -> np.ndarray:
        return self.std_dphi > std_min


_NAMES = ("n", "sx", "sy", "sxx", "syy", "sxy", "sg", "sgg", "sxg", "syg")


class CorrelationAccumulator:
    """Running moments of one action.  ``update(flow, d_g, z)``; the first call is the reference.

    ``flow`` is phi_{a,k} (HxWx2, target pixels).  ``d_g`` is the gripper displacement along
    the action direction (metres); ``z`` the gripper depth of the sample (metres, used in
    ``"gripper"`` mode).  ``focal`` is f in pixels.  ``target_depth`` is needed in ``"pixel"``
    mode.  ``dtype`` float32 (default, fast) or float64.
    """

    def __init__(
        self,
        shape: tuple[int, int],
        focal: float,
        params: CorrelationParams | None = None,
        target_depth: np.ndarray | None = None,
        dtype: type = np.float32,
    ) -> None:
        self.params = params if params is not None else CorrelationParams()
        try:
            h, w = int(shape[0]), int(shape[1])
        except (TypeError, ValueError, IndexError) as e:
            raise InputError(f"shape must be (height, width), got {shape!r}") from e
        if h <= 0 or w <= 0:
            raise InputError(f"shape must be positive, got {shape}")
        self.shape = (h, w)
        self.focal = check_positive(focal, "focal length")
        if dtype not in (np.float32, np.float64):
            raise InputError(f"dtype must be float32 or float64, got {dtype}")
        self.dtype = np.dtype(dtype)
        if self.params.depth_mode == "pixel":
            if target_depth is None:
                raise InputError("depth_mode 'pixel' needs the target frame's depth")
            target_depth = as_depth(target_depth, self.shape, "target_depth")
        self.target_depth = target_depth
        z = np.zeros(self.shape, self.dtype)
        self._m = {k: z.copy() for k in _NAMES}
        self._ref: tuple[np.ndarray, np.ndarray] | None = None
        self._ref_invalid: np.ndarray | None = None  # pixels without a reference flow
        self._buf = {k: np.empty(self.shape, self.dtype) for k in ("rx", "ry", "fx", "fy", "mag")}
        self.samples = 0
        self._zsum = 0.0

    def update(self, flow: np.ndarray, d_g: float, z: float | None = None) -> None:
        flow = as_flow(flow, self.shape)
        d_g = as_real(d_g, "d_g")
        if z is not None:
            z = as_real(z, "gripper depth z", finite=False)
        if self.params.depth_mode == "gripper":
            if z is None or not np.isfinite(z) or z <= 0:
                raise InputError(f"depth_mode 'gripper' needs a positive gripper depth, got {z!r}")
            scale = float(z) / self.focal
        else:
            scale = 1.0
        if z is not None and np.isfinite(z):
            self._zsum += float(z)
        self.samples += 1
        b = self._buf
        if self.dtype == np.float32:
            cv2.split(flow, [b["fx"], b["fy"]])
        else:
            b["fx"][:] = flow[..., 0]
            b["fy"][:] = flow[..., 1]
        # Non-finite flow (e.g. ``OracleFlow(invalid_value=nan)``) means "no measurement": the
        # pixel gives no sample in this frame, or in any frame if the reference lacks it.
        invalid = None
        if not cv2.checkRange(flow, quiet=True)[0]:
            invalid = ~np.isfinite(flow).all(axis=2)
            b["fx"][invalid] = 0.0
            b["fy"][invalid] = 0.0
        if self._ref is None:
            self._ref = (b["fx"].copy(), b["fy"].copy())
            self._ref_invalid = invalid
            # the reference has r = 0 <= tau_n everywhere: it contributes no sample
            return
        m = self._m
        rx, ry, mag = b["rx"], b["ry"], b["mag"]
        cv2.subtract(b["fx"], self._ref[0], rx)
        cv2.subtract(b["fy"], self._ref[1], ry)
        cv2.magnitude(rx, ry, mag)
        # mag <- 1.0 where |r| > tau_n else 0.0, in place (float 0/1 mask)
        cv2.threshold(mag, self.params.tau_n, 1.0, cv2.THRESH_BINARY, mag)
        for bad in (invalid, self._ref_invalid):
            if bad is not None:
                mag[bad] = 0.0
        if scale != 1.0:
            cv2.multiply(rx, mag, rx, scale)
            cv2.multiply(ry, mag, ry, scale)
        else:
            cv2.multiply(rx, mag, rx)
            cv2.multiply(ry, mag, ry)
        cv2.accumulate(mag, m["n"])
        cv2.scaleAdd(mag, d_g, m["sg"], m["sg"])
        cv2.scaleAdd(mag, d_g * d_g, m["sgg"], m["sgg"])
        cv2.accumulate(rx, m["sx"])
        cv2.accumulate(ry, m["sy"])
        cv2.accumulateSquare(rx, m["sxx"])
        cv2.accumulateSquare(ry, m["syy"])
        cv2.accumulateProduct(rx, ry, m["sxy"])
        cv2.scaleAdd(rx, d_g, m["sxg"], m["sxg"])
        cv2.scaleAdd(ry, d_g, m["syg"], m["syg"])

    @property
    def moments(self) -> dict[str, np.ndarray]:
        """The running sums (views; do not modify)."""
        return self._m

    def result(self) -> CorrelationResult:
        return moments_to_result(self._m, self._post_scale(), self.params.min_samples, self.samples)

    def _post_scale(self) -> np.ndarray | float:
        if self.params.depth_mode == "gripper":
            return 1.0
        zfill = self._zsum / max(self.samples, 1)
        z = np.asarray(self.target_depth, np.float64)
        ok = valid_depth(z)
        if not ok.all():
            if zfill <= 0:
                ok_vals = z[ok]
                zfill = float(np.median(ok_vals)) if ok_vals.size else 1.0
            z = np.where(ok, z, zfill)
        return z / self.focal


def principal_direction(cxx: np.ndarray, cyy: np.ndarray, cxy: np.ndarray) -> np.ndarray:
    """Unit leading eigenvector (HxWx2) of the symmetric 2x2 matrices [[cxx, cxy], [cxy, cyy]]."""
    theta = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    return np.stack([np.cos(theta), np.sin(theta)], -1)


def moments_to_result(
    m: dict[str, np.ndarray],
    post: np.ndarray | float = 1.0,
    min_samples: int = 3,
    n_samples: int = 0,
) -> CorrelationResult:
    """psi, c0, c1, R^2 and std(d_phi) from the running sums (computed in float64)."""
    n = m["n"].astype(np.float64)
    ok = n >= min_samples
    inv = np.where(ok, 1.0 / np.maximum(n, 1.0), 0.0)
    mx, my, mg = m["sx"] * inv, m["sy"] * inv, m["sg"] * inv
    cxx = m["sxx"] * inv - mx * mx
    cyy = m["syy"] * inv - my * my
    cxy = m["sxy"] * inv - mx * my
    vg = np.maximum(m["sgg"] * inv - mg * mg, 0.0)
    cxg = m["sxg"] * inv - mx * mg
    cyg = m["syg"] * inv - my * mg
    psi = principal_direction(cxx, cyy, cxy)
    px, py = psi[..., 0], psi[..., 1]
    post = np.asarray(post, np.float64)
    v_phi = np.maximum(px * px * cxx + 2 * px * py * cxy + py * py * cyy, 0.0) * post * post
    c_pg = (px * cxg + py * cyg) * post
    m_phi = (px * mx + py * my) * post
    # relative tolerances against float32 cancellation
    ok &= vg > 1e-12
    ok &= v_phi > 1e-14
    with np.errstate(divide="ignore", invalid="ignore"):
        c0 = np.where(ok, c_pg / vg, 0.0)
        r2 = np.where(ok, c_pg * c_pg / (v_phi * vg), 0.0)
    r2 = np.clip(r2, 0.0, 1.0)
    c1 = np.where(ok, m_phi - c0 * mg, 0.0)
    std = np.where(n >= max(min_samples, 2), np.sqrt(v_phi), 0.0)
    f32 = np.float32
    return CorrelationResult(
        n=n.astype(f32),
        c0=c0.astype(f32),
        c1=c1.astype(f32),
        r2=r2.astype(f32),
        psi=psi.astype(f32),
        std_dphi=std.astype(f32),
        n_samples=int(n_samples),
    )
