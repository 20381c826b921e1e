"""``cablesim benchmark thesis``: its config and jobs, and the aggregation from per-scene files
(tuned on validation, scored on test, the thesis's numbers beside ours)."""

from __future__ import annotations

import numpy as np
import pytest

from cablesim.cli import main
from cablesim.errors import ConfigError
from cablesim.perception.metrics import mean_scores, score_mask
from cablesim.perception.pipeline import compute_statistics, segment_from_statistics
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.perception.tuning import threshold_counts, tune_thresholds
from cablesim.thesis import explore_thresholds
from cablesim.thesis import report as rp
from cablesim.thesis.config import SceneSize, ThesisConfig


def test_config_refuses_overlapping_splits_and_unknown_settings():
    with pytest.raises(ConfigError, match="overlap"):
        ThesisConfig(validation=(0, 10), test=(5, 20))
    with pytest.raises(ConfigError, match="overlap"):
        ThesisConfig(clip_validation=(0, 10), clip_test=(9, 20))
    with pytest.raises(ConfigError, match="flow"):
        ThesisConfig(flows=("magic",))
    with pytest.raises(ConfigError, match="action_thresholds"):
        ThesisConfig(action_thresholds=(3,))
    with pytest.raises(ConfigError, match="validation"):
        ThesisConfig(validation=(5, 5))
    with pytest.raises(ConfigError, match="explore_flow"):
        ThesisConfig(flows=("oracle",), explore_flow="dis")
    with pytest.raises(ConfigError) as err:
        ThesisConfig().with_values({"scene.width": 0})
    assert err.value.field == "scene.width"
    assert main(["benchmark", "thesis", "--validation", "0:10", "--test", "5:20"]) == 2


def test_jobs_cover_every_scene_and_setting_once():
    cfg = ThesisConfig(validation=(10, 13), test=(20, 25))
    jobs = cfg.interaction_jobs()
    assert len(jobs) == (3 + 5) * 2 and len({j.key for j in jobs}) == len(jobs)
    assert {j.params["split"] for j in jobs if j.params["seed"] < 20} == {"validation"}
    # a changed setting is a new job (its result file is not reused); the same one is not
    other = ThesisConfig(validation=(10, 13), test=(20, 25), scene=SceneSize(width=320))
    assert not {j.key for j in jobs} & {j.key for j in other.interaction_jobs()}
    fewer = ThesisConfig(validation=(10, 13), test=(20, 25), perturb=(True,))
    assert {j.key for j in fewer.interaction_jobs()} < {j.key for j in jobs}
    assert len(cfg.exploration_jobs(0.2, 0.8)) == 5
    assert len(cfg.clip_jobs()) == 20 + 50
    assert explore_thresholds(cfg, [])[:2] == (0.18, 0.86)  # nothing tuned yet


def _sequence(seed: int):
    regions = [
        Region((4, 14, 4, 40), "linear", 0.5 + 0.2 * (seed % 3), label=0),
        Region((20, 30, 4, 40), "random", 0.8, label=1),
        Region((34, 44, 10, 40), "lag", 0.6, label=2),
    ]
    s = synthetic_stream(regions, SyntheticSpec(seed=seed, samples_per_period=8))
    stats = compute_statistics(s, "oracle", pipelined=False)
    return stats, s.target.truth.labels == 0


def _record(seed: int, split: str, stats, truth) -> dict:
    counts = {
        m: {str(n): threshold_counts(stats, truth, m, n).to_dict() for n in (1, 2)}
        for m in ("segmentation", "ablation", "correlation")
    }
    return {
        "key": f"s{seed}",
        "status": "ok",
        "outcome": "ok",
        "params": {"seed": seed, "split": split, "perturb": True},
        "result": {"flows": {"oracle": {"counts": counts}}},
    }


def test_tuned_on_validation_scored_on_test():
    val = [_sequence(s) for s in range(3)]
    test = [_sequence(s) for s in range(10, 14)]
    records = [_record(i, "validation", *v) for i, v in enumerate(val)]
    records += [_record(10 + i, "test", *t) for i, t in enumerate(test)]
    records.append({"key": "x", "status": "failed", "outcome": "close", "params": {}, "result": {}})
    rows = rp.segmentation_rows(records, ["oracle"], [True], [1.0, 0.4])
    assert len(rows) == 2 * 3 * 2  # n x methods x betas
    for row in rows:
        ref = tune_thresholds(
            [v[0] for v in val], [v[1] for v in val], row["method"], (row["beta"],), row["n"]
        )
        assert row["params"] == ref.rows[row["beta"]].params
        assert row["validation_scenes"] == 3 and row["test_scenes"] == 4
        if row["n"] == 1:  # the test means are the scores of the tuned masks on test
            p = ref.params(row["beta"])
            s = mean_scores(
                score_mask(segment_from_statistics(st, row["method"], p).mask(1), t)
                for st, t in test
            )
            assert row["precision"] == pytest.approx(s.precision)
            assert row["f"] == pytest.approx(s.f[row["beta"]])
            assert len(row["per_scene"]["f"]) == 4
    md = "\n".join(rp.segmentation_markdown(rows))
    assert "Table 6.4" in md and "Table 6.5" in md
    assert "| Motion correlation | 0.4 |" in md and "0.7488" in md and "0.9449" in md
    cfg = ThesisConfig(flows=("oracle",), explore_flow="oracle", perturb=(True,))
    c0, r2, where = explore_thresholds(cfg, rows)
    tuned = [r for r in rows if (r["method"], r["beta"], r["n"]) == ("correlation", 0.4, 1)][0]
    assert (c0, r2) == (tuned["params"]["c0_min"], tuned["params"]["r2_min"]) and "tuned" in where


def _scores(p: float | None, r: float) -> dict:
    return {"precision": p, "recall": r, "iou": r / 2, "f0.4": r}


def test_grasp_and_clip_tables():
    explorations = [
        {
            "status": "ok",
            "result": {
                "proposal_grades": {"correct_reachable": 1, "correct_unreachable": 2},
                "one_grasp": {"1": _scores(0.8, 0.4), "2": _scores(None, 0.0)},
                "two_grasps": {str(n): _scores(0.9, 0.6 / n) for n in range(1, 5)},
            },
        },
        {"status": "failed", "result": {"proposal_grades": {"wrong_hose": 1}}},
    ]
    t = rp.grasp_tables(explorations)
    assert t["grades"] == {"correct_reachable": 1, "correct_unreachable": 2, "wrong_hose": 1}
    assert t["rows"]["1@1"]["precision"] == pytest.approx(0.8)
    assert np.isnan(t["rows"]["1@2"]["precision"])  # an empty prediction: undefined
    assert t["rows"]["2@3"]["recall"] == pytest.approx(0.2)
    md = "\n".join(rp.grasp_markdown(t))
    assert "| correct reachable | 1 | 25 | 20 | 37 |" in md and "0.8838" in md

    def clip(split: str, iou: dict) -> dict:
        taus = {k: {"recall": [0.5], "precision": [0.5], "iou": [v]} for k, v in iou.items()}
        return {
            "status": "ok",
            "params": {"split": split},
            "result": {"flows": {"dis": {"taus": taus, "epe": [0.5, 1.5]}}},
        }

    clips = [clip("validation", {"1": 0.2, "2": 0.6}), clip("test", {"1": 0.9, "2": 0.3})]
    c = rp.clip_table(clips, ["dis"])
    assert c["dis"]["tau"] == 2.0 and c["dis"]["iou"] == pytest.approx(0.3)
    assert c["dis"]["epe"] == pytest.approx(1.0)
    assert "MfnProb FT" in "\n".join(rp.clip_markdown(c))


def test_command_line_config_is_json_with_its_out_folder(tmp_path):
    """``--out`` comes through the command line's path type; the config stays JSON."""
    import json as _json

    from cablesim.cli import build_parser
    from cablesim.commands.benchmark import config_from_args

    out = tmp_path / "bench"
    args = build_parser().parse_args(["benchmark", "thesis", "--out", str(out)])
    cfg = config_from_args(args)
    assert cfg.out == str(out)
    assert _json.loads(_json.dumps(cfg.to_dict()))["out"] == str(out)
