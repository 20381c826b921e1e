"""Stopping the bleed of estimated motion across hose boundaries, on a CPU (issue 10).

Block-based flow (DIS) matches patches wider than a 6-7 px hose, so a moving hose drags its
motion onto the still board beside it and onto hoses it crosses; the dragged motion follows
the gripper and passes motion correlation (SPEC section 9).  This module holds the remedies,
each optional and measured on its own (``benchmarks/experiments/realistic_flow/``):

Per sample (a kept frame k; its flow phi to the target in target pixels p) -- a rejected pixel
gets no sample in that frame (its flow becomes NaN, which the accumulators skip):

- **arm masks** (``arm_masks``): ``Frame.arm_mask`` (the arm model rendered at the frame's
  joint state) marks where frame k shows the arm; target pixels that see the arm in frame k
  (at p or at p + phi) have no measurement there.  Where no frame carries a mask nothing
  changes.  The target frame's own mask (normally empty: the arm has left) never votes.
- **normal flow** (``normal_flow``): a hose has one colour along its length, so an image-based
  flow sees only the motion across it (the aperture problem); the motion along it is
  unconstrained and DIS fills it with whatever its patches drift to, large on a plain board,
  which breaks the follow test of a hose that moves with the gripper.  Every flow vector is
  replaced by its component along the target's local edge normal: the dominant eigenvector of
  the colour structure tensor smoothed over ``normal_flow`` px.  Correlation needs one
  component per pixel anyway (it projects the motion on its principal direction), and this
  one is observed (the "normal flow" of the aperture problem; not the MovingCables layout's
  ``normal_flow`` files).  Ground-truth flow (``FlowEstimator.image_based`` False) is left
  whole.
- **photometric check** (``photometric``): the claimed motion must explain the image:
  ``max_c |target_c(p) - frame_c(p + phi)| <= photometric`` grey levels after a Gaussian blur
  of ``photometric_blur`` px (sensor noise).
- **forward-backward consistency** (``forward_backward``): the flow from frame k back to the
  target must return: ``|phi(p) + psi(p + phi(p))| <= forward_backward`` px (a second flow per
  frame).

Per pixel of the target frame, once per interaction (``support``: pixels allowed to vote):

- **foreground** (``foreground``, :class:`ForegroundParams`): the hose stands in front of the
  board.  Median-filtered target depth; a RANSAC fit of the board plane (``1/z`` is linear in
  the pixel coordinates for a plane); height above the plane, clipped to +-``max_height``; a
  pixel is foreground where its height exceeds the local background -- the grey opening of
  the height over a window of ``window_m``, which follows planes and slopes but not what is
  narrower than the window -- by ``min_height`` (and stays below ``max_height``); its edges
  can then be moved to the image's colour edges (``colour_px``: stereo depth fattens or
  erodes a thin object by a few pixels, the image does not).
- **contrast** (``contrast``, :class:`ContrastParams`): a hose pixel differs in colour from
  the board around it: max-channel distance to the median colour of a window several hose
  widths wide.

Per mask, after thresholding (``grow``, :class:`GrowParams`; off by default):

- **colour growth**: a hose has one colour along its length, and the flow misses much of it
  (recall, not precision, is what the CPU flow loses: textureless hose on a textureless board).
  Each action's mask grows, pixel by pixel up to ``max_px`` steps, into the support pixels
  whose CIELAB colour lies within ``colour`` of the mask's median colour.  This uses a cue the
  motion does not give: it helps where the hoses differ in colour (cablesim's default palette)
  and leaks along every hose of the same colour that touches the grasped one (measured on the
  validation scenes with the colour test switched off: precision 0.85 -> 0.30), so it is an
  option, not a default.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import cv2
import numpy as np

from cablesim.checks import as_flow
from cablesim.errors import InputError
from cablesim.frames import Frame, Intrinsics


@dataclass(frozen=True)
class ForegroundParams:
    """Depth cue on the target frame (module docstring)."""

    min_height: float = 0.005  # m above the local background (a hose is 15 mm thick)
    window_m: float = 0.036  # m, side of the local-background window (15 px at 640x480, 1 m)
    median_px: int = 5  # median filter of the depth (3 or 5)
    dilate_px: int = 0  # grow the foreground by this many pixels
    max_height: float = 0.3  # m: farther in front of the board is not a hose on it
    min_valid: float = 0.2  # fraction of pixels with depth below which the cue abstains
    # fraction of the valid pixels that must stand out for the cue to speak: a depth image in
    # which nothing stands in front of the board (a flat or synthetic scene, hoses the depth
    # cannot resolve) says nothing about the hoses, so the cue abstains there
    min_foreground: float = 0.002
    # the window must span this many pixels: in a coarser image (a 15 mm hose narrower than
    # about 3 px) the cue cannot separate a hose from its background, and abstains
    min_window_px: int = 7
    plane_stride: int = 4  # fit the plane on every n-th pixel
    plane_iterations: int = 5
    # image-guided edges: within this many pixels of the depth foreground's boundary a pixel
    # is foreground when its colour is closer to the nearby foreground core than to the nearby
    # background (stereo depth fattens or erodes thin objects by a few pixels; the image does
    # not); 0 = off
    colour_px: int = 0

    def __post_init__(self) -> None:
        if self.median_px not in (0, 1, 3, 5):
            raise InputError(f"foreground.median_px must be 0, 1, 3 or 5, got {self.median_px}")
        if self.min_height <= 0 or self.window_m <= 0:
            raise InputError("foreground.min_height and window_m must be positive")
        if self.dilate_px < 0 or self.plane_stride < 1 or self.plane_iterations < 1:
            raise InputError("foreground.dilate_px >= 0, plane_stride >= 1, iterations >= 1")
        if self.colour_px < 0:
            raise InputError(f"foreground.colour_px must be >= 0, got {self.colour_px}")


@dataclass(frozen=True)
class ContrastParams:
    """Colour cue on the target frame (module docstring)."""

    threshold: float = 30.0  # grey levels (max over channels)
    window_m: float = 0.05  # m, median window (21 px at 640x480, 1 m)
    dilate_px: int = 0

    def __post_init__(self) -> None:
        if self.threshold < 0 or self.window_m <= 0 or self.dilate_px < 0:
            raise InputError("contrast: threshold >= 0, window_m > 0, dilate_px >= 0")


@dataclass(frozen=True)
class GrowParams:
    """Colour growth of the masks (module docstring)."""

    colour: float = 15.0  # CIELAB distance (OpenCV's 8-bit Lab) to the mask's median colour
    max_px: int = 256  # growth steps (8-connected pixels) from the mask

    def __post_init__(self) -> None:
        if not (np.isfinite(self.colour) and self.colour > 0) or self.max_px < 1:
            raise InputError(
                f"grow: colour > 0 and max_px >= 1, got colour {self.colour}, max_px {self.max_px}"
            )


@dataclass(frozen=True)
class RefineParams:
    """Which bleed remedies run (module docstring); ``None`` switches one off."""

    arm_masks: bool = True
    normal_flow: float | None = None  # px, structure-tensor smoothing; None keeps the full flow
    photometric: float | None = None  # grey levels
    photometric_blur: float = 1.0  # px
    forward_backward: float | None = None  # px
    foreground: ForegroundParams | None = None
    contrast: ContrastParams | None = None
    grow: GrowParams | None = None

    def __post_init__(self) -> None:
        if self.normal_flow is not None and not (
            np.isfinite(self.normal_flow) and self.normal_flow > 0
        ):
            raise InputError(f"normal_flow must be > 0 (px) or None, got {self.normal_flow}")
        if self.photometric is not None and self.photometric < 0:
            raise InputError(f"photometric must be >= 0 or None, got {self.photometric}")
        if self.forward_backward is not None and self.forward_backward <= 0:
            raise InputError(f"forward_backward must be > 0 or None, got {self.forward_backward}")
        if self.photometric_blur < 0:
            raise InputError(f"photometric_blur must be >= 0, got {self.photometric_blur}")

    @property
    def per_sample(self) -> bool:
        return (
            self.arm_masks
            or self.normal_flow is not None
            or self.photometric is not None
            or self.forward_backward is not None
        )

    def describe(self) -> dict:

        return asdict(self)


#: no remedy at all (the flow as the back end gives it)
RAW = RefineParams(arm_masks=False)
#: what perception uses unless told otherwise (chosen on the validation scenes of
#: ``benchmarks/experiments/realistic_flow/``): the normal flow (structure tensor over 1.5 px), arm masks
#: where the frames have them, and the depth foreground with its edges moved to the image's
#: colour edges within 3 px; it abstains where the target has no usable depth
DEFAULT_REFINE = RefineParams(normal_flow=1.5, foreground=ForegroundParams(colour_px=3))


# ------------------------------------------------------------------------------ per sample
def _grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return xs, ys


def edge_normals(rgb: np.ndarray, sigma: float) -> np.ndarray:
    """HxWx2 float32 unit vectors (x, y): the dominant eigenvector of the structure tensor of
    ``rgb`` (3x3 Sobel gradients summed over the channels, each product smoothed by a Gaussian
    of ``sigma`` px), i.e. the direction across the local edge.  Zero where the image has no
    gradient at all (there no direction is observed)."""
    f = np.asarray(rgb, np.float32)
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)
    if f.ndim == 3:
        a, b, c = (gx * gx).sum(2), (gx * gy).sum(2), (gy * gy).sum(2)
    else:
        a, b, c = gx * gx, gx * gy, gy * gy
    a, b, c = (cv2.GaussianBlur(x, (0, 0), sigma) for x in (a, b, c))
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    n = np.dstack([np.cos(theta), np.sin(theta)]).astype(np.float32)
    n[(a + c) <= 0] = 0.0
    return n


def normal_flow(phi: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """``phi`` replaced by its component along ``normals`` (HxWx2 unit vectors or zero)."""
    dot = phi[..., 0] * normals[..., 0] + phi[..., 1] * normals[..., 1]
    return normals * dot[..., None]


@dataclass
class SampleFilter:
    """Per-sample validity of one stream's flows (module docstring); ``apply`` returns the
    flow with NaN where the sample is rejected.  Caches what depends on the target only."""

    params: RefineParams
    target: Frame
    flow: object = None  # the FlowEstimator (forward-backward needs it)
    _cache: dict = field(default_factory=dict)

    def _grid(self) -> np.ndarray:
        """HxWx2 float32 pixel coordinates (x, y) of the target."""
        if "grid" not in self._cache:
            xs, ys = _grid(*self.target.shape)
            self._cache["grid"] = np.dstack([xs, ys])
        return self._cache["grid"]

    def _blurred(self, rgb: np.ndarray) -> np.ndarray:
        s = self.params.photometric_blur
        return cv2.GaussianBlur(rgb, (0, 0), s) if s > 0 else rgb

    def _normals(self) -> np.ndarray | None:
        """The target's edge normals, or None where the normal flow is off (or the flow is
        ground truth, which has no aperture problem)."""
        p = self.params
        if p.normal_flow is None or not getattr(self.flow, "image_based", True):
            return None
        if "normals" not in self._cache:
            self._cache["normals"] = edge_normals(self.target.rgb, p.normal_flow)
        return self._cache["normals"]

    def apply(self, phi: np.ndarray, frame: Frame) -> np.ndarray:
        p = self.params
        arm = p.arm_masks and frame.arm_mask is not None
        normals = self._normals()
        checks = arm or p.photometric is not None or p.forward_backward is not None
        if frame is self.target or not (checks or normals is not None):
            return phi
        phi = as_flow(phi, self.target.shape, "flow")
        if normals is not None:
            phi = normal_flow(phi, normals)  # the checks below see the normal flow
        if not checks:
            return phi
        bad = np.zeros(phi.shape[:2], bool)
        finite = phi if np.isfinite(phi.sum()) else np.nan_to_num(phi)
        mxy = cv2.add(self._grid(), finite)  # where each target pixel lands in frame k
        if arm:
            a8 = frame.arm_mask.view(np.uint8)
            at_q = cv2.remap(a8, mxy, None, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
            bad |= frame.arm_mask
            bad |= at_q.view(bool)
        if p.photometric is not None:
            if "target_blur" not in self._cache:
                self._cache["target_blur"] = self._blurred(self.target.rgb)
            tb = self._cache["target_blur"]
            warped = cv2.remap(
                self._blurred(frame.rgb),
                mxy,
                None,
                cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )
            diff = cv2.absdiff(warped, tb)
            if diff.ndim == 3:
                diff = cv2.max(cv2.max(diff[..., 0], diff[..., 1]), diff[..., 2])
            bad |= diff > p.photometric
        if p.forward_backward is not None:
            if self.flow is None:
                raise InputError("forward_backward needs the flow estimator")
            psi = self.flow.compute(frame.rgb, self.target.rgb)  # frame(q) ~ target(q + psi)
            back = cv2.remap(psi, mxy, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            err = np.linalg.norm(finite + back, axis=2)
            bad |= err > p.forward_backward
        if not bad.any():
            return phi
        out = np.array(phi, np.float32, copy=True)
        out[bad] = np.nan
        return out


# ------------------------------------------------------------------------------ per pixel
def _fill_holes(z: np.ndarray) -> np.ndarray:
    """Pixels without depth take the farthest valid neighbour (up to 8 px away): conservative
    for the foreground cue (a hole never becomes foreground by itself)."""
    z = np.where(np.isfinite(z) & (z > 0), z, 0).astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    for _ in range(8):
        hole = z <= 0
        if not hole.any():
            break
        z = np.where(hole, cv2.dilate(z, k), z)
    return z


def fit_plane_inverse_depth(
    z: np.ndarray,
    stride: int = 4,
    iterations: int = 5,
    inlier: float = 0.004,
    trials: int = 64,
    seed: int = 0,
) -> np.ndarray | None:
    """Robust fit of the dominant plane (the board): ``1/z = a u + b v + c`` (a plane's inverse
    depth is linear in the pixel coordinates).  RANSAC over ``trials`` triples of every
    ``stride``-th valid pixel keeps the plane with the most points within ``inlier`` metres;
    it is refined by least squares on its inliers ``iterations`` times.  Returns the plane's
    depth at every pixel (NaN where it lies behind the camera), or None when there is too
    little depth.  Deterministic (``seed``)."""
    h, w = z.shape
    zs = z[::stride, ::stride]
    vs, us = np.mgrid[0:h:stride, 0:w:stride]
    ok = zs > 0
    if ok.sum() < 30:
        return None
    A = np.stack([us[ok], vs[ok], np.ones(int(ok.sum()))], 1).astype(np.float64)
    zz = zs[ok].astype(np.float64)
    y = 1.0 / zz
    tol = inlier / (zz * zz)  # an inverse-depth tolerance per point (d(1/z) = dz / z^2)
    rng = np.random.default_rng(seed)
    best, best_n = None, -1
    for _ in range(trials):
        idx = rng.choice(len(y), 3, replace=False)
        try:
            coef = np.linalg.solve(A[idx], y[idx])
        except np.linalg.LinAlgError:
            continue
        n = int((np.abs(A @ coef - y) < tol).sum())
        if n > best_n:
            best, best_n = coef, n
    if best is None:
        return None
    coef = best
    for _ in range(iterations):
        inl = np.abs(A @ coef - y) < tol
        if inl.sum() < 3:
            break
        coef, *_ = np.linalg.lstsq(A[inl], y[inl], rcond=None)
    V, U = np.mgrid[0:h, 0:w]
    inv = coef[0] * U + coef[1] * V + coef[2]
    return np.where(inv > 1e-6, 1.0 / np.maximum(inv, 1e-6), np.nan).astype(np.float32)


def _disk(r: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def colour_snap(fg: np.ndarray, rgb: np.ndarray, radius: int) -> np.ndarray:
    """Move the boundary of ``fg`` to the image's colour edges: pixels within ``radius`` of the
    boundary join the side (the foreground core ``radius`` px inside, the background outside)
    whose mean colour nearby is closer to their own; where one side has no pixel nearby the
    mask is kept."""
    if radius <= 0 or not fg.any():
        return fg
    f8 = fg.astype(np.uint8)
    core = cv2.erode(f8, _disk(radius)) > 0
    grown = cv2.dilate(f8, _disk(radius)) > 0
    outer = ~(cv2.dilate(f8, _disk(1)) > 0)
    band = grown & ~core
    if not band.any():
        return fg
    img = rgb.astype(np.float32)
    win = (4 * radius + 3, 4 * radius + 3)

    def mean_of(sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = cv2.boxFilter(sel.astype(np.float32), -1, win, normalize=False)
        acc = cv2.boxFilter(img * sel[..., None], -1, win, normalize=False)
        return acc / np.maximum(w, 1.0)[..., None], w > 0

    m_core, has_core = mean_of(core)
    m_out, has_out = mean_of(outer)
    d_core = np.abs(img - m_core).sum(axis=2)
    d_out = np.abs(img - m_out).sum(axis=2)
    decide = band & has_core & has_out
    out = fg.copy()
    out[decide] = d_core[decide] < d_out[decide]
    return out


def foreground_mask(
    depth: np.ndarray,
    intrinsics: Intrinsics,
    params: ForegroundParams,
    rgb: np.ndarray | None = None,
) -> np.ndarray | None:
    """HxW bool: pixels standing at least ``min_height`` in front of the local background;
    None when the depth cannot tell (no depth, less than ``min_valid`` of it valid, an image
    too coarse for the window, no plane, less than ``min_foreground`` of it standing out):
    the cue then abstains rather than silencing every pixel."""
    if depth is None:
        return None
    raw_valid = np.isfinite(depth) & (depth > 0)
    if raw_valid.mean() < params.min_valid:
        return None
    z = _fill_holes(depth)
    if params.median_px > 1:
        z = cv2.medianBlur(z, params.median_px)
    valid = z > 0
    zmed = float(np.median(z[valid]))
    win = int(round(params.window_m * intrinsics.f / zmed)) | 1
    if win < params.min_window_px:
        return None
    plane = fit_plane_inverse_depth(z, params.plane_stride, params.plane_iterations, 0.004)
    if plane is None:
        return None
    base = plane
    height = np.where(valid & np.isfinite(base), base - z, 0.0).astype(np.float32)
    # the board and what hangs on it: not what lies far behind or far in front of the plane
    height = np.clip(height, -params.max_height, params.max_height)
    # the local background: a grey opening (erosion then dilation) follows planes and slopes
    # (the table seen at a grazing angle) but not what is narrower than the window (a hose)
    ground = cv2.morphologyEx(
        height, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_RECT, (win, win))
    )
    fg = ((height - ground) > params.min_height) & (height < params.max_height) & valid
    if fg.sum() < params.min_foreground * max(int(raw_valid.sum()), 1):
        return None
    if params.colour_px > 0:
        if rgb is None:
            raise InputError("foreground.colour_px needs the target's colour image")
        fg = colour_snap(fg, rgb, params.colour_px)
    if params.dilate_px > 0:
        k = cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (2 * params.dilate_px + 1, 2 * params.dilate_px + 1)
        )
        fg = cv2.dilate(fg.astype(np.uint8), k) > 0
    return fg


def contrast_mask(
    rgb: np.ndarray, intrinsics: Intrinsics, depth: np.ndarray | None, params: ContrastParams
) -> np.ndarray:
    """HxW bool: pixels whose colour differs from the median colour around them."""
    ok = None if depth is None else np.isfinite(depth) & (depth > 0)
    zmed = float(np.median(depth[ok])) if ok is not None and ok.any() else 1.0
    k = max(3, int(round(params.window_m * intrinsics.f / zmed)) | 1)
    bg = cv2.medianBlur(np.ascontiguousarray(rgb), min(k, 255))
    diff = cv2.absdiff(rgb, bg).max(axis=2)
    m = diff > params.threshold
    if params.dilate_px > 0:
        kk = cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (2 * params.dilate_px + 1, 2 * params.dilate_px + 1)
        )
        m = cv2.dilate(m.astype(np.uint8), kk) > 0
    return m


def support_mask(target: Frame, params: RefineParams) -> np.ndarray | None:
    """Pixels of the target frame allowed to vote (None: all)."""
    out = None
    if params.arm_masks and target.arm_mask is not None:
        out = ~target.arm_mask
    if params.foreground is not None:
        fg = foreground_mask(target.depth, target.intrinsics, params.foreground, target.rgb)
        if fg is not None:
            out = fg if out is None else out & fg
    if params.contrast is not None:
        c = contrast_mask(target.rgb, target.intrinsics, target.depth, params.contrast)
        out = c if out is None else out & c
    return out


# ------------------------------------------------------------------------------ per mask
def colour_guide(rgb: np.ndarray) -> np.ndarray:
    """The target frame in OpenCV's 8-bit CIELAB (what :func:`grow_by_colour` compares)."""
    return cv2.cvtColor(np.ascontiguousarray(rgb, dtype=np.uint8), cv2.COLOR_RGB2LAB)


_K8 = np.ones((3, 3), np.uint8)


def grow_by_colour(
    mask: np.ndarray, guide: np.ndarray, params: GrowParams, support: np.ndarray | None = None
) -> np.ndarray:
    """``mask`` grown, one 8-connected pixel ring per step for up to ``params.max_px`` steps,
    into the ``support`` pixels whose colour in ``guide`` (:func:`colour_guide`) lies within
    ``params.colour`` of the median colour of ``mask``.  An empty mask stays empty."""
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return mask.copy()
    lab = guide.astype(np.float32)
    ref = np.median(lab[mask], axis=0)
    allowed = np.linalg.norm(lab - ref, axis=2) < params.colour
    if support is not None:
        allowed &= support
    allowed_u8 = allowed.astype(np.uint8)
    m = mask.astype(np.uint8)
    for _ in range(params.max_px):
        grown = (cv2.dilate(m, _K8) & allowed_u8) | m
        if np.array_equal(grown, m):
            break
        m = grown
    return m.astype(bool)
