"""``cablesim/HoseExploreBox-v0``: the hose environment with a ``Box`` action and image
observations (what Stable-Baselines3 and most RL libraries accept), and a fast configuration
for learning.

    import gymnasium as gym
    import cablesim.envs
    from cablesim.envs.box import fast_config
    env = gym.make("cablesim/HoseExploreBox-v0", config=fast_config(), aimed=True)

    from stable_baselines3 import PPO
    model = PPO("MultiInputPolicy", env, n_steps=16, batch_size=16)   # CNN on obs["image"]

``make_box_env`` (the registered entry point) is ``HoseExploreEnv`` wrapped in
:class:`~cablesim.envs.wrappers.BoxAction` (``aimed=False``) or
:class:`~cablesim.envs.wrappers.AimedBoxAction` (``aimed=True``: residual around the aimed
action, so rewards come from the first step), then
:class:`~cablesim.envs.wrappers.ImageObservation`.  Spaces, reward, truncation and ``info``
are those of ``cablesim/HoseExplore-v0`` plus ``info["dict_action"]``.

:func:`fast_config` is a configuration for learning: every step is still a full simulated
interaction (grasp or push, periodic action, release, retreat, settle, target frame,
segmentation), made cheaper: 2 hoses, 160x120 (smaller images leave too few hose pixels for a
start segment: hoses are about 1.6 px wide at 160x120), one action direction (along the hose)
of one period at 0.1 m/s, faster free motions (0.5 m/s travel, 0.1 m/s approach, retreat at
full joint speed), 10 frames/s, physics timestep 8 ms, two interactions per episode,
ground-truth flow for segmentation and DIS for carrying votes between images.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from cablesim.episode.config import (
    ActionConfig,
    CaptureConfig,
    GraspConfig,
    InteractionConfig,
    RetreatConfig,
)
from cablesim.sim.config import (
    CameraConfig,
    EpisodeConfig,
    HoseConfig,
    PhysicsConfig,
    SceneConfig,
)

from .hose_explore import HoseExploreConfig, HoseExploreEnv
from .wrappers import AimedBoxAction, BoxAction, ImageObservation

BOX_ENV_ID = "cablesim/HoseExploreBox-v0"


def fast_config(**changes: Any) -> HoseExploreConfig:
    """The fast learning configuration (module docstring); ``changes`` replace
    ``HoseExploreConfig`` fields or shortcuts (e.g. ``budget=1``, ``scene_seed=3``,
    ``hoses=3``), checked (an unknown name is a ``ConfigError`` naming it)."""
    interaction = InteractionConfig(
        grasp=GraspConfig(travel_speed=0.5, approach_speed=0.1),
        actions=ActionConfig(directions=("along",), periods=1, speed=0.1),
        capture=CaptureConfig(frame_rate=10.0, truth_every=1),  # the oracle flow reads it
        retreat=RetreatConfig(speed_factor=1.0),
    )
    scene = SceneConfig(
        seed=2,
        hoses=HoseConfig(count=2),
        camera=CameraConfig(width=160, height=120),
        physics=PhysicsConfig(timestep=0.008),
    )
    cfg = HoseExploreConfig(
        budget=2,
        flow="oracle",
        merge="dis",
        episode=EpisodeConfig(scene=scene, interaction=interaction),
    )
    return cfg.with_values(changes) if changes else cfg


def make_box_env(
    config: HoseExploreConfig | None = None,
    aimed: bool = False,
    along: float = 3.0,
    across: float = 0.5,
    angle_scale: float = 0.25,
    depth_range: tuple[float, float] = (0.5, 1.5),
    vote_step: int = 32,
    channels_first: bool = False,
    render_mode: str | None = None,
) -> gym.Env:
    """``HoseExploreEnv(config)`` with a ``Box(-1, 1, (4,))`` action (residual around the aim
    when ``aimed``) and the ``image``/``gripper`` observation (see
    :mod:`cablesim.envs.wrappers`).  ``config`` defaults to :func:`fast_config`."""
    env: gym.Env = HoseExploreEnv(config or fast_config(), render_mode=render_mode)
    env = AimedBoxAction(env, along, across, angle_scale) if aimed else BoxAction(env)
    return ImageObservation(env, depth_range, vote_step, channels_first)
