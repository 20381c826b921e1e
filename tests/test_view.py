"""``cablesim view``: a recording and a run folder become a rerun .rrd that reads back with the
camera, images, labels, votes and the gripper trajectory."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cablesim.cli import main
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.recording import write_stream

rerun = pytest.importorskip("rerun", reason="rerun-sdk is in the dev and viewer extras")
from rerun.chunk import RrdReader  # noqa: E402

T_WORLD_CAMERA = np.array(
    [[0.0, 0.0, 1.0, -0.4], [-1.0, 0.0, 0.0, 0.1], [0.0, -1.0, 0.0, 0.6], [0.0, 0.0, 0.0, 1.0]]
)


def _recording(path, seed: int = 0):
    spec = SyntheticSpec(height=30, width=40, periods=1, samples_per_period=4, seed=seed)
    stream = synthetic_stream([Region((5, 15, 10, 30), label=0)], spec)
    stream.meta["T_world_camera"] = T_WORLD_CAMERA.tolist()
    write_stream(stream, path)
    return stream


def _read(rrd) -> dict[str, dict]:
    """entity path -> {"rows": rows on the timelines, "static": static rows, "columns": set of
    component columns, "batches": [...]}"""
    out: dict[str, dict] = {}
    for chunk in RrdReader(rrd).stream().to_chunks():
        e = out.setdefault(
            chunk.entity_path, {"rows": 0, "static": 0, "columns": set(), "batches": []}
        )
        e["static" if chunk.is_static else "rows"] += chunk.num_rows
        batch = chunk.to_record_batch()
        e["columns"] |= set(batch.schema.names)
        e["batches"].append(batch)
    return out


def _column(entity: dict, name: str) -> list:
    values = []
    for b in entity["batches"]:
        if name in b.schema.names:
            values += b.column(name).to_pylist()
    return values


def test_recording_round_trip(tmp_path, capsys):
    stream = _recording(tmp_path / "rec")
    out = tmp_path / "rec.rrd"
    assert main(["view", str(tmp_path / "rec"), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    got = _read(out)
    n = len(stream.frames)
    for entity in ("rgb", "depth", "labels"):
        assert got[f"/world/camera/image/{entity}"]["rows"] == n, entity
    assert "Pinhole:image_from_camera" in got["/world/camera/image"]["columns"]
    assert _column(got["/world/camera/image"], "Pinhole:resolution") == [[[40.0, 30.0]]]
    translation = _column(got["/world/camera"], "Transform3D:translation")[0]
    assert np.allclose(np.ravel(translation), T_WORLD_CAMERA[:3, 3])
    # the gripper: one point per non-target frame, and the trajectory through all of them
    moving = [f.gripper for f in stream.frames if not f.is_target]
    points = [p for p in _column(got["/world/camera/gripper"], "Points3D:positions") if p]
    assert len(points) == len(moving)
    assert np.allclose(np.array([p[0] for p in points]), moving, atol=1e-6)
    strips = _column(got["/world/camera/gripper_path/rec"], "LineStrips3D:strips")
    assert np.allclose(np.asarray(strips[0][0]), moving, atol=1e-6)
    # depth as millimetres (1 m here), labels as class ids (hose 0 -> 2, background -> 0)
    depth = got["/world/camera/image/depth"]
    mm = np.frombuffer(bytes(_column(depth, "DepthImage:buffer")[0][0]), np.uint16)
    assert set(mm.tolist()) == {1000} and _column(depth, "DepthImage:meter")[0] == [1000.0]
    labels = got["/world/camera/image/labels"]
    ids = np.frombuffer(bytes(_column(labels, "SegmentationImage:buffer")[0][0]), np.uint16)
    truth = stream.frames[0].truth.labels.ravel()
    assert np.array_equal(ids == 2, truth == 0) and np.array_equal(ids == 0, truth < 0)


def test_run_folder_with_votes_metrics_and_pictures(tmp_path):
    run = tmp_path / "run"
    for k in range(2):
        _recording(run / "recordings" / f"interaction{k}", seed=k)
        votes = np.zeros((30, 40), np.int16)
        votes[5:15, 10:30] = 2
        np.save(run / f"interaction{k}_votes.npy", votes)
    np.save(run / "merged_votes.npy", np.full((30, 40), 3, np.int16))
    scores = {"precision": 0.9, "recall": 0.5, "f0.4": 0.8, "iou": 0.45}
    metrics = {"interactions": [{"index": k, "scores": scores, "merged": scores} for k in (0, 1)]}
    (run / "metrics.json").write_text(json.dumps(metrics))
    from cablesim.viz import panel, write_png

    write_png(run / "merged.png", panel([np.zeros((30, 40, 3), np.uint8)], ["merged"]))
    assert main(["view", str(run)]) == 0
    got = _read(run / "view.rrd")
    assert got["/world/camera/image/rgb"]["rows"] == 2 * 11  # 2 actions x 5 samples + target
    assert got["/world/camera/image/votes"]["rows"] == 2
    assert got["/world/camera/image/merged_votes"]["rows"] == 1
    assert {
        "/world/camera/gripper_path/interaction0",
        "/world/camera/gripper_path/interaction1",
    } <= set(got)
    assert got["/metrics/interaction/f0.4"]["rows"] == 2
    assert got["/pictures/merged"]["static"] == 1 and got["/metrics.json"]["static"] == 1
    # --stride keeps every n-th frame and each target frame
    assert main(["view", str(run), "--out", str(tmp_path / "s.rrd"), "--stride", "4"]) == 0
    assert _read(tmp_path / "s.rrd")["/world/camera/image/rgb"]["rows"] == 2 * 4  # 0 4 8 10


def test_bad_paths(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["view", str(tmp_path / "empty")]) == 2
    assert "neither a cablesim recording" in capsys.readouterr().err
    assert main(["view", str(tmp_path / "nothing")]) == 2
    _recording(tmp_path / "rec")
    assert main(["view", str(tmp_path / "rec"), "--out", str(tmp_path / "x.txt")]) == 2
    assert main(["view", str(tmp_path / "rec"), "--stride", "0"]) == 2
