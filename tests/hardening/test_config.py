"""Issue 12, item 2: config validation catches NaN, wrong types, bools as ints and degenerate
geometry with a ConfigError naming the field, before anything is built (issue 20: when the
config is made, so an impossible config never exists)."""

from __future__ import annotations

import math
from dataclasses import FrozenInstanceError

import pytest

from cablesim.config import from_dict
from cablesim.errors import ConfigError
from cablesim.panda.description import PARK_QPOS
from cablesim.sim.config import CameraConfig, EpisodeConfig, SceneConfig

NAN = float("nan")


def scene(**parts) -> SceneConfig:
    """``SceneConfig(seed=1)`` with nested fields (``camera__width``) replaced."""
    return SceneConfig(seed=1).with_values({k.replace("__", "."): v for k, v in parts.items()})


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
    with pytest.raises(ConfigError) as err:
        scene(**change)
    assert err.value.field == field
    assert shown in str(err.value)


def test_a_config_cannot_be_changed_into_an_impossible_one():
    cfg = SceneConfig(seed=1)
    with pytest.raises(FrozenInstanceError):
        cfg.camera.width = -5  # type: ignore[misc]
    with pytest.raises(ConfigError) as err:
        cfg.replace(camera=cfg.camera.replace(width=-5))
    assert err.value.field == "camera.width/height" and "-5" in str(err.value)
    with pytest.raises(ConfigError) as err:  # made on its own, a section names its fields
        CameraConfig(fovy=500.0)
    assert err.value.field == "camera.fovy"
    with pytest.raises(ConfigError) as err:  # inside a config: by the full path
        EpisodeConfig().with_values({"scene.camera.fovy": 500.0})
    assert err.value.field == "scene.camera.fovy"
    assert cfg.validate() is cfg  # nothing left to check


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
    cfg = EpisodeConfig.of(seed=3)
    again = EpisodeConfig.from_dict(cfg.to_dict())
    assert again == cfg and str(again) == str(cfg)
    s = SceneConfig(seed=4)
    assert SceneConfig.from_dict(s.to_dict()) == s


def test_jitter_that_could_merge_camera_and_target_is_refused():
    position = SceneConfig().view()[0]  # the board's camera (camera.position None)
    look_at = (position[0] + 0.05, 0.0, position[2])
    with pytest.raises(ConfigError, match="camera.look_at"):
        SceneConfig(camera=CameraConfig(look_at=look_at, position_jitter=0.02))
