"""Issue 12, item 2: config validation catches NaN, wrong types, bools as ints and degenerate
geometry with a ConfigError naming the field, before anything is built."""

from __future__ import annotations

import math

import pytest

from cablesim.config import from_dict
from cablesim.errors import ConfigError
from cablesim.panda.description import PARK_QPOS
from cablesim.sim.config import SceneConfig
from cablesim.sim.session import EpisodeConfig
from cablesim.sim.world import World

NAN = float("nan")


def scene(**parts) -> SceneConfig:
    cfg = SceneConfig(seed=1)
    for path, value in parts.items():
        obj = cfg
        *head, last = path.split("__")
        for name in head:
            obj = getattr(obj, name)
        setattr(obj, last, value)
    return cfg


@pytest.mark.parametrize(
    ("change", "field", "shown"),
    [
        ({"board__x": NAN}, "board.x", "nan"),  # hung World.build
        ({"camera__position": (NAN, 0.0, 0.0)}, "camera.position[0]", "nan"),  # black images
        ({"camera__look_at": (-0.42, 0.0, 0.62)}, "camera.look_at", "camera position"),
        ({"camera__look_at": (-0.42, 0.0, 0.1)}, "camera.look_at", "straight up or down"),
        ({"hoses__length": (NAN, NAN)}, "hoses.length[0]", "nan"),  # OverflowError
        ({"hoses__count": True}, "hoses.count", "True"),  # TypeError
        ({"hoses__length": (50.0, 60.0)}, "hoses.length", "3.0"),  # MuJoCo FatalError
        ({"camera__width": "640"}, "camera.width", "'640'"),
        ({"physics__gravity": math.inf}, "physics.gravity", "inf"),
        ({"robot__park_qpos": PARK_QPOS[:6] + (9.0,)}, "robot.park_qpos[6]", "9.0"),
        ({"hoses__colors": ((1.0, 0.0),)}, "hoses.colors[0]", "3 values"),
        ({"seed": 1.5}, "seed", "1.5"),
    ],
)
def test_bad_scene_values_are_named_before_building(change, field, shown):
    cfg = scene(**change)
    with pytest.raises(ConfigError) as err:
        World.build(cfg, settle=False)
    assert err.value.field == field
    assert shown in str(err.value)


def test_from_dict_checks_types_before_building():
    with pytest.raises(ConfigError, match=r"camera\.width: must be an integer, got '640'"):
        SceneConfig.from_dict({"camera": {"width": "640"}})
    with pytest.raises(ConfigError, match=r"hoses\.count: must be an integer, got True"):
        from_dict(SceneConfig, {"hoses": {"count": True}})
    with pytest.raises(ConfigError, match=r"board\.x: must be a finite number, got nan"):
        SceneConfig.from_dict({"board": {"x": NAN}})
    with pytest.raises(ConfigError, match=r"scene\.camera: expected a mapping"):
        EpisodeConfig.from_dict({"scene": {"camera": [1, 2]}})
    with pytest.raises(ConfigError, match=r"interaction\.retreat\.qpos\[2\]: must be a number"):
        EpisodeConfig.from_dict({"interaction": {"retreat": {"qpos": [0, 0, "a", 0, 0, 0, 0]}}})


def test_valid_configs_round_trip_unchanged():
    cfg = EpisodeConfig(seed=3)
    again = EpisodeConfig.from_dict(cfg.to_dict()).validate()
    assert again == cfg and str(again) == str(cfg)
    s = SceneConfig(seed=4)
    assert SceneConfig.from_dict(s.to_dict()).validate() == s


def test_jitter_that_could_merge_camera_and_target_is_refused():
    cfg = SceneConfig(seed=1)
    cfg.camera.look_at = (cfg.camera.position[0] + 0.05, 0.0, cfg.camera.position[2])
    cfg.camera.position_jitter = 0.02
    with pytest.raises(ConfigError, match="camera.look_at"):
        cfg.validate()
