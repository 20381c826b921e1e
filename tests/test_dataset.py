"""``cablesim dataset``: simulated sequences in the published layouts, read back by the
readers of ``cablesim.formats`` with the published conventions, the same bytes whatever the
number of workers, one moving hose and nothing else moving in a MovingCables clip."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import cablesim  # noqa: F401
from cablesim.commands.dataset import dataset_jobs
from cablesim.dataset.randomize import Randomization, randomize_scene
from cablesim.errors import ConfigError
from cablesim.jobs import Job, execute, load_results
from cablesim.sim.config import SceneConfig

TINY = {"width": 160, "height": 120}
FEW_HOSES = {"hoses": (2, 3)}
CLIP_SEEDS = (402, 403)  # seeds whose tiny randomised scene gives a clip


def _jobs(layout: str, seeds: tuple[int, ...], root: Path, split: str = "test") -> list[Job]:
    jobs = dataset_jobs(layout, seeds[0], seeds[-1] + 1, root, split, TINY, periods=1)
    return [
        Job(j.kind, j.key, {**j.params, "randomize": FEW_HOSES})
        for j in jobs
        if j.params["seed"] in seeds
    ]


def _tree(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*.png")) + sorted(root.rglob("*.json"))
        if "jobs" not in p.parts
    }


def test_randomised_scenes_depend_on_the_seed_only():
    base = SceneConfig()
    a, b = randomize_scene(7, base), randomize_scene(7, base)
    assert a.to_dict() == b.to_dict() and a.seed == 7
    many = [randomize_scene(s, base) for s in range(40)]
    assert len({c.board.background for c in many}) == 4
    assert {c.hoses.count for c in many} == set(range(2, 7))
    assert len({c.hoses.colors for c in many}) > 2
    assert all(c.light.jitter > 0 and c.camera.position_jitter > 0 for c in many)
    assert base.light.jitter == 0 and base.camera.position_jitter == 0  # base untouched
    with pytest.raises(ConfigError, match="hoses"):
        Randomization(hoses=(3, 2))
    with pytest.raises(ConfigError, match="backgrounds"):
        Randomization(backgrounds=("lava",))


def test_same_coloured_scenes_are_the_same_scenes_in_one_colour():
    from cablesim.dataset.generate import scene_from
    from cablesim.sim.layout import sample_hoses

    base = SceneConfig()
    plain = [randomize_scene(s, base) for s in range(40)]
    half = [randomize_scene(s, base, Randomization(same_colour=0.5)) for s in range(40)]
    flagged = [h.hoses.same_colour for h in half]
    assert 10 <= sum(flagged) <= 30  # about half, drawn per seed
    assert not any(p.hoses.same_colour for p in plain)
    for p, h in zip(plain, half, strict=True):  # everything else drawn as without it
        assert p.to_dict() == h.replace(hoses=h.hoses.replace(same_colour=False)).to_dict()
    # a flagged scene lays out the same cables, all in the first cable's colour (within the
    # kinds' jitter); the default keeps distinct colours
    seed = flagged.index(True)
    one, many = sample_hoses(half[seed]), sample_hoses(plain[seed])
    assert [(c.ends, c.length, c.young) for c in one] == [(c.ends, c.length, c.young) for c in many]
    assert one[0].rgb == many[0].rgb
    jitter = max(half[seed].hoses.cable(i).color_jitter for i in range(len(one)))
    assert all(np.abs(np.subtract(c.rgb, one[0].rgb)).max() <= 2 * jitter + 1e-9 for c in one)
    assert max(np.abs(np.subtract(c.rgb, many[0].rgb)).max() for c in many) > 2 * jitter
    # the dataset's jobs carry the share only where it is asked for, and their scenes use it
    jobs = dataset_jobs("movingcables", seed, seed + 1, Path("x"), "test", TINY, same_colour=0.5)
    assert jobs[0].params["randomize"]["same_colour"] == 0.5
    assert scene_from(jobs[0].params).hoses.same_colour
    plain_job = dataset_jobs("movingcables", seed, seed + 1, Path("x"), "test", TINY)[0]
    assert "same_colour" not in plain_job.params["randomize"]
    with pytest.raises(ConfigError, match="--same-colour: the share must be in"):
        dataset_jobs("movingcables", 0, 1, Path("x"), "test", TINY, same_colour=1.5)
    with pytest.raises(ConfigError, match="same_colour"):
        Randomization(same_colour=-0.1)


def test_a_clips_hand_motion_is_drawn_from_its_seed():
    from cablesim.dataset.generate import clip_motion

    motion = {"directions": ["along", "across"], "amplitude": [0.02, 0.05]}
    draws = [clip_motion(s, motion) for s in range(200)]
    assert draws == [clip_motion(s, motion) for s in range(200)]  # the seed alone decides
    assert {d for d, _ in draws} == {"along", "across"}
    amps = np.array([a for _, a in draws])
    assert amps.min() >= 0.02 and amps.max() <= 0.05 and amps.std() > 0.005
    assert clip_motion(5, {"directions": ["across"], "amplitude": [0.03, 0.03]}) == ("across", 0.03)
    assert clip_motion(5, None) == ("along", 0.02)  # jobs written before the draw existed
    jobs = dataset_jobs("movingcables", 0, 2, Path("x"), "test", TINY)
    assert jobs[0].params["motion"] == motion  # the default: along or across, 2-5 cm
    assert "motion" not in dataset_jobs("mcor", 0, 1, Path("x"), "test", TINY)[0].params


def test_h264_and_hose_counts_are_drawn_per_clip_and_checked():
    from cablesim.commands.dataset import check_h264
    from cablesim.dataset.generate import clip_h264, scene_from

    compress = {"h264": 0.5, "crf": [20, 34]}
    draws = [clip_h264(s, compress) for s in range(200)]
    assert draws == [clip_h264(s, compress) for s in range(200)]  # the seed alone decides
    crfs = [c for c in draws if c is not None]
    assert 70 < len(crfs) < 130 and min(crfs) >= 20 and max(crfs) <= 34 and len(set(crfs)) > 8
    assert clip_h264(3, None) is None and clip_h264(3, {"h264": 0.0, "crf": [20, 34]}) is None
    assert all(clip_h264(s, {"h264": 1.0, "crf": [27, 27]}) == 27 for s in range(20))
    # the jobs carry the settings only where asked for: older datasets' jobs stay as they were
    plain = dataset_jobs("movingcables", 0, 1, Path("x"), "test", TINY)[0].params
    assert "compress" not in plain and "hoses" not in plain["randomize"]
    jobs = dataset_jobs("movingcables", 0, 30, Path("x"), "test", TINY, hoses=(7, 8), h264=0.5)
    assert jobs[0].params["compress"] == compress
    counts = {scene_from(j.params).hoses.count for j in jobs}
    assert counts == {7, 8}
    assert "compress" not in dataset_jobs("mcor", 0, 1, Path("x"), "test", TINY, h264=0.5)[0].params
    with pytest.raises(ConfigError, match="--h264: the share must be in"):
        dataset_jobs("movingcables", 0, 1, Path("x"), "test", TINY, h264=2.0)
    with pytest.raises(ConfigError, match="--h264 crf: need 0 <= LO <= HI <= 51, got 30 60"):
        dataset_jobs("movingcables", 0, 1, Path("x"), "test", TINY, h264=0.5, h264_crf=(30, 60))
    with pytest.raises(ConfigError, match="--hoses: need 1 <= LO <= HI <= 8, got 3 9"):
        dataset_jobs("movingcables", 0, 1, Path("x"), "test", TINY, hoses=(3, 9))
    with pytest.raises(ConfigError, match="data.h264: the share"):
        check_h264(-1, (20, 34), "data.h264")
    # asking for the randomiser's own range writes the jobs of a dataset made without it
    assert (
        dataset_jobs("movingcables", 0, 1, Path("x"), "test", TINY, hoses=(2, 6))[0].params == plain
    )


def test_a_dataset_made_with_other_settings_is_not_added_to(tmp_path):
    from cablesim.commands.dataset import check_finished
    from cablesim.jobs import result_path

    jobs = dataset_jobs("movingcables", 0, 2, tmp_path, "test", TINY)
    (tmp_path / "jobs").mkdir()
    old = {**jobs[1].params, "root": "/moved/elsewhere"}  # a moved folder is still the same
    result_path(tmp_path / "jobs", jobs[1]).write_text(json.dumps({"status": "ok", "params": old}))
    check_finished(jobs, tmp_path / "jobs")
    old.pop("motion")  # made before the hand's motion was drawn: along, 2 cm
    result_path(tmp_path / "jobs", jobs[1]).write_text(json.dumps({"status": "ok", "params": old}))
    with pytest.raises(ConfigError, match="0002-s000001.json: was made with other settings"):
        check_finished(jobs, tmp_path / "jobs")
    with pytest.raises(ConfigError, match="--amplitude"):
        dataset_jobs("movingcables", 0, 2, tmp_path, "test", TINY, amplitude=(0.05, 0.02))
    with pytest.raises(ConfigError, match="--directions: unknown 'up'"):
        dataset_jobs("movingcables", 0, 2, tmp_path, "test", TINY, directions=("up",))


@pytest.mark.slow
def test_movingcables_clips_read_back_and_do_not_depend_on_workers(tmp_path):
    from cablesim.formats.movingcables import evaluate_clip, list_clips, read_clip

    two = tmp_path / "two_workers"
    s = execute(_jobs("movingcables", CLIP_SEEDS, two), two / "jobs", workers=2, progress=False)
    assert s.ok == 2, s.report()
    one = tmp_path / "in_process"  # the second clip again, alone, in this process
    s1 = execute(_jobs("movingcables", CLIP_SEEDS, one)[1:], one / "jobs", progress=False)
    assert s1.ok == 1
    clip2 = {k: v for k, v in _tree(two).items() if "/0002/" in k}
    assert clip2 and clip2 == _tree(one)

    split = two / "test"
    assert list_clips(split) == ["0001", "0002"]
    recs = {r["result"]["clip"]: r["result"] for r in load_results(two / "jobs", s_jobs(two))}
    for name in ("0001", "0002"):
        frames = list(read_clip(split, name))
        assert [f.index for f in frames] == list(range(1, 2 * len(frames), 2))
        assert len(frames) == recs[name]["images"] > 10
        # the record's arm share is the largest share of an image the written stick covers
        share = max(float(np.mean(f.stick_mask)) for f in frames)
        assert recs[name]["arm_share_max"] == pytest.approx(share, abs=1e-4) and share > 0
        assert np.all(frames[0].flow == 0)  # the first image against itself
        moving = int(recs[name]["hose"]) + 1  # instance id of the moved hose
        peak = 0.0
        for fr in frames:
            inst = fr.instances
            assert set(np.unique(inst)) >= {0, moving}
            # flow lives on hose pixels only; the hoses that were not moved have exactly none
            assert np.all(fr.flow[inst == 0] == 0)
            others = (inst > 0) & (inst != moving)
            assert np.all(fr.flow[others] == 0) and np.all(fr.normal_flow[others] == 0)
            # normal flow is the flow's projection: never longer than the flow
            on = inst == moving
            nf, f = (np.linalg.norm(x[on], axis=1) for x in (fr.normal_flow, fr.flow))
            assert np.all(nf <= f + 2 / 64)
            peak = max(peak, float(f.max()))
        assert peak > 1.0  # px: the hose moved (and came back: the action is periodic)
        assert any(fr.stick_mask.any() for fr in frames)  # the arm, as the stick
        _, summary = evaluate_clip(split, name, "farneback", thr_motion=1.0)
        assert summary.images == len(frames) and np.isfinite(summary.epe)


def s_jobs(root: Path) -> list[Job]:
    return _jobs("movingcables", CLIP_SEEDS, root)


@pytest.mark.slow
def test_mcor_sequence_reads_back_with_its_annotation(tmp_path):
    from cablesim.formats.mcor import read_mcor

    seed = 4
    s = execute(_jobs("mcor", (seed,), tmp_path), tmp_path / "jobs", progress=False)
    rec = load_results(tmp_path / "jobs", _jobs("mcor", (seed,), tmp_path))[0]
    assert s.ok == 1, rec["result"]
    name = rec["result"]["sequence"]
    folder = tmp_path / "motion_correlation_buffers" / name
    doc = json.loads((folder / "actions_gripper.json").read_text())
    seq = read_mcor(folder)
    assert len(seq.stream) == rec["result"]["images"] == len(doc["action_buffer"])
    assert seq.annotation is not None and seq.truth is not None
    assert int(seq.truth.sum()) == rec["result"]["truth_pixels"] > 0
    assert len(seq.arm_masks) == len(seq.stream)  # the arm masks of the published layout
    assert set(doc["action_buffer"][:-1]) >= {0, 1}
    assert seq.segment is not None and seq.segment.any()
