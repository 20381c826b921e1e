"""Motion correlation, segmentation baseline and ablation on synthetic streams."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from cablesim.errors import InputError
from cablesim.perception import (
    AblationParams,
    CorrelationAccumulator,
    CorrelationParams,
    SegmentationParams,
    segment_stream,
)
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream

BOXES = {
    "pos": (4, 14, 4, 28),
    "neg": (18, 28, 4, 28),
    "random": (32, 44, 4, 28),
    "lag": (4, 14, 36, 60),
    "oneoff": (18, 28, 36, 60),
}


@pytest.fixture(scope="module")
def stream():
    regions = [
        Region(BOXES["pos"], "linear", 0.8, label=0),
        Region(BOXES["neg"], "linear", -0.6, label=0),
        Region(BOXES["random"], "random", 0.8, label=1),
        Region(BOXES["lag"], "lag", 0.8, label=1),
        Region(BOXES["oneoff"], "oneoff", 0.8, label=2),
    ]
    # noise 0.2 px << tau_n = 0.67 px on the static rest
    return synthetic_stream(regions, SyntheticSpec(noise_px=0.2, seed=1))


def _box(m, name):
    y0, y1, x0, x1 = BOXES[name]
    return m[y0:y1, x0:x1]


def _rest(m):
    m = m.copy()
    for y0, y1, x0, x1 in BOXES.values():
        m[y0:y1, x0:x1] = False
    return m


@pytest.mark.parametrize("depth_mode", ["gripper", "pixel"])
def test_correlation_labels_linear_regions_only(stream, depth_mode):
    params = CorrelationParams(depth_mode=depth_mode)
    seg = segment_stream(stream, "correlation", flow="oracle", params=params, pipelined=False)
    assert set(seg.masks) == {0, 1}
    for a, m in seg.masks.items():
        assert _box(m, "pos").all(), a
        assert _box(m, "neg").all(), a  # negative gain: labelled too (|c0|)
        for name in ("random", "lag", "oneoff"):
            assert not _box(m, name).any(), (a, name)
        assert not _rest(m).any()  # static noise below tau_n ignored
    c0 = seg.c0[0]
    assert np.allclose(_box(c0, "pos"), 0.8, atol=0.02) or np.allclose(
        _box(c0, "pos"), -0.8, atol=0.02
    )
    assert np.allclose(np.abs(_box(c0, "neg")), 0.6, atol=0.02)
    assert np.all(_box(seg.r2[0], "pos") > 0.99)
    assert (seg.votes[4:14, 4:28] == 2).all()
    assert seg.mask("intersection").sum() == seg.mask(2).sum()


def test_segmentation_baseline_labels_all_motion(stream):
    seg = segment_stream(
        stream, "segmentation", flow="oracle", params=SegmentationParams(), pipelined=False
    )
    m = seg.mask("union")
    assert _box(m, "pos").all() and _box(m, "neg").all()
    assert _box(m, "random").mean() > 0.5  # the baseline cannot tell independent motion
    assert not _rest(m).any()


def test_ablation_uses_std_of_dphi(stream):
    seg = segment_stream(
        stream, "ablation", flow="oracle", params=AblationParams(std_min=0.004), pipelined=False
    )
    m = seg.mask("union")
    assert _box(m, "pos").all()
    assert _box(m, "random").all()  # moves a lot, ignored gripper: labelled
    assert not _rest(m).any()


def _batch(rs, dgs, tau_n, scale):
    """Reference: explicit per-sample arrays at one pixel."""
    rs = np.asarray(rs, float)
    dgs = np.asarray(dgs, float)
    used = np.linalg.norm(rs, axis=1) > tau_n
    s = rs[used] * np.asarray(scale, float)[used, None]
    g = dgs[used]
    cov = np.cov(s.T, bias=True)
    w, v = np.linalg.eigh(cov)
    psi = v[:, 1]
    dphi = s @ psi
    if g.std() <= 1e-3 or dphi.std() <= 1e-5:  # degenerate: no fit (checked by the caller)
        return psi, 0.0, 0.0, dphi.std(), w, g
    c0, c1 = np.polyfit(g, dphi, 1)
    pred = c0 * g + c1
    r2 = 1 - np.sum((dphi - pred) ** 2) / np.sum((dphi - dphi.mean()) ** 2)
    return psi, c0, r2, dphi.std(), w, g


vec = st.tuples(st.floats(-20, 20), st.floats(-20, 20))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    samples=st.lists(
        st.tuples(vec, st.floats(-0.03, 0.03), st.floats(0.5, 2.0)), min_size=4, max_size=30
    ),
    dtype=st.sampled_from([np.float32, np.float64]),
)
def test_one_pass_moments_match_batch(samples, dtype):
    tau_n = 0.67
    focal = 500.0
    ref = np.full((2, 3, 2), 0.25, np.float32)
    flows = [ref + np.asarray(smp[0], np.float32) for smp in samples]
    # the relative flow the accumulator sees (flows are float32)
    rs = [f[0, 0].astype(np.float64) - ref[0, 0].astype(np.float64) for f in flows]
    dgs = [smp[1] for smp in samples]
    zs = [smp[2] for smp in samples]
    mags = np.linalg.norm(np.asarray(rs), axis=1)
    assume(np.all(np.abs(mags - tau_n) > 1e-4))  # float32 may round across the threshold
    used = mags > tau_n
    assume(used.sum() >= 3)
    psi, c0, r2, std, w, g = _batch(rs, dgs, tau_n, np.asarray(zs) / focal)
    # well-posed cases only: distinct eigenvalues, spread in d_g and d_phi
    assume(w[1] > 1.2 * w[0] + 1e-9 and g.std() > 1e-3 and std > 1e-5)
    if dtype == np.float32:
        # float32 running sums lose the covariance to cancellation when it is tiny compared
        # with the squared mean: compare only well-conditioned moments
        s = np.asarray(rs)[used] * (np.asarray(zs)[used, None] / focal)
        assume(w[1] - w[0] > 1e-3 * (np.sum(s.mean(0) ** 2) + w[1]))
        assume(g.var() > 1e-3 * (g.mean() ** 2 + g.var()))
    acc = CorrelationAccumulator((2, 3), focal, CorrelationParams(tau_n=tau_n), dtype=dtype)
    acc.update(ref, 0.0, 1.0)
    for f, d, z in zip(flows, dgs, zs, strict=True):
        acc.update(f, d, z)
    res = acc.result()
    tol = 1e-5 if dtype == np.float64 else 2e-2
    for y in range(2):
        for x in range(3):
            assert res.n[y, x] == used.sum()
            assert abs(abs(float(np.dot(res.psi[y, x], psi))) - 1) < tol
            assert abs(abs(res.c0[y, x]) - abs(c0)) <= tol * (1 + abs(c0))
            assert abs(res.r2[y, x] - r2) <= tol
            assert abs(res.std_dphi[y, x] - std) <= tol * (std + 1e-4)


def test_memory_independent_of_length():
    import tracemalloc

    flows = [np.random.default_rng(k).normal(size=(64, 64, 2)).astype(np.float32) for k in range(4)]

    def peak(n: int) -> int:
        tracemalloc.start()
        acc = CorrelationAccumulator((64, 64), 500.0)
        for k in range(n):
            acc.update(flows[k % 4], k * 1e-4, 1.0)
        acc.result()
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak

    # keeping anything per frame would add at least 64 * 64 * 4 bytes for each of 180 frames
    assert peak(200) <= peak(20) + 64 * 64 * 4


def test_invalid_flow_gives_no_sample():
    """NaN flow (no measurement) must not poison the moments of a pixel."""
    rng = np.random.default_rng(1)
    d_g = np.linspace(0, 0.02, 12)
    clean = CorrelationAccumulator((1, 2), 500.0)
    holey = CorrelationAccumulator((1, 2), 500.0)
    for k, g in enumerate(d_g):
        f = np.zeros((1, 2, 2), np.float32)
        f[..., 0] = 400 * g + rng.normal(0, 0.05, 2)
        clean.update(f, g, 1.0)
        h = f.copy()
        if k == 5:
            h[0, 0] = np.nan  # pixel 0 unmeasured in one frame
        holey.update(h, g, 1.0)
    a, b = clean.result(), holey.result()
    assert np.isfinite(b.c0).all() and np.isfinite(b.r2).all()
    assert b.n[0, 0] == a.n[0, 0] - 1 and b.n[0, 1] == a.n[0, 1]
    assert b.c0[0, 0] == pytest.approx(a.c0[0, 0], rel=0.05) and b.r2[0, 0] > 0.9
    ref_missing = CorrelationAccumulator((1, 1), 500.0)
    ref_missing.update(np.full((1, 1, 2), np.nan, np.float32), 0.0, 1.0)
    for g in d_g[1:]:
        ref_missing.update(np.full((1, 1, 2), 400 * g, np.float32), g, 1.0)
    assert ref_missing.result().n[0, 0] == 0


def test_too_few_samples_give_zero():
    acc = CorrelationAccumulator((1, 1), 500.0, CorrelationParams(min_samples=3))
    acc.update(np.zeros((1, 1, 2), np.float32), 0.0, 1.0)
    acc.update(np.full((1, 1, 2), 5.0, np.float32), 0.01, 1.0)
    acc.update(np.full((1, 1, 2), 10.0, np.float32), 0.02, 1.0)
    res = acc.result()
    assert res.r2[0, 0] == 0 and res.c0[0, 0] == 0


def test_bad_input():
    acc = CorrelationAccumulator((4, 5), 500.0)
    with pytest.raises(InputError, match="size"):
        acc.update(np.zeros((5, 4, 2), np.float32), 0.0, 1.0)
    with pytest.raises(InputError, match="floating"):
        acc.update(np.zeros((4, 5, 2), np.int32), 0.0, 1.0)
    with pytest.raises(InputError, match="HxWx2"):
        acc.update(np.zeros((4, 5), np.float32), 0.0, 1.0)
    with pytest.raises(InputError, match="gripper depth"):
        acc.update(np.zeros((4, 5, 2), np.float32), 0.0, None)
    with pytest.raises(InputError, match="focal"):
        CorrelationAccumulator((4, 5), 0.0)
    with pytest.raises(InputError, match="pixel"):
        CorrelationAccumulator((4, 5), 500.0, CorrelationParams(depth_mode="pixel"))
    with pytest.raises(InputError, match="depth_mode"):
        CorrelationParams(depth_mode="median")
    with pytest.raises(InputError, match="tau_v"):
        SegmentationParams(tau_v=1.5)


def test_segment_stream_rejects_bad_method(stream):
    with pytest.raises(InputError, match="method"):
        segment_stream(stream, "magic", flow="oracle")
    with pytest.raises(InputError, match="Params"):
        segment_stream(stream, "segmentation", flow="oracle", params=CorrelationParams())
