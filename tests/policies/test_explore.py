"""A tiny headless exploration end to end (CLI), the perturbation hook and vote merging."""

from __future__ import annotations

import json

import numpy as np
import pytest

import cablesim  # noqa: F401  (selects the headless GL back end before mujoco)
from cablesim.cli import main
from cablesim.policies import ExploreConfig, PerturbConfig, VoteMerger, warp_votes
from cablesim.policies.report import count_video_frames

TINY = ["--seed", "2", "--hose", "1", "--hoses", "3", "--width", "160", "--height", "120"]
TINY += ["--periods", "1", "--flow", "oracle", "--perturb"]


@pytest.mark.slow
def test_cli_explore_tiny(tmp_path, capsys):
    out = tmp_path / "ex"
    assert main(["explore", *TINY, "--grasps", "2", "--out", str(out), "--quiet", "--record"]) == 0
    printed = capsys.readouterr().out
    assert "F0.4" in printed and "merged" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    ok = [i for i in metrics["interactions"] if i["success"]]
    assert ok, metrics["interactions"]
    for i in ok:
        s = i["scores"]
        for k in ("precision", "recall", "f0.4", "iou"):
            assert 0.0 <= s[k] <= 1.0
        assert s["precision"] > 0.5  # oracle flow: the grasped hose, not its neighbours
    assert metrics["merged"]["f0.4"] > 0.3
    assert metrics["perturbations"], "the neighbours were not perturbed"
    grades = metrics["proposal_grades"]
    assert set(grades) <= {"correct_reachable", "correct_unreachable", "wrong_hose", "background"}
    executed = sum(1 for i in metrics["interactions"] if i["source"] != "start")
    assert sum(grades.values()) >= executed
    for name in ("start.png", "interaction0_votes.png", "interaction0_flow.png", "merged.png"):
        assert (out / name).stat().st_size > 0, name
    # every interaction recorded as it happened, in cablesim's format and the published layout
    from cablesim.formats.mcor import read_mcor, read_multigrasp
    from cablesim.recording import Recording

    for i in metrics["interactions"]:
        rec = Recording(out / "recordings" / f"interaction{i['index']}")
        assert rec.complete == i["success"]
        if i["success"]:
            seq = read_mcor(out / "recordings" / "mcor" / f"interaction{i['index']}")
            assert len(seq.stream) == len(rec)
            np.testing.assert_allclose(
                [f.gripper for f in seq.stream.frames], [f.gripper for f in rec], atol=1e-6
            )
    groups = read_multigrasp(out / "recordings" / "mcor" / "multigrasp_sequences.json")
    assert groups == [[f"interaction{i['index']}" for i in ok]]
    video = out / "episode.mp4"
    if video.exists():
        assert count_video_frames(video) > 10
    else:
        assert (out / "episode.gif").stat().st_size > 0


def test_config_roundtrip_and_validation():
    cfg = ExploreConfig.of(
        seed=3, strategy="random", perturb=PerturbConfig(enabled=True, hoses=(1,))
    )
    again = ExploreConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg
    assert cfg.seed == cfg.episode.seed == 3 and cfg.episode.perturb.hoses == (1,)
    push = ExploreConfig.of(strategy="push")  # sets the interaction kind it runs
    assert push.resolved_method == "segmentation" and push.episode.interaction.kind == "push"
    from cablesim.errors import ConfigError

    with pytest.raises(ConfigError, match="strategy"):
        ExploreConfig(strategy="nope")
    with pytest.raises(ConfigError) as err:  # strategy and interaction kind must agree
        ExploreConfig(strategy="push")
    assert err.value.field == "episode.interaction.kind"


def test_explore_labels_every_eighth_frame_unless_its_flow_reads_ground_truth():
    from cablesim.errors import ConfigError

    assert ExploreConfig().episode.interaction.capture.truth_every == 8
    assert ExploreConfig.of(flow="dis").episode.interaction.capture.truth_every == 8
    # the oracle reads every frame's ground-truth flow: setting it labels every frame
    assert ExploreConfig.of(flow="oracle").episode.interaction.capture.truth_every == 1
    every = "episode.interaction.capture.truth_every"
    with pytest.raises(ConfigError) as err:  # unless told otherwise, which cannot work
        ExploreConfig().with_values({"flow": "oracle", every: 4})
    assert err.value.field == every and "oracle" in str(err.value)
    # a file of an earlier cablesim (no truth_every) reruns as it ran: every frame labelled
    doc = ExploreConfig().to_dict()
    del doc["episode"]["interaction"]["capture"]["truth_every"]
    assert ExploreConfig.from_dict(doc).episode.interaction.capture.truth_every == 1


def test_warp_votes_follows_flow():
    votes = np.zeros((20, 30), np.int16)
    votes[5:8, 10:12] = 2
    flow = np.zeros((20, 30, 2), np.float32)
    flow[..., 0] = 3.0  # new(p) shows previous(p + 3 px in x): content moved 3 px left
    warped = warp_votes(votes, flow)
    assert warped[5:8, 7:9].tolist() == [[2, 2]] * 3
    assert warped.sum() == votes.sum()
    m = VoteMerger(flow=lambda new, prev: flow)
    rgb = np.zeros((20, 30, 3), np.uint8)
    m.add(rgb, votes)
    m.add(rgb, votes)
    assert m.votes[6, 7] == 2 and m.votes[6, 10] == 2 and m.mask(2).sum() == 6 + 6
