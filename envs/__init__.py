"""Gymnasium environments (and a ``dm_env`` adapter) of interactive hose perception.

Importing this package registers ``cablesim/HoseExplore-v0`` (see
:mod:`cablesim.envs.hose_explore` for the spaces, reward and termination)::

    import gymnasium as gym
    import cablesim.envs
    env = gym.make("cablesim/HoseExplore-v0", render_mode="rgb_array")

``cablesim.envs.dm.DmEnvAdapter`` exposes the same environment through ``dm_env``.

It also registers ``cablesim/HoseExploreBox-v0`` (:mod:`cablesim.envs.box`): the same
environment with a ``Box(-1, 1, (4,))`` action (optionally a residual around the aimed action,
``aimed=True``) and uint8 image observations with a channel axis, as Stable-Baselines3 needs;
the wrappers are in :mod:`cablesim.envs.wrappers`, the aimed action in :mod:`cablesim.envs.aim`
and a fast learning configuration is :func:`cablesim.envs.box.fast_config`::

    env = gym.make("cablesim/HoseExploreBox-v0", config=fast_config(), aimed=True)
"""

import gymnasium

from .aim import aim_at_segment, aim_parameters
from .box import BOX_ENV_ID, fast_config, make_box_env
from .hose_explore import PRIMITIVES, HoseExploreConfig, HoseExploreEnv
from .wrappers import AimedBoxAction, BoxAction, ImageObservation

ENV_ID = "cablesim/HoseExplore-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="cablesim.envs.hose_explore:HoseExploreEnv")
if BOX_ENV_ID not in gymnasium.registry:
    gymnasium.register(BOX_ENV_ID, entry_point="cablesim.envs.box:make_box_env")

__all__ = [
    "BOX_ENV_ID",
    "ENV_ID",
    "PRIMITIVES",
    "AimedBoxAction",
    "BoxAction",
    "HoseExploreConfig",
    "HoseExploreEnv",
    "ImageObservation",
    "aim_at_segment",
    "aim_parameters",
    "fast_config",
    "make_box_env",
]
