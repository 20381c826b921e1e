"""Issue 12, item 5: the Gymnasium environment checks its config at construction and reset and
every action in ``step``; errors are the project's own, naming the key or field."""

from __future__ import annotations

import dataclasses
from dataclasses import FrozenInstanceError

import gymnasium as gym
import numpy as np
import pytest

import cablesim.envs  # noqa: F401  (registers the environment)
from cablesim.envs import ENV_ID, HoseExploreConfig, HoseExploreEnv
from cablesim.errors import CablesimError, ConfigError, InputError

TINY = HoseExploreConfig.of(scene_seed=2, hoses=2, width=160, height=120, budget=2, periods=1)
GOOD = {"primitive": 0, "point": np.array([0.5, 0.5], np.float32), "angle": np.array([0.0])}


@pytest.fixture(scope="module")
def env():
    e = gym.make(ENV_ID, config=dataclasses.replace(TINY))
    e.reset(seed=1)
    yield e
    e.close()


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"budget": 0}, "budget"),
        ({"flow": "magic"}, "flow"),
        ({"merge": "glue"}, "merge"),
        ({"hoses": 9}, "episode.scene.hoses.count"),
        ({"width": 10}, "episode.scene.camera.width/height"),
        ({"periods": 1.5}, "episode.interaction.actions.periods"),
        ({"segment_length": float("nan")}, "segment_length"),
        ({"hose": 2}, "episode.hose"),
        ({"randomize_scene": 1}, "randomize_scene"),
    ],
)
def test_bad_config_is_refused_at_construction(change, field):
    with pytest.raises(ConfigError) as err:  # the config itself, before any environment
        TINY.replace(**change)
    assert err.value.field == field


@pytest.mark.parametrize(
    ("action", "match"),
    [
        ({**GOOD, "point": np.array([np.nan, 0.5])}, r"action point must be finite, got \[nan"),
        ({**GOOD, "angle": np.array([np.inf])}, "action angle must be finite"),
        ({**GOOD, "primitive": 5}, "action primitive must be 0 .grasp. or 1 .push., got 5"),
        ({**GOOD, "primitive": 0.5}, "action primitive must be 0"),
        ({"primitive": 0, "point": GOOD["point"]}, r"the action lacks \['angle'\]"),
        ({**GOOD, "point": "abc"}, "action point must be 2 number"),
        ({**GOOD, "point": np.zeros(3)}, "action point must be 2 number"),
        ([0, 0.5, 0.5], "the action must be a dict"),
    ],
)
def test_bad_actions_are_named_and_change_nothing(env, action, match):
    inner = env.unwrapped
    before = (inner._count, inner._image.rgb.copy())
    with pytest.raises(InputError, match=match):
        env.step(action)
    assert inner._count == before[0] and np.array_equal(inner._image.rgb, before[1])


def test_reset_checks_the_config_and_the_seed(env):
    inner = env.unwrapped
    with pytest.raises(InputError, match="reset seed"):
        inner.reset(seed=-1)
    with pytest.raises(FrozenInstanceError):
        inner.config.budget = 0  # a config cannot be changed into an impossible one
    with pytest.raises(ConfigError, match="budget"):
        inner.config.replace(budget=0)
    with pytest.raises(ConfigError, match="flow"):
        inner.config.replace(flow="magic")
    old = inner.config
    try:
        inner.config = old.with_values(width=320, height=240)  # not the spaces' size
        with pytest.raises(ConfigError, match=r"episode\.scene\.camera\.width/height"):
            inner.reset(seed=1)
        inner.config = {"budget": 2}
        with pytest.raises(ConfigError, match="HoseExploreConfig"):
            inner.reset(seed=1)
    finally:
        inner.config = old


def test_step_after_close_is_named():
    e = HoseExploreEnv(dataclasses.replace(TINY))
    e.reset(seed=1)
    e.close()
    with pytest.raises(CablesimError, match=r"call reset\(\) before step\(\)"):
        e.step(GOOD)
    obs, _ = e.reset(seed=1)  # usable again after a reset
    assert obs["rgb"].shape == (120, 160, 3)
    e.close()
