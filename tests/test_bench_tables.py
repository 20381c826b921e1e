"""The tables two benchmarks compute, on hand-worked cases: the flow error by how far pixels
moved (``benchmarks.flow_by_motion``) and where an explore run's wall time went
(``benchmarks.bench_explore``), and the learned flow's per-clip table with the arm's share of
the view and its tables per cable kind (``benchmarks.learned_flow``), and how much motion a
back end reports on a real clip's moving cable (``benchmarks.real_clip_motion``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_explore import STAGES, stages
from benchmarks.flow_by_motion import Tally
from benchmarks.learned_flow import arm_shares, clip_kinds, clip_table, kind_table, score
from benchmarks.real_clip_motion import Motion, motion_on_truth, report
from cablesim.formats.movingcables import ClipFrame, write_clip
from cablesim.perception.flow import FlowEstimator


def _field(shape: tuple[int, int], u: np.ndarray) -> np.ndarray:
    f = np.zeros((*shape, 2), np.float32)
    f[..., 0] = u
    return f


def test_motion_bins_tell_missed_motion_from_tracked_motion() -> None:
    # 3 px in one column, 10 px in another, still elsewhere (still pixels are not scored)
    u = np.zeros((4, 4), np.float32)
    u[:, 0], u[:, 1] = 3.0, 10.0
    gt, known = _field(u.shape, u), np.ones(u.shape, bool)
    zero, exact, half = Tally(), Tally(), Tally()
    zero.add(gt, np.zeros_like(gt), known)
    exact.add(gt, gt.copy(), known)
    half.add(gt, gt * 0.6, known)  # error 0.4 |gt|: tracked, 60 % of the motion found
    rows = {r["bin"]: r for r in zero.rows()}
    assert rows["2-4 px"]["pixels"] == 4 and rows["8-16 px"]["pixels"] == 4
    assert rows["1-2 px"]["pixels"] == 0
    assert rows["2-4 px"]["epe"] == pytest.approx(3.0)  # a missed motion costs all of itself
    assert rows["8-16 px"]["epe"] == pytest.approx(10.0)
    assert rows["all > 1 px"]["epe"] == pytest.approx(6.5) == rows["all > 1 px"]["mean_true"]
    assert rows["all > 1 px"]["found"] == 0.0 and rows["all > 1 px"]["tracked"] == 0.0
    e = exact.rows()[-1]
    assert e["epe"] == 0.0 and e["found"] == pytest.approx(1.0) and e["tracked"] == 1.0
    h = half.rows()[-1]
    assert h["found"] == pytest.approx(0.6) and h["tracked"] == 1.0
    assert h["epe"] == pytest.approx(0.4 * 6.5)


def test_unknown_pixels_are_left_out_of_the_motion_bins() -> None:
    u = np.full((2, 2), 5.0, np.float32)
    gt = _field(u.shape, u)
    known = np.array([[True, False], [False, False]])
    t = Tally()
    t.add(gt, np.zeros_like(gt), known)
    assert t.rows()[-1]["pixels"] == 1


def test_explore_stages_add_up_to_the_wall_time(tmp_path: Path) -> None:
    doc = {
        "timings_s": {"build": 0.5, "start_segment": 0.1, "total": 10.0},
        "interactions": [
            {
                "timings_s": {
                    "episode": 7.0,
                    "episode_grasp": 1.0,
                    "episode_actions": 5.0,
                    "episode_retreat": 0.5,
                    "perception": 2.0,
                    "pictures_video": 0.3,
                }
            }
        ],
    }
    (tmp_path / "metrics.json").write_text(json.dumps(doc))
    s = stages(tmp_path / "metrics.json", wall=11.0)
    assert s is not None and tuple(s) == STAGES
    assert s["start, imports"] == pytest.approx(1.0)  # the process outside explore's clock
    assert s["interaction, other"] == pytest.approx(0.5)
    assert s["other"] == pytest.approx(11.0 - 1.0 - 0.5 - 0.1 - 7.0 - 2.0 - 0.3)
    assert sum(s.values()) == pytest.approx(11.0)
    assert stages(tmp_path / "missing.json", 1.0) is None


def test_the_per_clip_table_gives_each_clip_its_arm_share_and_errors(tmp_path: Path) -> None:
    split = tmp_path / "lf" / "test"
    rgb = np.zeros((4, 5, 3), np.uint8)
    flow = np.zeros((4, 5, 2), np.float32)
    inst = np.zeros((4, 5), np.uint16)
    for clip, covered in (("0001", 2), ("0002", 15)):
        frames = []
        for i, n in enumerate((0, covered)):  # the arm covers n of the 20 pixels
            stick = np.zeros(20, bool)
            stick[:n] = True
            frames.append(ClipFrame(2 * i + 1, rgb, flow, flow, inst, stick.reshape(4, 5)))
        write_clip(split, clip, frames)
    shares = arm_shares([split])
    assert shares == {"lf/test/0001": 0.1, "lf/test/0002": 0.75}
    per_clip = {
        "dis": {"lf/test/0001": {"epe_gt_gt1": 1.234}, "lf/test/0002": {"epe_gt_gt1": 36.6}},
        "raft": {"lf/test/0001": {"epe_gt_gt1": 0.5}, "lf/test/0002": {"epe_gt_gt1": 40.0}},
    }
    rows = clip_table(per_clip, shares)
    assert (
        rows[0] == "| clip | arm's largest share of the image | dis EPE > 1 px | raft EPE > 1 px |"
    )
    assert rows[2:] == [
        "| lf/test/0001 | 0.10 | 1.23 | 0.50 |",
        "| lf/test/0002 | 0.75 | 36.60 | 40.00 |",
    ]


class _Still(FlowEstimator):
    """No motion anywhere: the error is the true flow's length."""

    name = "still"

    def compute(self, image1: np.ndarray, image2: np.ndarray) -> np.ndarray:
        return np.zeros((*image1.shape[:2], 2), np.float32)


def test_clips_are_pooled_by_the_kind_of_the_cable_that_moves(tmp_path: Path) -> None:
    # three clips: two move a rope (2 px and 4 px on 4 pixels each), one a thin wire (6 px)
    split = tmp_path / "lf" / "test"
    rgb = np.zeros((4, 5, 3), np.uint8)
    inst = np.zeros((4, 5), np.uint16)
    no_stick = np.zeros((4, 5), bool)
    for clip, px, kind, seed in (
        ("0001", 2.0, "rope", 7),
        ("0002", 4.0, "rope", 8),
        ("0003", 6.0, "thin_wire", 9),
    ):
        moved = np.zeros((4, 5, 2), np.float32)
        moved[0, :4, 0] = px
        still = np.zeros_like(moved)
        frames = [
            ClipFrame(1, rgb, still, still, inst, no_stick),
            ClipFrame(3, rgb, moved, moved, inst, no_stick),
        ]
        write_clip(split, clip, frames)
        jobs = tmp_path / "lf" / "jobs"
        jobs.mkdir(exist_ok=True)
        record = {
            "status": "ok",
            "params": {"seed": seed, "scene": {"cable": kind}, "randomize": {}},
            "result": {"hose": 1},
        }
        (jobs / f"movingcables-test-{clip}-s{seed}.json").write_text(json.dumps(record))
    kinds = clip_kinds([split])
    assert kinds == {"lf/test/0001": "rope", "lf/test/0002": "rope", "lf/test/0003": "thin_wire"}
    per_kind: dict = {}
    out = score([split], _Still(), "normal_flow", kinds=kinds, per_kind=per_kind)
    assert per_kind["rope"]["epe_gt_gt1"] == pytest.approx(3.0)  # (4 * 2 + 4 * 4) / 8
    assert per_kind["thin_wire"]["epe_gt_gt1"] == pytest.approx(6.0)
    assert out["all"]["epe_gt_gt1"] == pytest.approx(4.0)
    assert per_kind["rope"]["images"] == 2 and per_kind["thin_wire"]["images"] == 1
    rows = kind_table({"still": per_kind}, kinds)
    assert rows[2].startswith("| rope | 2 | still | 0.000 |") and rows[2].endswith("| 3.00 | 2 |")
    assert rows[3].startswith("| thin_wire | 1 | still |")
    # a clip without its job record: no kinds rather than a wrong one
    next((tmp_path / "lf" / "jobs").glob("*-0003-*")).unlink()
    assert clip_kinds([split]) is None


def test_motion_on_the_true_pixels_leaves_out_the_stick_and_still_frames() -> None:
    # 3 frames of 2x3 px: frame 0 has no true moving pixel (skipped); in frame 1 the truth is
    # the top row, |flow| 0.5, 2, 4 there, and the stick covers its last pixel; in frame 2 the
    # truth is every pixel, |flow| 0 on the top row and 3 below
    mags = np.zeros((3, 2, 3), np.float32)
    mags[1, 0] = (0.5, 2.0, 4.0)
    mags[2, 1] = 3.0
    truth = np.zeros((3, 2, 3), bool)
    truth[1, 0] = True
    truth[2] = True
    stick = np.zeros((3, 2, 3), bool)
    stick[1, 0, 2] = True
    mo = motion_on_truth(mags, truth, stick)
    assert mo.frames == (1, 2)
    assert mo.median == (1.25, 1.5)  # of (0.5, 2) and of (0, 0, 0, 3, 3, 3)
    assert mo.found == (0.5, 0.5)
    assert mo.summary() == (1.375, 0.5)
    # without the stick frame 1 keeps its 4 px pixel
    assert motion_on_truth(mags, truth).median == (2.0, 1.5)
    table = report(
        {"dis": {"0003": mo}, "raft": {"0003": Motion((1,), (0.6875,), (0.25,))}}, ["0003"]
    )
    rows = [r for r in table.splitlines() if r.startswith("| `")]
    assert rows == [
        "| `dis` | 0003 | 2 | 1.38 | 1.00 | 0.50 |",
        "| `raft` | 0003 | 1 | 0.69 | 0.50 | 0.25 |",
    ]
