"""MovingCables flow PNG and the real-robot sequence folder."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cablesim.errors import InputError, RecordingError
from cablesim.perception import read_flow_png, read_sequence, write_flow_png, write_sequence
from cablesim.perception.formats import labels_to_instances
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream


def test_flow_png_roundtrip_and_channel_order(tmp_path):
    rng = np.random.default_rng(0)
    flow = rng.uniform(-100, 100, (6, 7, 2)).astype(np.float32)
    inst = rng.integers(0, 5, (6, 7)).astype(np.uint16)
    p = tmp_path / "flow.png"
    write_flow_png(p, flow, inst)
    back, ids = read_flow_png(p)
    assert np.abs(back - flow).max() <= 0.5 / 64 + 1e-6
    assert np.array_equal(ids, inst)
    raw = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)  # BGR: index 2 is the PNG's first channel
    assert raw.dtype == np.uint16
    assert (raw[0, 0, 2] - 2**15) / 64 == pytest.approx(flow[0, 0, 0], abs=1 / 64)
    assert labels_to_instances(np.array([[-2, -1, 0, 3]])).tolist() == [[0, 0, 1, 4]]


def test_flow_png_errors(tmp_path):
    with pytest.raises(RecordingError, match="not found"):
        read_flow_png(tmp_path / "none.png")
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(RecordingError, match="decode"):
        read_flow_png(tmp_path / "bad.png")
    cv2.imwrite(str(tmp_path / "u8.png"), np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(RecordingError, match="16-bit"):
        read_flow_png(tmp_path / "u8.png")
    with pytest.raises(InputError, match="instances"):
        write_flow_png(
            tmp_path / "x.png", np.zeros((4, 4, 2), np.float32), np.zeros((3, 3), np.uint16)
        )


@pytest.fixture
def stream():
    return synthetic_stream(
        [Region((4, 14, 4, 40), "linear", 0.7, label=0)],
        SyntheticSpec(seed=2, samples_per_period=4, periods=1),
    )


def test_sequence_roundtrip(tmp_path, stream):
    mask = stream.target.truth.labels == 0
    arm = {0: np.eye(48, 64, dtype=bool)}
    write_sequence(
        tmp_path / "seq", stream, target_mask=mask, arm_masks=arm, crop=(100, 50, 64, 48)
    )
    back = read_sequence(tmp_path / "seq")
    assert len(back) == len(stream)
    for a, b in zip(stream.frames, back.frames, strict=True):
        assert np.array_equal(a.rgb, b.rgb)
        assert np.allclose(a.depth, b.depth, atol=5e-4)
        assert np.allclose(a.gripper, b.gripper)
        assert (a.action, a.sample) == (b.action, b.sample)
        assert b.truth is None
    K0, K1 = stream.intrinsics, back.intrinsics
    assert (K1.fx, K1.cx, K1.cy, K1.width) == pytest.approx((K0.fx, K0.cx, K0.cy, K0.width))
    assert np.array_equal(back.meta["target_mask"], mask)
    assert np.array_equal(back.meta["arm_masks"][0], arm[0])
    assert back.target.is_target


def test_sequence_rescaled_crop(tmp_path, stream):
    K = np.array([[600.0, 0, 400], [0, 600, 300], [0, 0, 1]])
    write_sequence(tmp_path / "s", stream, crop=(10, 20, 32, 24), camera_matrix=K)
    back = read_sequence(tmp_path / "s")  # images 64x48 are the 32x24 crop scaled 2x
    assert back.intrinsics.fx == pytest.approx(1200)
    assert back.intrinsics.cx == pytest.approx((390 + 0.5) * 2 - 0.5)


def test_sequence_errors(tmp_path, stream):
    with pytest.raises(RecordingError, match="not found"):
        read_sequence(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordingError, match="missing"):
        read_sequence(tmp_path / "empty")
    seq = write_sequence(tmp_path / "seq", stream)
    (seq / "rgb_000001.png").unlink()
    with pytest.raises(RecordingError, match="rgb_000001"):
        read_sequence(seq)
    (seq / "depth_000000.png").write_bytes(b"garbage")
    meta = json.loads((seq / "actions_gripper.json").read_text())
    with pytest.raises(RecordingError, match="depth_000000"):
        read_sequence(seq)
    (seq / "actions_gripper.json").write_text("{not json")
    with pytest.raises(RecordingError, match="JSON"):
        read_sequence(seq)
    meta["version"] = 99
    (seq / "actions_gripper.json").write_text(json.dumps(meta))
    with pytest.raises(RecordingError, match="version"):
        read_sequence(seq)
    meta["version"] = 1
    del meta["frames"][0]["gripper"]
    (seq / "actions_gripper.json").write_text(json.dumps(meta))
    with pytest.raises(RecordingError, match="frame 0"):
        read_sequence(seq)
