"""Fuzzing the Gymnasium environment: any action (of any structure) either works or raises
InputError naming the key, leaving the environment as it was; any config edit either makes an
environment or raises ConfigError.  One small environment is built once and reused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cablesim.envs import HoseExploreConfig, HoseExploreEnv
from cablesim.envs.hose_explore import ENV_SHORTCUTS, check_action
from cablesim.errors import InputError

from ._fuzz import HOSTILE, SCALARS, fuzz, own_error_or_result

TINY = HoseExploreConfig.of(scene_seed=2, hoses=2, width=160, height=120, budget=100, periods=1)

VALUES = st.one_of(
    HOSTILE,
    hnp.arrays(
        st.sampled_from([np.float32, np.float64, np.int64, bool]),
        hnp.array_shapes(min_dims=0, max_dims=2, max_side=3),
    ),
    st.integers(-3, 3),
)
ACTIONS = st.one_of(
    HOSTILE,
    st.fixed_dictionaries(
        {"primitive": st.one_of(st.integers(0, 1), VALUES), "point": VALUES, "angle": VALUES}
    ),
    st.dictionaries(st.sampled_from(["primitive", "point", "angle", "x"]), VALUES, max_size=4),
)


@fuzz(400)
@given(ACTIONS)
def test_check_action(action):
    parsed = own_error_or_result(check_action, action)
    if parsed is not None:
        primitive, point, angle = parsed
        assert primitive in (0, 1) and point.shape == (2,) and np.isfinite(angle)
        assert np.all(np.isfinite(point))


@pytest.fixture(scope="module")
def env():
    e = HoseExploreEnv(dataclasses.replace(TINY))
    e.reset(seed=3)
    yield e
    e.close()


@fuzz(40)
@given(ACTIONS.filter(lambda a: own_error_or_result(check_action, a) is None))
def test_rejected_actions_change_nothing(env, action):
    before = (env._count, env._image.rgb.copy(), env._segment.copy())
    with pytest.raises(InputError):
        env.step(action)
    assert env._count == before[0]
    assert np.array_equal(env._image.rgb, before[1]) and np.array_equal(env._segment, before[2])


@fuzz(3, deadline_ms=None)
@given(
    primitive=st.integers(0, 1),
    point=st.tuples(st.floats(-0.5, 1.5), st.floats(-0.5, 1.5)),
    angle=st.floats(-3, 3),
)
def test_valid_actions_step(env, primitive, point, angle):
    """A few real interactions with random (valid, possibly out-of-box) actions."""
    action = {"primitive": primitive, "point": np.array(point), "angle": np.array([angle])}
    obs, reward, terminated, truncated, info = env.step(action)
    assert env.observation_space.contains(obs)
    assert np.isfinite(reward) and not terminated
    assert isinstance(info["success"], bool) and isinstance(info["reason"], str)


#: the environment's own fields and the shortcuts into its session (``width`` -> ``episode...``)
FIELDS = [f.name for f in dataclasses.fields(HoseExploreConfig) if f.name != "episode"]
FIELDS += sorted(ENV_SHORTCUTS)


@fuzz(120)
@given(
    st.dictionaries(st.sampled_from(FIELDS), st.one_of(SCALARS, HOSTILE), min_size=1, max_size=3)
)
def test_config_edits(changes):
    cfg = own_error_or_result(TINY.replace, **changes)  # checked when made
    if cfg is not None:
        own_error_or_result(HoseExploreEnv, cfg)  # builds nothing
