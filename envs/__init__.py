"""Gymnasium environments (and a ``dm_env`` adapter) of interactive hose perception.

Importing this package registers ``cablesim/HoseExplore-v0`` (see
:mod:`cablesim.envs.hose_explore` for the spaces, reward and termination)::

    import gymnasium as gym
    import cablesim.envs
    env = gym.make("cablesim/HoseExplore-v0", render_mode="rgb_array")

``cablesim.envs.dm.DmEnvAdapter`` exposes the same environment through ``dm_env``.
"""

import gymnasium

from .hose_explore import PRIMITIVES, HoseExploreConfig, HoseExploreEnv

ENV_ID = "cablesim/HoseExplore-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="cablesim.envs.hose_explore:HoseExploreEnv")

__all__ = ["ENV_ID", "PRIMITIVES", "HoseExploreConfig", "HoseExploreEnv"]
