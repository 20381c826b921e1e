"""Metrics against hand-worked cases; vote merging; threshold tuning."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception import (
    CorrelationParams,
    VoteAccumulator,
    compute_statistics,
    confusion,
    f_beta,
    flow_epe,
    grade_proposal,
    intersection,
    mean_scores,
    merge_votes,
    score_mask,
    segment_from_statistics,
    tune_thresholds,
    tuning_table,
    union,
    vote_image,
)
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream


def test_hand_worked_scores():
    truth = np.zeros((4, 4), bool)
    truth[0, :] = True  # 4 pixels
    pred = np.zeros((4, 4), bool)
    pred[0, :2] = True  # 2 TP
    pred[1, :1] = True  # 1 FP
    assert confusion(pred, truth) == (2, 1, 2)
    s = score_mask(pred, truth)
    assert s.precision == pytest.approx(2 / 3)
    assert s.recall == pytest.approx(0.5)
    assert s.iou == pytest.approx(2 / 5)
    # F1 = 2PR/(P+R) = 2*(1/3)/(7/6) = 4/7
    assert s.f[1.0] == pytest.approx(4 / 7)
    # F_0.5 = 1.25 * (1/3) / (0.25*2/3 + 0.5) = (5/12) / (2/3) = 0.625
    assert s.f[0.5] == pytest.approx(0.625)
    assert f_beta(0.0, 0.0, 0.4) == 0.0
    # as published: an empty prediction has no precision; F and IoU are 0 (the truth is missed)
    empty = score_mask(np.zeros((4, 4), bool), truth)
    assert np.isnan(empty.precision)
    assert (empty.recall, empty.iou, empty.f[0.4], empty.f[0.1]) == (0, 0, 0, 0)
    # nothing predicted and nothing to find: every score is undefined
    nothing = score_mask(np.zeros((4, 4), bool), np.zeros((4, 4), bool))
    assert all(
        np.isnan(v) for v in (nothing.precision, nothing.recall, nothing.iou, nothing.f[1.0])
    )
    m = mean_scores([s, empty, nothing])
    assert m.precision == pytest.approx(2 / 3)  # the empty predictions are left out
    assert m.recall == pytest.approx(0.25)
    assert m.f[0.5] == pytest.approx(0.625 / 2)
    with pytest.raises(InputError):
        f_beta(0.5, 0.5, 0.0)
    with pytest.raises(InputError, match="size"):
        score_mask(np.zeros((3, 4), bool), truth)
    with pytest.raises(InputError, match="bool or integer"):
        score_mask(np.zeros((4, 4), np.float32), truth)


def test_flow_epe_on_moving_pixels():
    truth = np.zeros((2, 2, 2), np.float32)
    truth[0, 0] = (3, 4)
    est = np.zeros_like(truth)
    est[0, 0] = (3, 1)  # error 3
    est[1, 1] = (10, 0)  # static pixel: not counted
    assert flow_epe(est, truth) == pytest.approx(3.0)
    assert np.isnan(flow_epe(est, np.zeros_like(truth)))


def test_grade_proposal():
    labels = np.full((4, 4), -1, np.int16)
    labels[0] = 2
    labels[1] = 1
    m = np.zeros((4, 4), bool)
    m[0] = True
    assert grade_proposal(m, labels, 2, True) == "correct_reachable"
    assert grade_proposal(m, labels, 2, False) == "correct_unreachable"
    assert grade_proposal(m, labels, 1, True) == "wrong_hose"
    bg = np.zeros((4, 4), bool)
    bg[3] = True
    assert grade_proposal(bg, labels, 2, True) == "background"
    with pytest.raises(InputError, match="empty"):
        grade_proposal(np.zeros((4, 4), bool), labels, 2, True)


def test_vote_merging():
    a = np.array([[1, 1, 0, 0]], bool)
    b = np.array([[1, 0, 1, 0]], bool)
    c = np.array([[1, 0, 0, 0]], bool)
    v = vote_image([a, b, c])
    assert v.tolist() == [[3, 1, 1, 0]]
    assert union([a, b, c]).tolist() == [[True, True, True, False]]
    assert intersection([a, b, c]).tolist() == [[True, False, False, False]]
    assert merge_votes(v, 2).tolist() == [[True, False, False, False]]
    acc = VoteAccumulator((1, 4))
    acc.add([a, b])  # grasp 1: two actions
    acc.add([c])  # grasp 2
    assert acc.votes.tolist() == [[3, 1, 1, 0]] and acc.n_actions == 3 and acc.n_grasps == 2
    assert acc.mask("intersection").sum() == 1
    with pytest.raises(InputError, match="action threshold"):
        merge_votes(v, 0)
    with pytest.raises(InputError, match="size"):
        vote_image([a, np.zeros((2, 2), bool)])


@pytest.fixture(scope="module")
def validation():
    """Three small sequences with truth masks and cached statistics."""
    out = []
    for seed in range(3):
        regions = [
            Region((4, 14, 4, 40), "linear", 0.5 + 0.2 * seed, label=0),
            Region((20, 30, 4, 40), "random", 0.8, label=1),
            Region((34, 44, 10, 40), "lag", 0.6, label=2),
        ]
        s = synthetic_stream(regions, SyntheticSpec(seed=seed, samples_per_period=8))
        stats = compute_statistics(s, "oracle", pipelined=False)
        out.append((stats, s.target.truth.labels == 0))
    return out


def test_tuning_finds_perfect_thresholds(validation):
    stats = [v[0] for v in validation]
    truths = [v[1] for v in validation]
    res = tune_thresholds(
        stats,
        truths,
        "correlation",
        betas=(1.0, 0.4),
        grid={"c0_min": np.array([0.0, 0.1, 0.3]), "r2_min": np.array([0.0, 0.5, 0.9])},
    )
    row = res.rows[0.4]
    assert row.f_beta == pytest.approx(1.0)
    assert row.params["r2_min"] >= 0.5
    # the tuned thresholds reproduce the score when applied
    p = res.params(0.4)
    assert isinstance(p, CorrelationParams)
    scores = [
        score_mask(segment_from_statistics(s, "correlation", p).mask(1), t)
        for s, t in zip(stats, truths, strict=True)
    ]
    assert mean_scores(scores).f[0.4] == pytest.approx(row.f_beta)
    seg = tune_thresholds(stats, truths, "segmentation", betas=(0.4,))
    assert seg.rows[0.4].precision < 1.0  # the baseline also takes the random region
    abl = tune_thresholds(stats, truths, "ablation", betas=(0.4,))
    table = tuning_table([res, seg, abl])
    assert table.count("\n") == 2 + 4
    assert "| correlation | 1 | 0.4 |" in table


def test_tuning_matches_brute_force(validation):
    stats = [v[0] for v in validation]
    truths = [v[1] for v in validation]
    taus = np.array([0.1, 0.3, 0.5, 0.7])
    res = tune_thresholds(stats, truths, "segmentation", betas=(1.0,), n=2, grid={"tau_v": taus})
    best = -1.0
    for t in taus:
        f = np.mean(
            [
                score_mask(
                    merge_votes(vote_image([s.segmentation[a].mask(t) for a in s.actions]), 2), m
                ).f[1.0]
                for s, m in zip(stats, truths, strict=True)
            ]
        )
        best = max(best, f)
    assert res.rows[1.0].f_beta == pytest.approx(best)
    with pytest.raises(InputError, match="truths"):
        tune_thresholds(stats, truths[:1], "segmentation")


@pytest.mark.parametrize("method", ["correlation", "segmentation", "ablation"])
def test_counts_tune_as_tune_thresholds(validation, method):
    """Counts per sequence (what parallel jobs store) tune and score exactly as
    :func:`tune_thresholds` on the statistics, also after a JSON round trip."""
    from cablesim.perception.tuning import ThresholdCounts, threshold_counts, tune_counts

    stats = [v[0] for v in validation]
    truths = [v[1] for v in validation]
    for n in (1, 2):
        ref = tune_thresholds(stats, truths, method, betas=(1.0, 0.4), n=n)
        counts = [
            ThresholdCounts.from_dict(threshold_counts(s, t, method, n).to_dict())
            for s, t in zip(stats, truths, strict=True)
        ]
        for beta in (1.0, 0.4):
            i, j, f = tune_counts(counts, beta)
            assert counts[0].params(i, j) == ref.rows[beta].params
            assert f == pytest.approx(ref.rows[beta].f_beta)
            p = np.nanmean([c.scores(beta)[0][i, j] for c in counts])
            assert p == pytest.approx(ref.rows[beta].precision)
