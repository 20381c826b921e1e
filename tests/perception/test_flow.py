"""Flow back ends against analytic motion; the texture gate; the oracle."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception import (
    DISFlow,
    FarnebackFlow,
    Frame,
    FrameTruth,
    GateParams,
    Intrinsics,
    OracleFlow,
    flow_epe,
    make_flow,
    texture_mask,
)

from .helpers import shifted, texture, to_u8_rgb

H, W = 96, 128


@pytest.mark.parametrize("est", [DISFlow("medium"), FarnebackFlow()], ids=["dis", "farneback"])
def test_subpixel_translation(est):
    img1 = texture(H, W, seed=3)
    dx, dy = 1.3, -0.7
    img2 = shifted(img1, dx, dy)  # image1(p) = image2(p + d)
    flow = est.compute(to_u8_rgb(img1), to_u8_rgb(img2))
    assert flow.shape == (H, W, 2) and flow.dtype == np.float32
    inner = flow[12:-12, 12:-12]
    tex = texture_mask(to_u8_rgb(img1))[12:-12, 12:-12]
    err = np.linalg.norm(inner[tex] - np.array([dx, dy]), axis=-1)
    assert np.median(err) < 0.15
    assert (
        flow_epe(flow[12:-12, 12:-12], np.broadcast_to(np.float32([dx, dy]), inner.shape).copy())
        < 0.3
    )


def _object_on_plain(seed=0):
    rng = np.random.default_rng(seed)
    bg = np.full((H, W), 128.0) + rng.normal(0, 1.0, (H, W))
    obj = texture(32, 32, seed=seed + 1)
    a = bg.copy()
    a[30:62, 40:72] = obj
    b = bg + rng.normal(0, 1.0, (H, W))
    b[32:64, 43:75] = obj
    plain = np.ones((H, W), bool)
    plain[22:72, 32:84] = False
    return to_u8_rgb(a), to_u8_rgb(b), plain


def test_gate_removes_motion_on_plain_background():
    a, b, plain = _object_on_plain()
    raw = DISFlow("medium", gate=GateParams(enabled=False)).compute(a, b)
    gated = DISFlow("medium").compute(a, b)
    moving_raw = (np.linalg.norm(raw, axis=-1)[plain] > 0.5).mean()
    moving_gated = (np.linalg.norm(gated, axis=-1)[plain] > 0.5).mean()
    assert moving_gated < 0.03
    assert moving_gated < moving_raw
    obj = np.median(gated[36:56, 46:66].reshape(-1, 2), 0)
    assert np.allclose(obj, [3, 2], atol=0.3)


def test_frame_flow_uses_target_as_first_image():
    K = Intrinsics(100, 100, W / 2, H / 2, W, H)
    img = texture(H, W, seed=5)
    # frame k shows the scene shifted by (+2, +1): frame(p + (2, 1)) = target(p)
    target = Frame(to_u8_rgb(img), np.ones((H, W), np.float32), K, np.zeros(3))
    frame = Frame(
        to_u8_rgb(shifted(img, 2.0, 1.0)), np.ones((H, W), np.float32), K, np.zeros(3), action=0
    )
    phi = DISFlow().frame_flow(frame, target)
    assert np.allclose(np.median(phi[10:-10, 10:-10].reshape(-1, 2), 0), [2, 1], atol=0.15)


def test_oracle_reads_truth_and_zeroes_invalid():
    K = Intrinsics(100, 100, 4, 3, 8, 6)
    flow = np.ones((6, 8, 2), np.float32)
    valid = np.ones((6, 8), bool)
    valid[0] = False
    truth = FrameTruth(labels=np.zeros((6, 8), np.int16), flow_to_target=flow, flow_valid=valid)
    rgb = np.zeros((6, 8, 3), np.uint8)
    f = Frame(rgb, np.ones((6, 8), np.float32), K, np.zeros(3), action=0, truth=truth)
    t = Frame(rgb, np.ones((6, 8), np.float32), K, np.zeros(3))
    phi = OracleFlow().frame_flow(f, t)
    assert (phi[0] == 0).all() and (phi[1:] == 1).all()
    assert np.isnan(OracleFlow(invalid_value=np.nan).frame_flow(f, t)[0]).all()
    assert (OracleFlow().frame_flow(t, t) == 0).all()
    with pytest.raises(InputError, match="ground-truth"):
        OracleFlow().frame_flow(
            Frame(rgb, np.ones((6, 8), np.float32), K, np.zeros(3), action=0), t
        )


def test_bad_images():
    est = DISFlow()
    with pytest.raises(InputError, match="uint8"):
        est.compute(np.zeros((8, 8), np.float32), np.zeros((8, 8), np.float32))
    with pytest.raises(InputError, match="differ"):
        est.compute(np.zeros((8, 8), np.uint8), np.zeros((8, 9), np.uint8))
    with pytest.raises(InputError, match="preset"):
        DISFlow("slowest")
    with pytest.raises(InputError, match="unknown flow"):
        make_flow("lucas-kanade")


def test_the_gate_cache_tells_images_of_the_same_bytes_apart_by_shape():
    """The gate is cached per target image; two targets with the same pixel bytes but other
    shapes (120x160 and 160x120) must each get their own gate."""
    from cablesim.perception.flow import DISFlow, texture_mask

    rng = np.random.default_rng(3)
    flat = np.zeros(120 * 160, np.uint8)
    flat[: 120 * 80] = rng.integers(0, 255, 120 * 80, dtype=np.uint8)  # textured half
    dis = DISFlow(preset="medium")
    for shape in ((120, 160), (160, 120)):
        img = flat.reshape(shape)
        flow = dis.compute(img, img)
        assert flow.shape == (*shape, 2)
        np.testing.assert_array_equal(dis._gate(img), texture_mask(img))
