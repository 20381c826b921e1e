"""What an exploration writes for a person: titled pictures, TP/FP/FN overlays, a flow key,
colour bars, an H.264 video, vote arrays that ``cablesim view`` turns into an .rrd.

Runs the real writer on a real segmentation of a synthetic stream (oracle flow), no simulator.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cablesim.cli import main
from cablesim.evaluation import scores_dict
from cablesim.perception.flow import make_flow
from cablesim.perception.pipeline import segment_stream
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.policies import ExploreConfig
from cablesim.policies.explore import ExplorationResult, Interaction
from cablesim.policies.report import ExplorationWriter
from cablesim.recording import write_stream
from cablesim.video import count_video_frames, video_codec


def _exploration(tmp_path):
    spec = SyntheticSpec(height=120, width=160, periods=1, samples_per_period=8, seed=1)
    stream = synthetic_stream(
        [Region((40, 60, 20, 140), label=0), Region((80, 100, 20, 140), kind="random", label=1)],
        spec,
    )
    seg = segment_stream(stream, method="correlation", flow="oracle", pipelined=False)
    truth = stream.target.truth.labels == 0
    target = stream.target
    segment = np.zeros_like(truth)
    segment[45:55, 60:80] = True
    inter = Interaction(
        index=0,
        success=True,
        source="start",
        segment=segment,
        seg=seg,
        target_rgb=target.rgb,
        target_depth=target.depth,
        truth=truth,
        scores=scores_dict(seg.mask(1), truth),
        merged=scores_dict(seg.votes >= 1, truth),
    )
    cfg = ExploreConfig.of(seed=0, flow="oracle")
    res = ExplorationResult(
        config=cfg, hose=0, start_rgb=target.rgb, start_segment=segment, interactions=[inter]
    )
    res.merged_votes, res.final_rgb, res.final_truth = seg.votes, target.rgb, truth
    out = tmp_path / "run"
    writer = ExplorationWriter(out, cfg)
    writer.start(target.rgb, segment)
    writer.interaction(inter, stream, seg.votes, make_flow("oracle"))
    writer.finish(res)
    writer.close()
    return out, stream, seg, truth


def test_pictures_video_and_votes(tmp_path):
    out, stream, seg, truth = _exploration(tmp_path)
    metrics = json.loads((out / "metrics.json").read_text())
    expected = {
        "start.png",
        "interaction0_votes.png",
        "interaction0_votes.npy",
        "interaction0_errors.png",
        "interaction0_flow.png",
        "interaction0_maps.png",
        "merged.png",
        "merged_votes.npy",
        "merged_errors.png",
        "episode.mp4",
    }
    assert set(metrics["files"]) == expected
    for name in expected:
        assert (out / name).stat().st_size > 0, name
    # every picture has a white title strip above 120-pixel-high tiles
    for name in sorted(n for n in expected if n.endswith(".png")):
        img = cv2.imread(str(out / name))
        assert img.shape[0] > 120 + 10, name
        assert (img[:3] == 255).all(), name  # the strip starts white ...
        assert (img[: img.shape[0] - 120] < 60).any(), name  # ... and has dark text
    # the flow picture carries its key, the maps their colour bars: wider than bare tiles
    assert cv2.imread(str(out / "interaction0_flow.png")).shape[1] > 2 * 160 + 40
    assert cv2.imread(str(out / "interaction0_maps.png")).shape[1] > 4 * 160 + 4 * 30
    # the error overlay: TP green, FP red, FN blue, where the mask and the truth say
    errors = cv2.imread(str(out / "interaction0_errors.png"))[..., ::-1]
    tile = errors[errors.shape[0] - 120 :, :160]
    pred = seg.mask(1)
    assert (tile[pred & truth] == (0, 220, 0)).all()
    assert (tile[pred & ~truth] == (235, 30, 30)).all()
    assert (tile[~pred & truth] == (40, 110, 255)).all()
    assert np.array_equal(np.load(out / "interaction0_votes.npy"), seg.votes)
    assert video_codec(out / "episode.mp4") == "avc1"
    n_frames = 8 + sum(1 for f in stream.frames if not f.is_target) + 10 + 10
    assert count_video_frames(out / "episode.mp4") == n_frames


def test_run_folder_to_rrd(tmp_path):
    pytest.importorskip("rerun", reason="rerun-sdk is in the dev and viewer extras")
    from rerun.chunk import RrdReader

    out, stream, seg, _ = _exploration(tmp_path)
    write_stream(stream, out / "recordings" / "interaction0")
    assert main(["view", str(out)]) == 0
    entities = {c.entity_path for c in RrdReader(out / "view.rrd").stream().to_chunks()}
    for e in ("rgb", "depth", "labels", "votes", "merged_votes"):
        assert f"/world/camera/image/{e}" in entities, e
    assert {"/world/camera", "/world/camera/image", "/world/camera/gripper"} <= entities
    assert "/world/camera/gripper_path/interaction0" in entities
    assert "/pictures/interaction0_errors" in entities
