"""The published motion-correlation layout: the writer follows the published code's
``save_buffer_to_disk``, the reader follows its ``load_buffer_from_disk`` and the dataset's
annotations tree; round trips, legacy files and bad files."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cablesim.errors import InputError, RecordingError
from cablesim.formats import detect_layout, read_any
from cablesim.formats.mcor import (
    find_annotation,
    multigrasp_name,
    read_mcor,
    read_multigrasp,
    retarget,
    sequence_name,
    transform_point,
    write_annotation,
    write_mcor,
    write_multigrasp,
)

NAME = "2024-08-06-153012"
# the keys save_buffer_to_disk writes (camera_matrix and the transform when given)
PUBLISHED_KEYS = {
    "action_buffer",
    "ee_point_buffer",
    "crop_origin",
    "crop_size",
    "scale_factor",
    "camera_matrix",
    "robot_base_to_camera_transform",
}


def _transform() -> np.ndarray:
    a = 0.6
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = R @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    T[:3, 3] = [0.1, -0.2, 1.3]
    return T


@pytest.fixture
def dataset(tmp_path, moving_stream):
    """A CMCor-like tree: buffers/<name> written by write_mcor, annotations/validation/<name>."""
    root = tmp_path / "CMCor"
    seq = root / "motion_correlation_buffers" / NAME
    h, w = moving_stream.frames[0].shape
    arm = {i: np.zeros((h, w), bool) for i in range(len(moving_stream))}
    arm[3][:5, :5] = True
    segment = moving_stream.target.truth.labels == 0
    segment[:, 40:] = False
    write_mcor(
        seq,
        moving_stream,
        segment=segment,
        arm_masks=arm,
        base_to_camera=_transform(),
        crop_origin=(8, 20),
        crop_size=(80, 40),
        scale_factor=1.5,
    )
    truth = moving_stream.target.truth.labels == 0
    ann = root / "motion_correlation_annotations"
    write_annotation(ann, "validation", NAME, len(moving_stream) - 1, truth)
    return seq, arm, segment, truth


def test_writer_follows_the_published_schema(dataset, moving_stream):
    seq, _, _, _ = dataset
    text = (seq / "actions_gripper.json").read_text()
    doc = json.loads(text)
    assert set(doc) == PUBLISHED_KEYS  # arm masks given: no poor_arm_masks
    assert text == json.dumps(doc, sort_keys=True, indent=4)
    n = len(moving_stream)
    assert len(doc["action_buffer"]) == len(doc["ee_point_buffer"]) == n
    assert doc["action_buffer"][-1] == -1 and doc["action_buffer"][0] == 0
    assert (doc["crop_origin"], doc["crop_size"], doc["scale_factor"]) == ([8, 20], [80, 40], 1.5)
    T = np.array(doc["robot_base_to_camera_transform"])
    for p, f in zip(doc["ee_point_buffer"], moving_stream.frames, strict=True):
        np.testing.assert_allclose(transform_point(T, np.array(p)), f.gripper, atol=1e-12)
    names = sorted(p.name for p in seq.iterdir())
    for kind in ("rgb", "depth", "arm"):
        assert [x for x in names if x.startswith(kind + "_")] == [
            f"{kind}_{i:08d}.png" for i in range(n)
        ]
    assert "grasped_cable_00000000.png" in names
    # the published loader reads colour with OpenCV and reverses it to RGB
    raw = cv2.imread(str(seq / "rgb_00000005.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(raw[..., ::-1], moving_stream.frames[5].rgb)
    depth = cv2.imread(str(seq / "depth_00000000.png"), cv2.IMREAD_UNCHANGED)
    assert depth.dtype == np.uint16 and int(depth[0, 0]) == 1000  # millimetres
    arm = cv2.imread(str(seq / "arm_00000003.png"), cv2.IMREAD_UNCHANGED)
    assert set(np.unique(arm)) == {0, 255}


def test_round_trip(dataset, moving_stream):
    seq_dir, arm, segment, truth = dataset
    assert detect_layout(seq_dir) == "mcor"
    seq = read_mcor(seq_dir)
    s = seq.stream
    assert len(s) == len(moving_stream)
    for a, b in zip(moving_stream.frames, s.frames, strict=True):
        assert np.array_equal(a.rgb, b.rgb)
        np.testing.assert_allclose(a.depth, b.depth, atol=5e-4)
        np.testing.assert_allclose(a.gripper, b.gripper, atol=1e-12)
        assert a.action == b.action
    assert s.intrinsics == moving_stream.intrinsics
    assert s.meta["gripper_depth_source"] == "transform"
    assert s.meta["gripper_depth"] == pytest.approx(moving_stream.frames[0].gripper[2])
    assert (s.meta["crop_origin"], s.meta["crop_size"], s.meta["scale_factor"]) == (
        [8, 20],
        [80, 40],
        1.5,
    )
    assert seq.crop == (8, 20, 80, 40)
    assert s.meta["target_action"] == -1 and s.meta["has_depth"]
    assert np.array_equal(seq.segment, segment)
    assert sorted(seq.arm_masks) == list(range(len(s)))
    assert np.array_equal(seq.arm_masks[3], arm[3])
    # the annotation found in the dataset's tree, also as the target's ground truth
    assert seq.annotation.name == f"cable_mask_{len(s) - 1:08d}.png"
    assert seq.annotation.parent.parent.name == "validation"
    assert np.array_equal(seq.truth, truth)
    assert np.array_equal(s.target.truth.labels == s.target.truth.grasped_hose, truth)
    assert read_mcor(seq_dir, annotations=None).truth is None
    assert np.array_equal(read_any(seq_dir).frames[4].rgb, s.frames[4].rgb)


def test_legacy_sequence_without_intrinsics_transform_depth_or_arm(tmp_path, moving_stream):
    """Older published sequences: ``focal_length``/``gripper_depth`` numbers, no depth images,
    ``poor_arm_masks``; the gripper points stay in the base frame, shifted to depth Z."""
    seq = tmp_path / NAME
    write_mcor(seq, moving_stream, depth=False, target_action=1)
    doc = json.loads((seq / "actions_gripper.json").read_text())
    assert doc["poor_arm_masks"] is True  # the published reader needs it without arm masks
    base = np.array(doc["ee_point_buffer"]) + [0.4, 0.1, -0.7]
    doc.update(ee_point_buffer=base.tolist(), focal_length=512.0, gripper_depth=0.9)
    doc["action_buffer"][1] = -2  # any negative code is outside the actions
    for key in ("camera_matrix", "robot_base_to_camera_transform", "crop_origin"):
        del doc[key]
    (seq / "actions_gripper.json").write_text(json.dumps(doc))
    s = read_mcor(seq).stream
    K = s.intrinsics
    assert (K.fx, K.fy, K.cx) == (512.0, 512.0, (K.width - 1) / 2)
    assert s.meta["gripper_depth_source"] == "gripper_depth" and s.meta["gripper_frame"] == (
        "base-shifted"
    )
    g = np.array([f.gripper for f in s.frames])
    np.testing.assert_allclose(g[0], [0, 0, 0.9], atol=1e-12)
    np.testing.assert_allclose(g - g[0], base - base[0], atol=1e-12)
    assert s.frames[1].action == -1 and s.target.action == -1
    assert s.meta["target_action"] == 1  # kept for the published variant
    assert not s.meta["has_depth"] and not s.frames[0].depth.any()
    assert s.meta["crop_origin"] is None
    del doc["focal_length"], doc["gripper_depth"]
    (seq / "actions_gripper.json").write_text(json.dumps(doc))
    s = read_mcor(seq).stream
    assert s.intrinsics.fx == 644.3 and s.meta["gripper_depth"] == 1.1


def test_bad_sequences_are_named(tmp_path, moving_stream):
    with pytest.raises(RecordingError, match="not found"):
        read_mcor(tmp_path / "none")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordingError, match="actions_gripper.json"):
        read_mcor(tmp_path / "empty")
    seq = write_mcor(tmp_path / NAME, moving_stream)
    with pytest.raises(RecordingError, match="exists"):
        write_mcor(seq, moving_stream)
    (seq / f"rgb_{len(moving_stream) - 1:08d}.png").unlink()
    with pytest.raises(RecordingError, match="images"):
        read_mcor(seq)
    write_mcor(seq, moving_stream, overwrite=True)
    doc = json.loads((seq / "actions_gripper.json").read_text())
    for key, value, match in [
        ("camera_matrix", [[1, 0], [0, 1]], "camera_matrix"),
        ("ee_point_buffer", [[0, 0]] * len(moving_stream), "ee_point_buffer"),
        ("action_buffer", [0.5] * len(moving_stream), "integers"),
        ("scale_factor", -1, "scale_factor"),
    ]:
        bad = dict(doc, **{key: value})
        (seq / "actions_gripper.json").write_text(json.dumps(bad))
        with pytest.raises(RecordingError, match=match):
            read_mcor(seq)
    (seq / "actions_gripper.json").write_text("{not json")
    with pytest.raises(RecordingError, match="JSON"):
        read_mcor(seq)
    with pytest.raises(InputError, match="crop"):
        write_mcor(tmp_path / "x", moving_stream, crop_origin=(0, 0))
    with pytest.raises(InputError, match="split"):
        write_annotation(tmp_path, "train", NAME, 3, np.zeros((2, 2), bool))


def test_annotations_roots(tmp_path):
    seq = tmp_path / "buffers" / NAME
    seq.mkdir(parents=True)
    for i in range(3):
        cv2.imwrite(str(seq / f"rgb_{i:08d}.png"), np.zeros((4, 4, 3), np.uint8))
    assert find_annotation(seq) is None
    m = np.eye(4, dtype=bool)
    other = write_annotation(tmp_path / "gt", "test", NAME, 7, m)  # not the last index
    assert find_annotation(seq, tmp_path / "gt") == other  # the first cable mask, as published
    last = write_annotation(tmp_path / "gt", "test", NAME, 2, m)
    assert find_annotation(seq, tmp_path / "gt") == last
    with pytest.raises(RecordingError, match="annotations root"):
        find_annotation(seq, tmp_path / "nowhere")
    assert sequence_name(__import__("datetime").datetime(2024, 8, 6, 15, 30, 12)) == NAME


def test_multigrasp_lists_and_retarget(tmp_path, moving_stream):
    groups = [["2024-10-30-161137", "2024-10-30-161441"], ["2025-03-20-142304"]]
    path = write_multigrasp(tmp_path / "multigrasp_sequences.json", groups)
    assert read_multigrasp(path) == groups
    assert multigrasp_name(groups[0]) == "2024-10-30-161-137-441"
    path.write_text(json.dumps([["a"], "b"]))
    with pytest.raises(RecordingError, match="list"):
        read_multigrasp(path)
    later = moving_stream.frames[3]
    s = retarget(moving_stream, later, target_action=1)
    assert len(s) == len(moving_stream) + 1 and s.frames[-1] is later
    assert s.meta["target_action"] == 1 and s.frames[-2].action == -1
