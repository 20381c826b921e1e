"""The whole typed config from the command line: ``--set FIELD=VALUE`` reaches any field,
``--show-config`` lists them, a run's ``config.json`` reruns through ``--config``, and bad
paths or values are one line naming the field."""

from __future__ import annotations

import json

import pytest

from cablesim.cli import main
from cablesim.config import flatten, override, parse_value
from cablesim.errors import ConfigError
from cablesim.policies.config import ExploreConfig
from cablesim.sim.config import EpisodeConfig


def _shown(capsys) -> dict[str, object]:
    lines = capsys.readouterr().out.splitlines()
    return {k: json.loads(v) for k, v in (line.split(" = ", 1) for line in lines)}


def test_set_reaches_nested_fields_and_checks_their_type():
    cfg = override(ExploreConfig(), "episode.scene.hoses.count=2")
    assert cfg.episode.scene.hoses.count == 2
    cfg = override(cfg, "episode.interaction.actions.amplitude=0.03")
    assert cfg.episode.interaction.actions.amplitude == 0.03
    cfg = override(cfg, "episode.scene.camera.position=[1.2, 0.0, 0.9]")
    assert cfg.episode.scene.camera.position == (1.2, 0.0, 0.9)
    assert override(cfg, "episode.hose=null").episode.hose is None
    assert dict(flatten(cfg))["episode.scene.hoses.count"] == 2
    with pytest.raises(ConfigError, match=r"episode\.scene\.hoses\.count.*integer"):
        override(cfg, "episode.scene.hoses.count=many")
    with pytest.raises(ConfigError, match=r"episode\.scene\.hoses\.cuont.*no such field"):
        override(cfg, "episode.scene.hoses.cuont=3")
    with pytest.raises(ConfigError, match="FIELD=VALUE"):
        override(cfg, "grasps")
    assert parse_value("True") is True and parse_value("dis") == "dis"


def test_show_config_prints_every_field_with_flags_and_sets_applied(tmp_path, capsys):
    argv = ["explore", "--out", str(tmp_path / "x"), "--grasps", "1", "--hoses", "3"]
    argv += ["--set", "episode.interaction.actions.periods=2", "--show-config"]
    assert main(argv) == 0
    shown = _shown(capsys)
    assert shown["grasps"] == 1 and shown["max_attempts"] == 3
    assert shown["episode.scene.hoses.count"] == 3
    assert shown["episode.interaction.actions.periods"] == 2
    assert len(shown) > 100  # the whole nested config, not a handful of flags
    assert not (tmp_path / "x").exists()  # nothing run, nothing written


def test_config_file_reruns_and_flags_override_it(tmp_path, capsys):
    cfg = override(EpisodeConfig.of(seed=7), "scene.hoses.count=2")
    path = tmp_path / "config.json"
    path.write_text(json.dumps(cfg.to_dict()))
    assert (
        main(["episode", "--out", str(tmp_path / "o"), "--config", str(path), "--show-config"]) == 0
    )
    shown = _shown(capsys)
    assert shown["scene.seed"] == 7 and shown["scene.hoses.count"] == 2
    argv = ["episode", "--out", str(tmp_path / "o"), "--config", str(path), "--seed", "9"]
    assert main([*argv, "--show-config"]) == 0
    assert _shown(capsys)["scene.seed"] == 9
    # a real run's file holds {"explore": ..., "real": ...}: --config takes its explore part
    both = tmp_path / "real.json"
    both.write_text(json.dumps({"explore": ExploreConfig(grasps=2).to_dict(), "real": {}}))
    argv = ["explore", "--out", str(tmp_path / "e"), "--config", str(both), "--show-config"]
    assert main(argv) == 0
    assert _shown(capsys)["grasps"] == 2


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--set", "episode.scene.hoses.count=abc"], "episode.scene.hoses.count"),
        (["--set", "nonsense=1"], "nonsense"),
        (["--config", "/nonexistent/config.json"], "/nonexistent/config.json"),
        (["--grow-colour", "300"], "grow_colour"),
    ],
)
def test_bad_config_input_is_one_line_naming_it(tmp_path, capsys, extra, needle):
    assert main(["explore", "--out", str(tmp_path / "x"), *extra, "--show-config"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_config_file_with_a_bad_value_names_file_and_field(tmp_path, capsys):
    path = tmp_path / "config.json"
    doc = EpisodeConfig().to_dict()
    doc["scene"]["camera"]["width"] = "640"
    path.write_text(json.dumps(doc))
    argv = ["episode", "--out", str(tmp_path / "o"), "--config", str(path), "--show-config"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "scene.camera.width" in err


@pytest.mark.parametrize("command", ["scene", "episode", "explore"])
def test_out_is_needed_to_run_but_not_to_show_the_config(command, capsys):
    assert main([command, "--show-config"]) == 0
    capsys.readouterr()
    assert main([command]) == 2
    assert "--out is required" in capsys.readouterr().err
