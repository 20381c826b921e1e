"""A ``dm_env`` view of :class:`~cablesim.envs.hose_explore.HoseExploreEnv`.

    from cablesim.envs.dm import DmEnvAdapter
    env = DmEnvAdapter(HoseExploreConfig.of(width=160, height=120), seed=0)
    ts = env.reset()                      # TimeStep(FIRST), ts.observation: dict of arrays
    ts = env.step({"primitive": 0, "point": np.array([0.5, 0.4], np.float32),
                   "angle": np.array([0.0], np.float32)})

Specs mirror the Gymnasium spaces (``BoundedArray`` per observation key; the action is a dict
of ``DiscreteArray(2)`` and two ``BoundedArray``).  The end of the interaction budget is a
truncation: ``dm_env.truncation`` (LAST with discount 1.0).  The first reset uses ``seed``,
later resets continue the environment's generator.

Only ``dm_env`` is used here: dm_control's ``Physics`` does not work with MuJoCo 4.0 (see the
README), so this is an adapter of the same MuJoCo-bindings environment, not a dm_control suite
task.
"""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np
from dm_env import specs
from gymnasium import spaces

from .hose_explore import HoseExploreConfig, HoseExploreEnv


def _spec(space: spaces.Space, name: str) -> Any:
    if isinstance(space, spaces.Discrete):
        return specs.DiscreteArray(int(space.n), dtype=np.int64, name=name)
    if isinstance(space, spaces.Box):
        return specs.BoundedArray(space.shape, space.dtype, space.low, space.high, name=name)
    if isinstance(space, spaces.Dict):
        return {k: _spec(s, k) for k, s in space.spaces.items()}
    raise TypeError(f"no dm_env spec for {type(space).__name__}")


class DmEnvAdapter(dm_env.Environment):
    """``dm_env.Environment`` over a :class:`HoseExploreEnv`."""

    def __init__(
        self, config: HoseExploreConfig | HoseExploreEnv | None = None, seed: int | None = 0
    ) -> None:
        self.env = config if isinstance(config, HoseExploreEnv) else HoseExploreEnv(config)
        self._seed = seed
        self._need_reset = True
        self.last_info: dict[str, Any] = {}

    def reset(self) -> dm_env.TimeStep:
        obs, self.last_info = self.env.reset(seed=self._seed)
        self._seed = None
        self._need_reset = False
        return dm_env.restart(obs)

    def step(self, action: dict[str, Any]) -> dm_env.TimeStep:
        if self._need_reset:
            return self.reset()
        obs, reward, terminated, truncated, self.last_info = self.env.step(action)
        if terminated:
            self._need_reset = True
            return dm_env.termination(reward, obs)
        if truncated:
            self._need_reset = True
            return dm_env.truncation(reward, obs)
        return dm_env.transition(reward, obs)

    def observation_spec(self) -> dict[str, specs.Array]:
        return _spec(self.env.observation_space, "observation")

    def action_spec(self) -> dict[str, specs.Array]:
        return _spec(self.env.action_space, "action")

    def reward_spec(self) -> specs.Array:
        return specs.Array((), np.float64, name="reward")

    def close(self) -> None:
        self.env.close()
