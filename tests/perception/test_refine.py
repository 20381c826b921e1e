"""Bleed remedies (cablesim.perception.refine), the flow region (RegionFlow) and arm masks."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception import (
    DISFlow,
    FlowEstimator,
    Frame,
    FrameTruth,
    Intrinsics,
    OracleFlow,
    Stream,
    compute_statistics,
    segment_stream,
)
from cablesim.perception.flow_region import FlowRegion, RegionFlow
from cablesim.perception.refine import (
    RAW,
    ForegroundParams,
    GrowParams,
    RefineParams,
    SampleFilter,
    colour_guide,
    edge_normals,
    fit_plane_inverse_depth,
    foreground_mask,
    grow_by_colour,
    normal_flow,
    support_mask,
)

from .helpers import shifted, texture

H, W = 120, 160
F = 433.0  # px: a 15 mm hose at 1 m is 6-7 px wide, as with the default camera
K = Intrinsics(F, F, (W - 1) / 2, (H - 1) / 2, W, H)


# ------------------------------------------------------------------------------ RegionFlow
class _Constant(FlowEstimator):
    """Returns the same flow everywhere and remembers the size it was given."""

    name = "constant"

    def __init__(self, v: tuple[float, float]) -> None:
        self.v = v
        self.seen: tuple[int, ...] | None = None

    def compute(self, image1, image2):
        self.seen = image1.shape
        out = np.empty((*image1.shape[:2], 2), np.float32)
        out[...] = self.v
        return out


def test_region_flow_crops_scales_and_pastes():
    img = np.zeros((H, W, 3), np.uint8)
    base = _Constant((3.0, -1.5))
    rf = RegionFlow(base, FlowRegion.from_crop((20, 10, 80, 60), 1.5))
    flow = rf.compute(img, img)
    assert base.seen[:2] == (90, 120)  # the crop scaled up 1.5x
    inside = flow[10:70, 20:100]
    assert np.allclose(inside, [2.0, -1.0], atol=1e-5)  # divided by the scale
    outside = np.ones((H, W), bool)
    outside[10:70, 20:100] = False
    assert np.all(flow[outside] == 0)
    region = rf.describe()["region"]
    assert region["crop_origin"] == [20, 10] and region["crop_size"] == [80, 60]
    assert region["scale_factor"] == 1.5
    with pytest.raises(InputError, match="exceeds"):
        RegionFlow(base, FlowRegion.from_crop((100, 10, 80, 60))).compute(img, img)
    with pytest.raises(InputError, match="scale"):
        FlowRegion.from_crop(None, 0.0)
    with pytest.raises(InputError, match="crop"):
        FlowRegion.from_crop((0, 0, 2.5, 2))


def test_region_flow_recovers_an_analytic_translation():
    t = texture(H, W, seed=3)
    dx, dy = 1.4, -0.8
    a = np.repeat(np.clip(t, 0, 255).astype(np.uint8)[..., None], 3, 2)
    b = np.repeat(np.clip(shifted(t, dx, dy), 0, 255).astype(np.uint8)[..., None], 3, 2)
    crop = (30, 20, 100, 80)
    flow = RegionFlow(DISFlow("medium"), FlowRegion.from_crop(crop, 1.5)).compute(a, b)
    x0, y0, w, h = crop
    inner = flow[y0 + 8 : y0 + h - 8, x0 + 8 : x0 + w - 8]
    err = np.linalg.norm(inner - np.float32([dx, dy]), axis=-1)
    assert np.median(err) < 0.1  # in full-image pixels: the scale was divided out
    assert np.all(flow[:y0] == 0) and np.all(flow[:, x0 + w :] == 0)


# ------------------------------------------------------------------------------ a thin bar
BAR_X, BAR_W = 78, 6  # target position and width (px) of a hose-like bar
ARM = (slice(40, 80), slice(100, 140))  # where the arm covers the plane in action frames
Z_PLANE, Z_BAR = 1.0, 0.92  # m: the bar hangs 8 cm in front of the plane


def _bar_scene(offset: float, plane: np.ndarray) -> np.ndarray:
    """RGB of the textured plane with the bar moved right by ``offset`` px."""
    img = np.stack([plane * 0.9, plane * 0.8, plane * 0.6], -1)
    x = np.arange(W)[None, :]
    cover = np.clip(
        np.minimum(x + 0.5 - (BAR_X + offset), BAR_X + offset + BAR_W - (x - 0.5)), 0, 1
    )
    cover = np.repeat(cover, H, 0)[..., None]
    bar = np.float32([40, 90, 210])  # a blue hose
    out = img * (1 - cover) + bar * cover
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _bar_depth(fatten: int = 0) -> np.ndarray:
    """Target depth: the plane, tilted, with the bar in front (``fatten`` px wider each side,
    as block-matching stereo measures a thin near object)."""
    v = np.arange(H, dtype=np.float64)[:, None]
    z = np.repeat(1.0 / (1.0 / Z_PLANE + 0.0008 * (v - H / 2)), W, 1).astype(np.float32)
    z[:, BAR_X - fatten : BAR_X + BAR_W + fatten] = Z_BAR
    return z


@pytest.fixture(scope="module")
def bar_stream() -> Stream:
    plane = texture(H, W, seed=7, sigma=1.5) * 0.6 + 60
    frames = []
    n = 16
    for k in range(n + 1):
        d = 3.0 * np.sin(2 * np.pi * k / n)  # px, follows the gripper
        g = np.array([d * Z_BAR / F, 0.0, Z_BAR])
        frames.append(Frame(_bar_scene(d, plane), _bar_depth(), K, g, action=0, sample=k))
    target = Frame(_bar_scene(0.0, plane), _bar_depth(fatten=2), K, np.array([0.3, 0.3, 0.5]))
    truth = np.zeros((H, W), np.int16) - 1
    truth[:, BAR_X : BAR_X + BAR_W] = 0
    target.truth = FrameTruth(labels=truth, grasped_hose=0)
    return Stream([*frames, target])


def _beside(mask: np.ndarray) -> int:
    """Voted plane pixels within 1..5 px of the bar."""
    cols = np.r_[BAR_X - 5 : BAR_X, BAR_X + BAR_W : BAR_X + BAR_W + 5]
    return int(mask[10:-10, cols].sum())


def test_foreground_cue_removes_the_bleed_beside_a_thin_bar(bar_stream: Stream):
    truth = bar_stream.target.truth.labels == 0
    raw = segment_stream(bar_stream, flow=DISFlow("medium"), refine=RAW).mask("union")
    assert _beside(raw) > 100  # DIS drags the bar's motion onto the still plane beside it
    fg = RefineParams(foreground=ForegroundParams(colour_px=3))
    ref = segment_stream(bar_stream, flow=DISFlow("medium"), refine=fg).mask("union")
    assert _beside(ref) < 0.1 * _beside(raw)
    # the bar itself keeps its votes
    assert (ref & truth).sum() >= 0.85 * (raw & truth).sum() > 0.5 * truth[10:-10].sum()
    # without the image the fattened depth lets the bleed next to the bar through
    depth_only = RefineParams(foreground=ForegroundParams())
    mid = segment_stream(bar_stream, flow=DISFlow("medium"), refine=depth_only).mask("union")
    assert _beside(ref) < _beside(mid) < _beside(raw)


def test_foreground_mask_on_a_tilted_plane():
    z = _bar_depth()
    fg = foreground_mask(z, K, ForegroundParams())
    bar = np.zeros((H, W), bool)
    bar[:, BAR_X : BAR_X + BAR_W] = True
    assert fg[bar].mean() > 0.95 and fg[~bar].mean() < 0.01
    plane = fit_plane_inverse_depth(z)
    assert np.nanmax(np.abs(plane - _bar_depth(fatten=-BAR_W))[:, :60]) < 1e-4
    # the cue abstains when the depth cannot tell: nothing stands out, or no depth at all
    assert foreground_mask(_bar_depth(fatten=-BAR_W), K, ForegroundParams()) is None
    assert foreground_mask(np.zeros((H, W), np.float32), K, ForegroundParams()) is None
    assert foreground_mask(None, K, ForegroundParams()) is None
    coarse = Intrinsics(100.0, 100.0, (W - 1) / 2, (H - 1) / 2, W, H)  # a hose ~1.5 px wide
    assert foreground_mask(z, coarse, ForegroundParams()) is None
    with pytest.raises(InputError, match="colour"):
        foreground_mask(z, K, ForegroundParams(colour_px=2))


def test_photometric_check_rejects_motion_the_image_does_not_show():
    plane = texture(H, W, seed=2, sigma=1.0) * 0.9 + 10  # a finely textured board
    g = np.zeros(3)
    target = Frame(_bar_scene(0.0, plane), _bar_depth(), K, g)
    frame = Frame(_bar_scene(3.0, plane), _bar_depth(), K, g, action=0)  # bar 3 px right
    sf = SampleFilter(RefineParams(arm_masks=False, photometric=8.0, photometric_blur=0.5), target)
    good = np.zeros((H, W, 2), np.float32)
    good[:, BAR_X : BAR_X + BAR_W, 0] = 3.0  # the true motion
    seen = np.ones((H, W), bool)  # away from the bar's edges (the blur mixes them)
    seen[:, BAR_X - 2 : BAR_X + 2] = seen[:, BAR_X + BAR_W - 2 : BAR_X + BAR_W + 5] = False
    seen[:20] = seen[-20:] = False
    assert np.isfinite(sf.apply(good, frame)[seen]).all()
    wrong = good.copy()
    wrong[:, BAR_X - 4 : BAR_X, 0] = 3.0  # dragged onto the plane beside the bar
    out = sf.apply(wrong, frame)
    assert np.isnan(out[20:-20, BAR_X - 4 : BAR_X]).mean() > 0.5


# ------------------------------------------------------------------------------ arm masks
class _ArmFlow(OracleFlow):
    """Ground truth from the frames, plus motion that follows the gripper inside the arm's
    region (what a flow back end sees where the arm covers the board)."""

    def frame_flow(self, frame, target):
        flow = super().frame_flow(frame, target)
        if frame is not target:
            flow[ARM + (0,)] = frame.gripper[0] * F / Z_BAR
        return flow


def _arm_stream(with_masks: bool) -> Stream:
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, (H, W, 3), dtype=np.uint8)
    depth = np.ones((H, W), np.float32)
    arm = np.zeros((H, W), bool)
    arm[ARM] = True
    frames = []
    for k in range(17):
        d = 3.0 * np.sin(2 * np.pi * k / 16)
        flow = np.zeros((H, W, 2), np.float32)
        flow[:, 20:26, 0] = d  # the grasped hose
        t = FrameTruth(np.zeros((H, W), np.int16), 0, flow, np.ones((H, W), bool))
        frames.append(
            Frame(
                rgb,
                depth,
                K,
                np.array([d * Z_BAR / F, 0, Z_BAR]),
                action=0,
                sample=k,
                truth=t,
                arm_mask=arm if with_masks else None,
            )
        )
    target = Frame(
        rgb, depth, K, np.zeros(3), arm_mask=np.zeros((H, W), bool) if with_masks else None
    )
    return Stream([*frames, target])


def test_arm_masks_never_vote():
    arm = np.zeros((H, W), bool)
    arm[ARM] = True
    hose = np.zeros((H, W), bool)
    hose[:, 20:26] = True
    without = segment_stream(_arm_stream(False), flow=_ArmFlow()).mask("union")
    assert without[arm].mean() > 0.9  # the arm's motion follows the gripper: it would vote
    masked = segment_stream(_arm_stream(True), flow=_ArmFlow()).mask("union")
    assert not masked[arm].any()  # where the arm was, perception ignores the pixels
    assert masked[hose].mean() > 0.9  # and the hose still votes
    # switched off, the masks are ignored
    off = segment_stream(_arm_stream(True), flow=_ArmFlow(), refine=RAW).mask("union")
    assert off[arm].mean() > 0.9
    # the target frame's own arm pixels never vote either
    s = _arm_stream(True)
    s.frames[-1].arm_mask = hose.copy()
    st = compute_statistics(s, _ArmFlow(), methods=("correlation",))
    assert st.support is not None and not st.support[hose].any()
    assert support_mask(s.target, RAW) is None


# ------------------------------------------------------------------ colour growth
def _crossing() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A red hose (row band) crossing over a blue one (column band) on a grey board:
    (rgb, red truth, blue truth)."""
    rgb = np.full((60, 80, 3), 128, np.uint8)
    red = np.zeros((60, 80), bool)
    red[28:34, :] = True
    blue = np.zeros((60, 80), bool)
    blue[:, 40:46] = True
    blue &= ~red  # the red hose lies on top
    rgb[blue] = (40, 80, 200)
    rgb[red] = (200, 40, 30)
    return rgb, red, blue


def test_colour_growth_fills_the_hose_and_stops_at_other_colours():
    rgb, red, blue = _crossing()
    seed = np.zeros_like(red)
    seed[29:33, 5:12] = True  # the flow found a short piece of the red hose
    grown = grow_by_colour(seed, colour_guide(rgb), GrowParams(colour=15.0))
    np.testing.assert_array_equal(grown, red)  # all of it, across the crossing, nothing else
    # limited steps: 10 px on either side of the seed
    near = grow_by_colour(seed, colour_guide(rgb), GrowParams(colour=15.0, max_px=10))
    assert near.sum() == 6 * (12 + 10 - 0)  # columns 0..21 of the 6 red rows
    assert near[28:34, :22].all() and not near[:, 22:].any()
    # the support bounds it (the right half is not allowed to vote)
    support = np.zeros_like(red)
    support[:, :50] = True
    half = grow_by_colour(seed, colour_guide(rgb), GrowParams(), support)
    np.testing.assert_array_equal(half, red & support)
    assert not grow_by_colour(np.zeros_like(red), colour_guide(rgb), GrowParams()).any()


def test_colour_growth_leaks_along_a_hose_of_the_same_colour():
    """Why it is not a default: where the hoses share a colour the mask takes both."""
    rgb, red, blue = _crossing()
    rgb[blue] = (200, 40, 30)
    seed = np.zeros_like(red)
    seed[29:33, 5:12] = True
    grown = grow_by_colour(seed, colour_guide(rgb), GrowParams())
    np.testing.assert_array_equal(grown, red | blue)


def test_grow_params_are_checked():
    with pytest.raises(InputError, match="colour > 0"):
        GrowParams(colour=0.0)
    with pytest.raises(InputError, match="max_px"):
        GrowParams(max_px=0)


def test_colour_growth_in_the_pipeline_only_adds_pixels_of_the_bar(bar_stream: Stream):
    """On the bar scene the grown masks hold the plain masks and stay on the bar."""
    truth = bar_stream.target.truth.labels == 0
    fg = RefineParams(foreground=ForegroundParams(colour_px=3))
    plain = segment_stream(bar_stream, flow=DISFlow("medium"), refine=fg)
    grow = RefineParams(foreground=ForegroundParams(colour_px=3), grow=GrowParams())
    grown = segment_stream(bar_stream, flow=DISFlow("medium"), refine=grow)
    assert grown.stats.grow == GrowParams() and grown.stats.guide is not None
    for a, m in plain.masks.items():
        g = grown.masks[a]
        assert (g | m).sum() == g.sum()  # nothing lost
        assert (g & ~truth).sum() <= (m & ~truth).sum()  # nothing added off the bar
    assert (grown.mask(1) & truth).sum() >= (plain.mask(1) & truth).sum()


# ------------------------------------------------------------------------------ normal flow
def _plain_bar(offset: float) -> np.ndarray:
    """The bar on a plain grey plane: the solid board, where only the bar's edges carry
    texture."""
    return _bar_scene(offset, np.full((H, W), 120.0))


def test_edge_normals_point_across_the_bar_and_vanish_where_nothing_is_seen():
    n = edge_normals(_plain_bar(0.0), 1.5)
    for x in (BAR_X - 1, BAR_X, BAR_X + BAR_W - 1, BAR_X + BAR_W):
        assert np.allclose(np.abs(n[10:-10, x]), [1.0, 0.0], atol=1e-4)
    assert np.all(n[:, :40] == 0)  # the plain plane has no gradient: no direction observed
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0], flow[..., 1] = 2.0, 3.0  # across the bar, and along it
    out = normal_flow(flow, n)
    edge = out[10:-10, BAR_X - 1]
    assert np.allclose(edge, [2.0, 0.0], atol=1e-3)  # the motion along the bar is dropped


class _Aperture(FlowEstimator):
    """The flow an image-based estimator gives for the bar: the true motion across it plus a
    drift along it that nothing in the images constrains (a seeded random walk, as DIS's
    patches wander along a plain hose on a plain board)."""

    name = "aperture"

    def __init__(self) -> None:
        self.rng = np.random.default_rng(4)

    def compute(self, image1, image2):
        raise AssertionError("frame_flow only")

    def frame_flow(self, frame: Frame, target: Frame) -> np.ndarray:
        out = np.zeros((H, W, 2), np.float32)
        if frame is target:
            return out
        d = frame.gripper[0] * F / Z_BAR  # px, the bar's shift in this frame
        out[:, BAR_X - 1 : BAR_X + BAR_W + 1, 0] = d
        out[:, BAR_X - 1 : BAR_X + BAR_W + 1, 1] = self.rng.normal(0.0, 4.0)
        return out


def test_normal_flow_restores_the_follow_test_of_a_plain_bar():
    """With a drift along the bar the correlation's principal direction is the drift and the
    bar fails the follow test; projected on the edge normals it passes."""
    frames = []
    n = 16
    for k in range(n + 1):
        d = 3.0 * np.sin(2 * np.pi * k / n)
        g = np.array([d * Z_BAR / F, 0.0, Z_BAR])
        frames.append(Frame(_plain_bar(d), _bar_depth(), K, g, action=0, sample=k))
    target = Frame(_plain_bar(0.0), _bar_depth(), K, np.array([0.3, 0.3, 0.5]))
    stream = Stream([*frames, target])
    edges = np.zeros((H, W), bool)
    edges[10:-10, [BAR_X - 1, BAR_X, BAR_X + BAR_W - 1, BAR_X + BAR_W]] = True

    def r2(refine: RefineParams) -> np.ndarray:
        st = compute_statistics(stream, _Aperture(), methods=("correlation",), refine=refine)
        return st.correlation[0].r2[edges]

    assert np.median(r2(RAW)) < 0.5
    assert np.all(r2(RefineParams(arm_masks=False, normal_flow=1.5)) > 0.99)


def test_normal_flow_leaves_ground_truth_whole_and_is_checked():
    target = Frame(_plain_bar(0.0), _bar_depth(), K, np.zeros(3))
    frame = Frame(_plain_bar(1.0), _bar_depth(), K, np.zeros(3), action=0, sample=1)
    phi = np.zeros((H, W, 2), np.float32)
    phi[..., 1] = 2.0  # along the bar
    params = RefineParams(arm_masks=False, normal_flow=1.5)
    np.testing.assert_array_equal(SampleFilter(params, target, OracleFlow()).apply(phi, frame), phi)
    projected = SampleFilter(params, target, DISFlow()).apply(phi, frame)
    assert np.allclose(projected[10:-10, BAR_X - 1], 0.0, atol=1e-3)
    with pytest.raises(InputError, match="normal_flow"):
        RefineParams(normal_flow=0.0)
