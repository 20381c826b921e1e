"""``cablesim segment`` on a published-layout sequence, a cablesim recording and a RealSense
recording with a gripper log."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cablesim.cli import main
from cablesim.formats.gripper_log import write_gripper_log
from cablesim.formats.mcor import write_annotation, write_mcor
from cablesim.recording import write_stream

OUTPUTS = ("votes.png", "votes.npy", "mask_union.png", "mask_intersection.png", "overlay.png")


def test_segment_a_published_layout_sequence(tmp_path, moving_stream, capsys):
    seq = tmp_path / "motion_correlation_buffers" / "2024-08-06-153012"
    write_mcor(seq, moving_stream, crop_origin=(4, 4), crop_size=(88, 64), scale_factor=1.5)
    truth = moving_stream.target.truth.labels == 0
    ann = tmp_path / "motion_correlation_annotations"
    write_annotation(ann, "test", seq.name, len(moving_stream) - 1, truth)
    out = tmp_path / "out"
    assert main(["segment", str(seq), "--out", str(out), "--method", "published"]) == 0
    assert "union: P" in capsys.readouterr().out
    for name in (*OUTPUTS, "mask_action0.png", "mask_action1.png", "maps.png", "scores.json"):
        assert (out / name).stat().st_size > 0, name
    scores = json.loads((out / "scores.json").read_text())
    assert scores["counted_in"] == "crop" and scores["crop"] == [4, 4, 88, 64]
    u = scores["union"]
    assert u["precision"] > 0.6 and u["recall"] > 0.6
    assert set(u) >= {"f1", "f0.5", "f0.4", "f0.3", "f0.2", "f0.1", "iou"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["layout"] == "mcor" and summary["flow"]["region"]["scale_factor"] == 1.5
    assert summary["published"]["r2_pct"] == 86
    votes = np.load(out / "votes.npy")
    assert np.array_equal(votes >= 1, cv2.imread(str(out / "mask_union.png"), 0) > 0)
    # without ground-truth flow the oracle is refused before any work, naming why
    assert main(["segment", str(seq), "--out", str(out), "--flow", "oracle"]) == 2
    assert "ground-truth flow" in capsys.readouterr().err


def test_segment_a_cablesim_recording(tmp_path, moving_stream):
    rec = write_stream(moving_stream, tmp_path / "rec")
    out = tmp_path / "out"
    argv = ["segment", str(rec), "--out", str(out), "--flow", "oracle", "--quiet"]
    assert main(argv + ["--method", "correlation", "--beta", "0.3"]) == 0
    scores = json.loads((out / "scores.json").read_text())
    assert scores["counted_in"] == "image"
    assert scores["union"]["precision"] > 0.95 and scores["union"]["recall"] > 0.95
    summary = json.loads((out / "summary.json").read_text())
    assert summary["params"]["r2_min"] == pytest.approx(0.92) and summary["actions"] == [0, 1]
    assert main(argv + ["--method", "segmentation", "--out", str(tmp_path / "seg")]) == 0
    summary = json.loads((tmp_path / "seg" / "summary.json").read_text())
    assert summary["method"] == "segmentation" and summary["params"]["tau_v"] == 0.47
    assert not (tmp_path / "seg" / "maps.png").exists()  # no correlation maps to show


def test_segment_a_realsense_recording_with_a_gripper_log(tmp_path, moving_stream):
    pytest.importorskip("pyrealsense2", reason="the real extra (pyrealsense2) is not installed")
    from cablesim.camera.base import CameraImage
    from cablesim.camera.realsense import write_recording

    frames = moving_stream.frames
    images = [CameraImage(f.rgb, f.depth, 1.0 + f.timestamp, f.intrinsics) for f in frames]
    db3 = tmp_path / "session.db3"
    write_recording(db3, images)
    # the robot logs its own samples, a little off the camera's times
    log = write_gripper_log(
        tmp_path / "gripper.jsonl",
        [(1.0 + f.timestamp - 0.01, f.action, f.gripper) for f in frames[:-1]],
    )
    truth = tmp_path / "truth.png"
    cv2.imwrite(str(truth), (moving_stream.target.truth.labels == 0).astype(np.uint8) * 255)
    out = tmp_path / "out"
    argv = ["segment", str(db3), "--gripper-log", str(log), "--truth", str(truth)]
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["layout"] == "realsense" and summary["actions"] == [0, 1]
    assert sum(summary["kept_samples"].values()) >= len(frames) - 6
    scores = json.loads((out / "scores.json").read_text())
    assert scores["union"]["recall"] > 0.5
    assert main(["segment", str(db3), "--out", str(out)]) == 2  # no gripper log


def test_segment_with_colour_growth(tmp_path, moving_stream, capsys):
    """``--grow-colour`` grows the masks along the target's colour; the published methods
    refuse it, and a bad distance is one line naming it."""
    rec = write_stream(moving_stream, tmp_path / "rec")
    argv = ["segment", str(rec), "--flow", "oracle", "--quiet", "--method", "correlation"]
    assert main([*argv, "--out", str(tmp_path / "plain")]) == 0
    assert main([*argv, "--out", str(tmp_path / "grown"), "--grow-colour", "15"]) == 0
    plain = np.load(tmp_path / "plain" / "votes.npy") >= 1
    grown = np.load(tmp_path / "grown" / "votes.npy") >= 1
    assert (grown | plain).sum() == grown.sum() >= plain.sum()  # grown, nothing lost
    summary = json.loads((tmp_path / "grown" / "summary.json").read_text())
    assert summary["refine"]["grow"]["colour"] == 15.0
    pub = ["segment", str(rec), "--out", str(tmp_path / "p"), "--method", "published"]
    assert main([*pub, "--grow-colour", "15"]) == 2
    assert "--grow-colour applies to" in capsys.readouterr().err
    assert main([*argv, "--out", str(tmp_path / "bad"), "--grow-colour", "-1"]) == 2
    assert "colour > 0" in capsys.readouterr().err
