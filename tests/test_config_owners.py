"""Issue 20, one owner per config field: the seed lives in one place, ``--show-config`` prints
each field once, a config is checked when it is made (and stays so: frozen), every top-level
config round-trips, and the ``config.json`` files of runs made before the change
(``tests/data/old_configs``) still load, with a warning where a field moved, and rerun to the
results they gave then."""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import FrozenInstanceError, fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cablesim.cli import main
from cablesim.config import ConfigMigrationWarning, flatten, replace_paths
from cablesim.dataset.randomize import Randomization
from cablesim.envs.hose_explore import HoseExploreConfig
from cablesim.episode.config import ActionConfig, InteractionConfig
from cablesim.errors import ConfigError
from cablesim.policies.config import ExploreConfig
from cablesim.provenance import float_platforms
from cablesim.sim.config import (
    CameraConfig,
    EpisodeConfig,
    HoseConfig,
    PerturbConfig,
    SceneConfig,
)
from cablesim.thesis.config import SceneSize, ThesisConfig

DATA = Path(__file__).parent / "data" / "old_configs"
#: what the runs of the old config files gave before the change (see DATA / "README.md"), per
#: platform (:func:`cablesim.provenance.float_platform`: floats and pixels agree bit for bit on
#: one CPU vendor only); ``CABLESIM_PIN_RECORD=1 pytest -n0 -k reruns tests/test_config_owners.py``
#: on a machine of a new platform records its entry
EXPECTED_FILE = DATA / "expected.json"
EXPECTED_ALL: dict[str, dict[str, Any]] = json.loads(EXPECTED_FILE.read_text())
RECORD = bool(os.environ.get("CABLESIM_PIN_RECORD"))
#: keys of run documents that hold the config (its layout changed) or wall-clock timings
VOLATILE = frozenset({"config", "timings_s", "timings", "scene_build_s", "wall_s", "cpu_s"})


def expected(run: str) -> dict[str, Any]:
    """This platform's record of ``run``; skipped, naming the platform, where there is none
    (and not recording)."""
    names = float_platforms()  # the most specific name first (with the CPU family)
    here = next((n for n in names if run in EXPECTED_ALL.get(n, {})), None)
    if RECORD:
        # this platform's record, else any platform's (the first to hold the run)
        mine = EXPECTED_ALL[here][run] if here is not None else None
        return mine or next(runs[run] for runs in EXPECTED_ALL.values() if run in runs)
    if here is not None:
        return EXPECTED_ALL[here][run]
    here = next((n for n in names if n in EXPECTED_ALL), names[0])
    if here not in EXPECTED_ALL:
        pytest.skip(
            f"no expected results for {here!r} (recorded: {', '.join(sorted(EXPECTED_ALL))}); "
            "record them with CABLESIM_PIN_RECORD=1 (see EXPECTED_FILE)"
        )
    if run not in EXPECTED_ALL[here]:
        # a run whose results a later change altered on purpose, re-recorded on another
        # platform only (the README beside EXPECTED_FILE says which and why)
        others = sorted(p for p, runs in EXPECTED_ALL.items() if run in runs)
        pytest.skip(
            f"no expected {run!r} results for {here!r} (recorded on: {', '.join(others)}); "
            "record them with CABLESIM_PIN_RECORD=1 (see EXPECTED_FILE)"
        )
    return EXPECTED_ALL[here][run]


def check_rerun(run: str, want: dict[str, Any], got: dict[str, Any]) -> None:
    """``got`` equals ``want``, this platform's record of ``run`` (:func:`expected`, taken
    before the run so that a platform with none skips it), key by key; in record mode ``got``
    becomes that record."""
    if RECORD:
        doc = json.loads(EXPECTED_FILE.read_text())
        doc.setdefault(float_platforms()[0], {})[run] = got
        EXPECTED_FILE.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
        return
    assert set(got) == set(want), run
    for key in sorted(want):
        assert got[key] == want[key], f"{run}: {key} differs on {float_platforms()[0]!r}"


def stable(doc: Any) -> Any:
    """``doc`` without its ``VOLATILE`` keys, at any depth."""
    if isinstance(doc, dict):
        return {k: stable(v) for k, v in doc.items() if k not in VOLATILE}
    if isinstance(doc, list):
        return [stable(v) for v in doc]
    return doc


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def json_digest(doc: Any) -> str:
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def shown(capsys) -> dict[str, Any]:
    """``--show-config``'s lines as {path: value}; every path once."""
    lines = capsys.readouterr().out.splitlines()
    pairs = [line.split(" = ", 1) for line in lines]
    paths = [p for p, _ in pairs]
    assert len(paths) == len(set(paths)), [p for p in paths if paths.count(p) > 1]
    return {p: json.loads(v) for p, v in pairs}


def load(cls: type, name: str) -> tuple[Any, list[str]]:
    """An old config file of DATA, loaded, and the migration warnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cfg = cls.from_dict(json.loads((DATA / name).read_text()))
    return cfg, [str(w.message) for w in caught if w.category is ConfigMigrationWarning]


# ---------------------------------------------------------------------- one seed, each field once
@pytest.mark.parametrize(
    ("argv", "seed"),
    [
        (["scene"], "seed"),
        (["episode"], "scene.seed"),
        (["explore"], "episode.scene.seed"),
        (["twin"], "scene.seed"),
        (["benchmark", "thesis"], None),
    ],
)
def test_show_config_prints_every_field_once_and_one_seed(argv, seed, capsys):
    assert main([*argv, "--seed", "5", "--show-config"] if seed else [*argv, "--show-config"]) == 0
    values = shown(capsys)
    assert len(values) > 20
    seeds = [p for p in values if p.rsplit(".", 1)[-1] == "seed"]
    assert seeds == ([seed] if seed else [])
    if seed:
        assert values[seed] == 5


def test_the_three_seed_case_is_gone(capsys):
    """``explore --set episode.seed=5`` printed three seeds (``seed``, ``episode.seed``,
    ``episode.scene.seed``); now there is one, and the old path says where it went."""
    assert main(["explore", "--set", "episode.scene.seed=5", "--show-config"]) == 0
    values = shown(capsys)
    assert [p for p in values if "seed" in p.rsplit(".", 1)[-1]] == ["episode.scene.seed"]
    assert values["episode.scene.seed"] == 5
    for old in ("episode.seed", "seed"):
        assert main(["explore", "--set", f"{old}=5", "--show-config"]) == 2
        err = capsys.readouterr().err
        assert f"{old}: no such field" in err and "episode.scene.seed" in err
    cfg = ExploreConfig.of(seed=5)
    assert cfg.seed == cfg.episode.seed == cfg.episode.scene.seed == 5
    assert [p for p, _ in flatten(cfg) if p.endswith("seed")] == ["episode.scene.seed"]


def test_flags_write_the_nested_fields(capsys):
    argv = ["explore", "--seed", "4", "--width", "200", "--height", "150", "--hoses", "3"]
    argv += ["--periods", "2", "--hose", "1", "--perturb", "--strategy", "push", "--grasps", "2"]
    assert main([*argv, "--show-config"]) == 0
    values = shown(capsys)
    assert (
        values["episode.scene.camera.width"] == 200 and values["episode.scene.camera.height"] == 150
    )
    assert values["episode.scene.hoses.count"] == 3 and values["episode.hose"] == 1
    assert values["episode.interaction.actions.periods"] == 2
    assert values["episode.perturb.enabled"] is True
    assert values["strategy"] == "push" and values["episode.interaction.kind"] == "push"
    assert values["grasps"] == 2 and values["max_attempts"] == 4
    for gone in ("seed", "hose", "width", "height", "perturb.enabled", "episode.progress"):
        assert gone not in values
    # --set wins over the flag whatever the order; the config is built once
    assert main([*argv, "--set", "episode.scene.camera.width=320", "--show-config"]) == 0
    assert shown(capsys)["episode.scene.camera.width"] == 320
    assert main(["benchmark", "thesis", "--width", "160", "--hoses", "2", "--show-config"]) == 0
    values = shown(capsys)
    assert values["scene.width"] == 160 and values["scene.hoses"] == 2


# ---------------------------------------------------------------------- checked when made
@pytest.mark.parametrize(
    ("make", "field", "value"),
    [
        (lambda: SceneConfig(seed=-1), "seed", "-1"),
        (lambda: CameraConfig(width=5), "camera.width/height", "5x480"),
        (lambda: SceneConfig(camera=CameraConfig(fovy=float("nan"))), "camera.fovy", "nan"),
        (lambda: InteractionConfig(kind="pull"), "kind", "pull"),
        (lambda: ActionConfig(periods=0), "actions.periods", "0"),
        (lambda: PerturbConfig(points=0), "perturb.points", "0"),
        (lambda: EpisodeConfig(hose=9), "hose", "9"),
        (lambda: EpisodeConfig.of(width=5), "scene.camera.width/height", "5x480"),
        (lambda: EpisodeConfig.of(hoses=2, hose=3), "hose", "3"),
        (lambda: ExploreConfig(grasps=0), "grasps", "0"),
        (lambda: ExploreConfig.of(height=5000), "episode.scene.camera.width/height", "5000"),
        (lambda: ExploreConfig.of(seed=1.5), "episode.scene.seed", "1.5"),
        (lambda: ExploreConfig(strategy="push"), "episode.interaction.kind", "grasp"),
        (lambda: HoseExploreConfig(budget=0), "budget", "0"),
        (lambda: HoseExploreConfig.of(scene_seed=2**31), "episode.scene.seed", "2147483648"),
        (lambda: ThesisConfig(workers=-1), "workers", "-1"),
        (lambda: ThesisConfig(scene=SceneSize(hoses=0)), "scene.hoses", "0"),
        (lambda: ThesisConfig().with_values({"scene.width": "wide"}), "scene.width", "wide"),
        (lambda: Randomization(random_colours=2.0), "random_colours", "2.0"),
    ],
)
def test_an_impossible_config_is_refused_when_made(make, field, value):
    with pytest.raises(ConfigError) as err:
        make()
    assert err.value.field == field
    assert value in str(err.value)


def test_a_config_stays_valid():
    cfg = ExploreConfig.of(seed=3, width=160, height=120)
    with pytest.raises(FrozenInstanceError):
        cfg.episode.scene.camera.width = 5  # type: ignore[misc]
    with pytest.raises(FrozenInstanceError):
        cfg.grasps = 0  # type: ignore[misc]
    with pytest.raises(ConfigError, match=r"episode\.scene\.camera\.width/height"):
        cfg.with_values({"episode.scene.camera.width": 5})
    assert cfg.validate() is cfg  # nothing left to check
    assert cfg.replace(seed=4).seed == 4 and cfg.seed == 3  # a new config; this one unchanged


# ---------------------------------------------------------------------- round trips
CONFIGS = [
    SceneConfig(seed=7, draw=1, hoses=HoseConfig(count=3), camera=CameraConfig.realistic()),
    InteractionConfig(kind="push", actions=ActionConfig(extra_directions=((0.0, 0.0, 1.0),))),
    PerturbConfig(enabled=True, hoses=(0, 2)),
    EpisodeConfig.of(seed=3, hose=1, width=320, height=240, periods=2, clutter=False),
    ExploreConfig.of(seed=4, strategy="push", grasps=2, perturb=PerturbConfig(enabled=True)),
    HoseExploreConfig.of(scene_seed=2, hoses=2, budget=1, flow="dis", hose=1),
    ThesisConfig(
        validation=(1, 3), test=(5, 9), scene=SceneSize(width=160, height=120), ray="local"
    ),
    Randomization(hoses=(2, 3), backgrounds=("wood",)),
]


@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: type(c).__name__)
def test_every_top_level_config_round_trips(cfg):
    cls = type(cfg)
    assert cfg != cls()
    assert cls.from_dict(cfg.to_dict()) == cfg
    assert cls.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    assert cls.from_dict(json.loads(str(cfg))) == cfg  # printed and reloaded
    # every field by its dotted path (what --show-config prints and --set takes) rebuilds it
    assert replace_paths(cls(), dict(flatten(cfg)), shortcuts=False) == cfg
    first = fields(cfg)[0].name
    with pytest.raises(FrozenInstanceError):
        setattr(cfg, first, getattr(cfg, first))


@pytest.mark.parametrize(
    ("command", "cfg"),
    [
        ("explore", CONFIGS[4]),
        ("episode", CONFIGS[3]),
        ("scene", CONFIGS[0]),
        ("benchmark", CONFIGS[6]),
    ],
)
def test_a_runs_config_json_shows_and_reloads_as_it_was(tmp_path, capsys, command, cfg):
    path = tmp_path / "config.json"
    path.write_text(json.dumps(cfg.to_dict(), indent=2))
    argv = [command, "thesis"] if command == "benchmark" else [command]
    assert main([*argv, "--config", str(path), "--show-config"]) == 0
    assert replace_paths(type(cfg)(), shown(capsys), shortcuts=False) == cfg
    assert "warning" not in capsys.readouterr().err


# ---------------------------------------------------------------------- old config files
def test_old_explore_config_moves_its_fields_with_a_warning():
    cfg, said = load(ExploreConfig, "explore.json")
    old = json.loads((DATA / "explore.json").read_text())
    assert old["seed"] == 2 and old["episode"]["seed"] == 0  # the three seeds of that layout
    assert cfg.seed == cfg.episode.scene.seed == 2
    assert cfg.episode.perturb.enabled is old["perturb"]["enabled"] is True
    assert cfg.episode.scene.camera.width == 160 and cfg.episode.scene.hoses.count == 2
    assert any(m.startswith("seed moved to episode.scene.seed") for m in said), said
    assert any(m.startswith("perturb moved to episode.perturb") for m in said), said
    assert any("width moved to episode.scene.camera.width" in m for m in said), said
    # an old push exploration ran pokes though its nested interaction said "grasp"
    push, said = load(ExploreConfig, "explore_push.json")
    assert push.strategy == "push" and push.episode.interaction.kind == "push"
    assert push.episode.perturb.enabled and push.seed == 4
    assert any("was not what its run used" in m for m in said), said


def test_old_episode_env_scene_and_thesis_configs_load():
    ep, said = load(EpisodeConfig, "episode.json")
    assert ep.seed == 2 and ep.scene.hoses.count == 2
    assert any(m.startswith("seed moved to scene.seed") for m in said), said
    assert any(m.startswith("progress (") and "no longer a config field" in m for m in said)
    env, said = load(HoseExploreConfig, "env_fast_config.json")
    assert env.episode.scene.seed == 3 and env.episode.scene.hoses.count == 2
    assert env.episode.interaction.actions.periods == 1 and env.budget == 1
    assert any(m.startswith("scene_seed moved to episode.scene.seed") for m in said), said
    scene, said = load(SceneConfig, "scene.json")
    assert scene.seed == 2 and not said  # the scene's layout did not change
    thesis, said = load(ThesisConfig, "thesis.json")
    assert thesis.scene == SceneSize(160, 120, 2, 1) and not said


def test_a_file_of_mixed_layouts_is_refused_where_they_disagree():
    doc = ExploreConfig.of(seed=2).to_dict()  # today's layout
    with pytest.raises(ConfigError) as err:
        ExploreConfig.from_dict({**doc, "seed": 9})
    assert err.value.field == "seed" and "episode.scene.seed" in str(err.value)
    assert "9" in str(err.value) and "2" in str(err.value)
    with pytest.warns(ConfigMigrationWarning, match="seed moved to episode.scene.seed"):
        assert ExploreConfig.from_dict({**doc, "seed": 2}).seed == 2
    env = HoseExploreConfig.of(hoses=2).to_dict()
    with pytest.raises(ConfigError, match=r"hoses: moved to episode\.scene\.hoses\.count"):
        HoseExploreConfig.from_dict({**env, "hoses": 3})


def test_the_command_line_says_which_fields_moved(capsys):
    argv = ["explore", "--config", str(DATA / "explore.json"), "--show-config"]
    assert main(argv) == 0
    err = capsys.readouterr().err.splitlines()
    assert any(
        line.startswith("cablesim: warning: --config ")
        and line.endswith("seed moved to episode.scene.seed (2)")
        for line in err
    ), err


# ---------------------------------------------------------------------- old runs rerun
@pytest.mark.slow
def test_old_explore_reruns_to_its_metrics(tmp_path):
    want, out = expected("explore"), tmp_path / "explore"
    assert (
        main(["explore", "--config", str(DATA / "explore.json"), "--out", str(out), "--quiet"]) == 0
    )
    metrics = stable(json.loads((out / "metrics.json").read_text()))
    files = {n: digest(out / n) for n in want["files"]}
    check_rerun("explore", want, {"metrics": metrics, "files": files})


@pytest.mark.slow
def test_old_episode_reruns_to_its_summary_and_frames(tmp_path):
    want, out = expected("episode"), tmp_path / "episode"
    assert (
        main(["episode", "--config", str(DATA / "episode.json"), "--out", str(out), "--quiet"]) == 0
    )
    summary = stable(json.loads((out / "summary.json").read_text()))
    # recording/index.jsonl holds every frame's sha256
    files = {n: digest(out / n) for n in want["files"]}
    check_rerun("episode", want, {"summary": summary, "files": files})


def test_old_scene_reruns_to_its_files(tmp_path):
    want, out = expected("scene"), tmp_path / "scene"
    assert main(["scene", "--config", str(DATA / "scene.json"), "--out", str(out)]) == 0
    scene = stable(json.loads((out / "scene.json").read_text()))
    check_rerun(
        "scene", want, {"scene": scene, "files": {n: digest(out / n) for n in want["files"]}}
    )


@pytest.mark.slow
def test_old_thesis_benchmark_reruns_to_its_results(tmp_path):
    want, out = expected("thesis"), tmp_path / "thesis"
    argv = ["benchmark", "thesis", "--config", str(DATA / "thesis.json"), "--out", str(out)]
    assert main([*argv, "--quiet"]) == 0
    results = {
        p.name: json_digest(stable(json.loads(p.read_text())))
        for p in sorted((out / "results").glob("*.json"))
    }
    check_rerun("thesis", want, {"results": results})


@pytest.mark.slow
def test_old_dataset_job_reruns_to_its_files(tmp_path):
    """``cablesim dataset`` writes no ``config.json``: a sequence's job record (its params)
    is what reruns it."""
    from cablesim.jobs import Job, execute

    want = expected("dataset")
    record = json.loads((DATA / "dataset_mcor_job.json").read_text())
    params = {**record["params"], "root": str(tmp_path / "dataset")}
    summary = execute(
        [Job(record["kind"], record["key"], params)], tmp_path / "jobs", progress=False
    )
    assert summary.ok == 1
    doc = json.loads((tmp_path / "jobs" / f"{record['key']}.json").read_text())
    # the job record's result is the file's own on the platform that wrote it, else recorded
    result = want.get("result", stable(record["result"]))
    assert RECORD or stable(doc["result"]) == result
    got = {
        str(p.relative_to(tmp_path / "dataset")): digest(p)
        for p in sorted((tmp_path / "dataset").rglob("*"))
        if p.is_file()
    }
    rerun = {"files": len(got), "digest": json_digest(got)}
    if "result" in want or stable(doc["result"]) != stable(record["result"]):
        rerun["result"] = stable(doc["result"])
    check_rerun("dataset", want, rerun)


@pytest.mark.slow
def test_old_environment_config_resets_and_steps_as_before():
    from cablesim.envs import HoseExploreEnv
    from cablesim.envs.aim import aim_at_segment

    want = expected("env")
    cfg, _ = load(HoseExploreConfig, "env_fast_config.json")
    env = HoseExploreEnv(cfg)
    try:
        obs, info = env.reset(seed=0)
        got = {"reset": _obs_digest(obs), "reset_info": json.loads(json.dumps(info, default=float))}
        obs, reward, _, _, info = env.step(aim_at_segment(obs))
        got |= {"step": _obs_digest(obs), "reward": float(reward)}
        got["step_info"] = json.loads(json.dumps(info, default=float))
    finally:
        env.close()
    check_rerun("env", want, got)


def _obs_digest(obs: dict[str, np.ndarray]) -> dict[str, str]:
    return {
        k: hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()[:16]
        for k, v in sorted(obs.items())
    }


def test_the_old_files_are_what_earlier_runs_wrote():
    """The files are the runs' own (the old layout: a seed beside the nested one)."""
    explore = json.loads((DATA / "explore.json").read_text())
    assert {"seed", "hose", "width", "height", "perturb"} <= set(explore)
    assert {"seed", "progress"} <= set(explore["episode"])
    assert "seed" in json.loads((DATA / "episode.json").read_text())
    assert "scene_seed" in json.loads((DATA / "env_fast_config.json").read_text())
