"""Fuzzing perception: frames, streams, flow back ends, masks and metrics, vote images, the
grasp sampler, parameters and the flow PNG format.  Every input works or raises the project's
own error (InputError); nothing else escapes and nothing hangs."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cablesim.formats.movingcables import read_flow_png, write_flow_png
from cablesim.frames import Frame, FrameTruth, Intrinsics, Stream
from cablesim.perception import score_mask, segment_stream
from cablesim.perception.correlation import (
    AblationParams,
    CorrelationAccumulator,
    CorrelationParams,
)
from cablesim.perception.flow import DISFlow, FarnebackFlow, GateParams, OracleFlow, texture_mask
from cablesim.perception.grasp_sampler import GraspSampler, GraspSamplerParams
from cablesim.perception.metrics import confusion, flow_epe, grade_proposal
from cablesim.perception.segmentation import SegmentationParams
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.perception.votes import VoteAccumulator, merge_votes, vote_image

from ._fuzz import HOSTILE, SCALARS, fuzz, own_error_or_result

DTYPES = st.sampled_from(
    [np.uint8, np.int8, np.int16, np.int32, np.int64, np.uint64, np.float32, np.float64, bool]
)


def arrays(shape=None, dtype=None, max_side: int = 12) -> st.SearchStrategy[np.ndarray]:
    """Arrays of any (or the given) dtype and shape, with NaN, infinities and extremes."""
    shapes = (
        shape
        if shape is not None
        else hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=max_side)
    )
    return (dtype if dtype is not None else DTYPES).flatmap(
        lambda dt: hnp.arrays(np.dtype(dt), shapes)
    )


def images(h: int, w: int) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.uint8, (h, w, 3))


ANYTHING = st.one_of(HOSTILE, arrays())


# ------------------------------------------------------------------ frames and streams
@fuzz(200)
@given(st.lists(st.one_of(SCALARS, st.integers(0, 700)), min_size=6, max_size=6))
def test_intrinsics(values):
    own_error_or_result(Intrinsics, *values)
    keys = ("fx", "fy", "cx", "cy", "width", "height")
    own_error_or_result(Intrinsics.from_dict, dict(zip(keys, values, strict=True)))


@fuzz(40)
@given(HOSTILE)
def test_intrinsics_from_anything(d):
    own_error_or_result(Intrinsics.from_dict, d)


K = Intrinsics(100.0, 100.0, 15.5, 11.5, 32, 24)


@fuzz(150)
@given(
    rgb=st.one_of(images(24, 32), arrays()),
    depth=st.one_of(st.none(), hnp.arrays(np.float32, (24, 32)), arrays()),
    gripper=st.one_of(arrays(), HOSTILE),
    action=st.one_of(st.integers(-2, 3), SCALARS, arrays()),
    timestamp=st.one_of(st.floats(allow_nan=True), SCALARS),
    labels=st.one_of(st.none(), arrays(), hnp.arrays(np.int16, (24, 32))),
)
def test_frames(rgb, depth, gripper, action, timestamp, labels):
    truth = None if labels is None else FrameTruth(labels)
    own_error_or_result(
        Frame, rgb, depth, K, gripper, action=action, timestamp=timestamp, truth=truth
    )


def valid_frame(k: Intrinsics, action: int) -> Frame:
    h, w = k.height, k.width
    return Frame(np.zeros((h, w, 3), np.uint8), np.ones((h, w), np.float32), k, np.zeros(3), action)


@fuzz(80)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(
                [K, Intrinsics(90.0, 90.0, 15.5, 11.5, 32, 24), Intrinsics(1, 1, 0, 0, 8, 8)]
            ),
            st.integers(-1, 2),
        ),
        max_size=5,
    ),
    st.booleans(),
)
def test_streams(specs, junk):
    frames: list = [valid_frame(k, a) for k, a in specs]
    if junk:
        frames.append("not a frame")
    stream = own_error_or_result(Stream, frames)
    if stream is not None:
        own_error_or_result(lambda: stream.target)


@fuzz(25, deadline_ms=20000)
@given(
    h=st.integers(1, 40),
    w=st.integers(1, 70),
    periods=st.integers(1, 2),
    samples=st.integers(1, 4),
    method=st.sampled_from(["correlation", "segmentation", "ablation", "magic"]),
    flow=st.sampled_from(["oracle", "dis", "farneback"]),
)
def test_segment_synthetic_streams(h, w, periods, samples, method, flow):
    spec = SyntheticSpec(height=h, width=w, periods=periods, samples_per_period=samples)
    box = (h // 4, max(h // 4 + 1, 3 * h // 4), w // 4, max(w // 4 + 1, 3 * w // 4))
    stream = own_error_or_result(synthetic_stream, [Region(box, label=0)], spec)
    if stream is None:
        return
    seg = own_error_or_result(segment_stream, stream, method=method, flow=flow, pipelined=False)
    if seg is not None:
        mask = seg.mask("union")
        assert mask.shape == (h, w) and mask.dtype == bool


# ------------------------------------------------------------------ flow back ends
@fuzz(80)
@given(
    st.one_of(arrays(max_side=70), images(8, 8), images(48, 64)),
    st.one_of(arrays(max_side=70), images(8, 8), images(48, 64)),
    st.sampled_from(["dis", "farneback", "dis-fast"]),
)
def test_flow_back_ends(a, b, which):
    est = {"dis": DISFlow(), "farneback": FarnebackFlow(), "dis-fast": DISFlow("fast")}[which]
    flow = own_error_or_result(est.compute, a, b)
    if flow is not None:
        assert flow.shape == (*a.shape[:2], 2) and flow.dtype == np.float32


@fuzz(80)
@given(st.integers(0, 100), st.integers(0, 140), st.sampled_from(["ultrafast", "fast", "medium"]))
def test_dis_any_size(h, w, preset):
    """Every image size either works or is refused (OpenCV crashes the process on some)."""
    rng = np.random.default_rng(h * 1000 + w)
    a = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    flow = own_error_or_result(DISFlow(preset).compute, a, a)
    if flow is not None:
        assert flow.shape == (h, w, 2)


@fuzz(60)
@given(arrays(), st.one_of(st.integers(-2, 20), SCALARS), st.one_of(st.floats(), SCALARS))
def test_texture_mask_and_gate(img, window, threshold):
    own_error_or_result(texture_mask, img, window, threshold)
    own_error_or_result(GateParams, True, window, threshold)


@fuzz(40)
@given(arrays(), arrays())
def test_oracle_flow(flow, valid):
    f = valid_frame(K, 0)
    f.truth = FrameTruth(np.zeros((24, 32), np.int16), flow_to_target=flow, flow_valid=valid)
    own_error_or_result(OracleFlow().frame_flow, f, valid_frame(K, -1))


# ------------------------------------------------------------------ masks, metrics, votes
@fuzz(150)
@given(
    arrays(max_side=6),
    arrays(max_side=6),
    st.one_of(st.just((1.0, 0.4)), st.lists(st.one_of(st.floats(), SCALARS), max_size=2)),
    st.one_of(st.none(), st.lists(st.integers(-2, 8), min_size=4, max_size=4), HOSTILE),
)
def test_masks_and_metrics(pred, truth, betas, crop):
    own_error_or_result(confusion, pred, truth)
    scores = own_error_or_result(score_mask, pred, truth, betas)
    if scores is not None:
        for v in (scores.precision, scores.recall, scores.iou):  # NaN where undefined
            assert not (v < 0 or v > 1)
    own_error_or_result(score_mask, pred, truth, (1.0,), crop)
    own_error_or_result(flow_epe, pred, truth)
    own_error_or_result(grade_proposal, pred, truth, 0, True)


@fuzz(100)
@given(
    st.lists(arrays(max_side=5), max_size=3),
    st.one_of(st.integers(-1, 4), st.sampled_from(["union", "intersection", "x"]), SCALARS),
)
def test_votes(masks, n):
    votes = own_error_or_result(vote_image, masks)
    if votes is not None:
        own_error_or_result(merge_votes, votes, n, len(masks))
    acc = VoteAccumulator((4, 5))
    own_error_or_result(acc.add, masks)
    own_error_or_result(acc.mask, n)


# ------------------------------------------------------------------ grasp sampler
def bar_depth(h: int, w: int) -> np.ndarray:
    return np.full((h, w), 1.0, np.float32)


@fuzz(120)
@given(
    votes=st.one_of(
        arrays(max_side=24),
        st.tuples(DTYPES, st.integers(0, 2**64 - 1)).map(
            lambda t: np.where(np.arange(24 * 32).reshape(24, 32) % 7 < 3, 0, t[1] % 2**62).astype(
                t[0]
            )
        ),
    ),
    depth=st.one_of(
        hnp.arrays(np.float32, (24, 32)), arrays(max_side=24), st.just(bar_depth(24, 32))
    ),
    k=st.sampled_from([K, Intrinsics(100.0, 100.0, 15.5, 11.5, 31, 24), None]),
    blacklist=st.booleans(),
)
def test_grasp_sampler(votes, depth, k, blacklist):
    sampler = GraspSampler()
    if blacklist:
        sampler.add_grasp(np.array([0.0, 0.0, 1.0]), np.zeros((24, 32), bool))
    res = own_error_or_result(sampler.propose, votes, depth, k)
    if res is not None and res.proposal is not None:
        assert np.all(np.isfinite(res.proposal.centre))


@fuzz(80)
@given(
    st.dictionaries(
        st.sampled_from(
            [
                "segment_length_px",
                "gather_radius_px",
                "area_min",
                "area_max",
                "eccentricity_min",
                "min_votes",
                "g_min",
                "g_max",
                "g_delta",
                "blacklist_overlap",
            ]
        ),
        st.one_of(SCALARS, st.integers(0, 50), st.floats(0, 2)),
        max_size=3,
    )
)
def test_sampler_params(kwargs):
    params = own_error_or_result(GraspSamplerParams, **kwargs)
    if params is not None:
        votes = np.zeros((24, 32), np.int16)
        votes[10:14, 4:28] = 2
        own_error_or_result(GraspSampler(params).propose, votes, bar_depth(24, 32), K)


# ------------------------------------------------------------------ parameters, accumulators
@fuzz(100)
@given(
    st.sampled_from([CorrelationParams, AblationParams, SegmentationParams]),
    st.dictionaries(
        st.sampled_from(
            ["tau_n", "c0_min", "r2_min", "depth_mode", "min_samples", "std_min", "tau_m", "tau_v"]
        ),
        st.one_of(SCALARS, st.floats(-1, 5), st.sampled_from(["gripper", "pixel"])),
        max_size=3,
    ),
)
def test_method_params(cls, kwargs):
    try:
        own_error_or_result(cls, **kwargs)
    except TypeError as e:  # an unknown keyword for this class: Python's own call error
        assert "unexpected keyword" in str(e)


@fuzz(60)
@given(
    flow=st.one_of(hnp.arrays(np.float32, (6, 8, 2)), arrays(max_side=8)),
    d_g=st.one_of(st.floats(allow_nan=True, allow_infinity=True), SCALARS),
    z=st.one_of(st.floats(allow_nan=True, allow_infinity=True), SCALARS),
    focal=st.one_of(st.floats(allow_nan=True), SCALARS),
)
def test_correlation_accumulator(flow, d_g, z, focal):
    acc = own_error_or_result(CorrelationAccumulator, (6, 8), focal)
    if acc is None:
        return
    for _ in range(3):
        own_error_or_result(acc.update, flow, d_g, z)
    own_error_or_result(acc.result)


# ------------------------------------------------------------------ flow PNG
@fuzz(60)
@given(flow=arrays(max_side=6), instances=st.one_of(st.none(), arrays(max_side=6)))
def test_flow_png_round_trip(tmp_path_factory, flow, instances):
    path = tmp_path_factory.mktemp("png") / "f.png"
    if own_error_or_result(write_flow_png, path, flow, instances) is None:
        return
    back = own_error_or_result(read_flow_png, path)
    assume(back is not None)
    got, _ = back
    finite = np.isfinite(flow)
    assert np.allclose(got[finite], flow[finite], atol=1 / 64 + 1e-6)


@fuzz(30)
@given(st.binary(max_size=200))
def test_flow_png_from_any_bytes(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("png") / "f.png"
    path.write_bytes(data)
    own_error_or_result(read_flow_png, path)
