"""``cablesim/HoseExploreBox-v0``: Box actions, image observations, the aimed action, the fast
configuration, and Stable-Baselines3 (PPO learns, SAC accepts it)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import cablesim  # noqa: F401  (headless GL before mujoco)
import cablesim.envs  # noqa: F401  (registers the environments)
from cablesim.envs import (
    BOX_ENV_ID,
    AimedBoxAction,
    BoxAction,
    HoseExploreConfig,
    HoseExploreEnv,
    ImageObservation,
    aim_at_segment,
    aim_parameters,
    fast_config,
    make_box_env,
)
from cablesim.errors import ConfigError, InputError

TINY = HoseExploreConfig.of(scene_seed=2, hoses=2, width=160, height=120, budget=2, periods=1)


# ---------------------------------------------------------------------- aim
def _line_mask(h: int, w: int, u0: float, v0: float, angle: float, half: int) -> np.ndarray:
    m = np.zeros((h, w), np.uint8)
    for t in np.linspace(-half, half, 4 * half + 1):
        m[int(round(v0 + t * math.sin(angle))), int(round(u0 + t * math.cos(angle)))] = 1
    return m


@pytest.mark.parametrize("deg", [0.0, 30.0, -60.0, 89.0])
def test_aim_follows_a_straight_segment(deg: float) -> None:
    mask = _line_mask(120, 160, 70, 50, math.radians(deg), 8)
    a = aim_parameters(mask)
    assert a.found
    assert a.u * 160 == pytest.approx(70.5, abs=1.0) and a.v * 120 == pytest.approx(50.5, abs=1.0)
    got = a.angle * 90.0
    diff = (got - deg + 90.0) % 180.0 - 90.0  # -90 and 90 degrees are one direction
    assert abs(diff) < 5.0 and -90.0 <= got < 90.0
    # the point is a pixel of the segment
    assert mask[int(a.v * 120), int(a.u * 160)]


def test_aim_stays_on_a_curved_segment_and_handles_empty() -> None:
    mask = np.zeros((120, 160), np.uint8)
    for t in np.linspace(0, math.pi, 200):  # a half circle: its centroid is off the arc
        mask[int(round(60 - 20 * math.sin(t))), int(round(80 + 20 * math.cos(t)))] = 1
    a = aim_parameters({"segment": mask})
    assert mask[int(a.v * 120), int(a.u * 160)]
    empty = aim_parameters(np.zeros((120, 160), np.uint8))
    assert not empty.found and (empty.u, empty.v, empty.angle) == (0.5, 0.5, 0.0)
    act = aim_at_segment(mask, "push")
    assert act["primitive"] == 1 and act["point"].dtype == np.float32
    with pytest.raises(InputError, match="primitive"):
        aim_at_segment(mask, "poke")
    with pytest.raises(InputError, match="segment"):
        aim_parameters(np.zeros((3, 4, 5)))


# ---------------------------------------------------------------------- wrappers
def test_box_action_maps_to_the_dict_action() -> None:
    env = BoxAction(HoseExploreEnv(TINY))
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
    d = env.action(np.array([-0.2, -1.0, 0.5, 0.3], np.float32))
    assert d["primitive"] == 0  # grasp
    np.testing.assert_allclose(d["point"], [0.0, 0.75])
    np.testing.assert_allclose(d["angle"], [0.3], rtol=1e-6)
    assert env.unwrapped.action_space.contains(d)
    assert env.action(np.array([0.0, 3.0, -3.0, 0.0]))["primitive"] == 1  # push; clipped
    np.testing.assert_allclose(env.action(np.array([0.5, 3.0, -3.0, 0.0]))["point"], [1.0, 0.0])
    with pytest.raises(InputError, match="shape"):
        env.action(np.zeros(3))
    with pytest.raises(InputError, match="finite"):
        env.action(np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(InputError, match="Dict action"):
        BoxAction(env)  # already a Box


def test_aimed_box_action_is_a_residual_around_the_aim() -> None:
    env = AimedBoxAction(HoseExploreEnv(TINY), along=4.0, across=1.0, angle_scale=0.5)
    with pytest.raises(InputError, match="reset"):
        env.action(np.zeros(4))
    seg = _line_mask(120, 160, 100, 40, math.radians(30), 6)
    env._last_obs = {"segment": seg}  # the observation the next action refers to
    aim = aim_parameters(seg)
    zero = env.action(np.zeros(4, np.float32))
    np.testing.assert_allclose(zero["point"], [aim.u, aim.v], atol=1e-6)
    assert zero["angle"][0] == pytest.approx(aim.angle, abs=1e-6) and zero["primitive"] == 1
    along = env.action(np.array([-1.0, 1.0, 0.0, 0.0]))
    du = (along["point"] - zero["point"]) * [160, 120]
    t = aim.angle * math.pi / 2
    np.testing.assert_allclose(du, [4 * math.cos(t), 4 * math.sin(t)], atol=1e-3)
    across = env.action(np.array([-1.0, 0.0, -1.0, 0.0]))
    dv = (across["point"] - zero["point"]) * [160, 120]
    np.testing.assert_allclose(dv, [math.sin(t), -math.cos(t)], atol=1e-3)
    turned = env.action(np.array([0.0, 0.0, 0.0, 1.0]))["angle"][0]
    assert turned == pytest.approx((aim.angle + 0.5 + 1) % 2 - 1, abs=1e-6)
    with pytest.raises(ConfigError, match="along"):
        AimedBoxAction(HoseExploreEnv(TINY), along=-1.0)


def test_image_observation_channels() -> None:
    from stable_baselines3.common.preprocessing import is_image_space

    env = ImageObservation(HoseExploreEnv(TINY), depth_range=(0.5, 1.5), vote_step=32)
    space = env.observation_space["image"]
    assert space.shape == (120, 160, 6) and space.dtype == np.uint8
    assert is_image_space(space)  # SB3 gives it a CNN
    rng = np.random.default_rng(0)
    depth = np.full((120, 160), 1.0, np.float32)
    depth[0, :4] = [0.0, np.nan, 0.2, 9.0]  # invalid, invalid, clipped low, clipped high
    votes = np.zeros((120, 160), np.uint8)
    votes[5, 5], votes[5, 6] = 1, 20
    seg = np.zeros((120, 160), np.uint8)
    seg[7, 7] = 1
    raw = {
        "rgb": rng.integers(0, 256, (120, 160, 3), dtype=np.uint8),
        "depth": depth,
        "votes": votes,
        "segment": seg,
        "gripper": np.array([0.1, 0.2, 0.9, 0.08], np.float32),
    }
    obs = env.observation(raw)
    assert env.observation_space.contains(obs)
    img = obs["image"]
    np.testing.assert_array_equal(img[..., :3], raw["rgb"])
    assert list(img[0, :4, 3]) == [0, 0, 1, 255] and img[10, 10, 3] == 1 + 127
    assert (img[5, 5, 4], img[5, 6, 4], img[0, 0, 4]) == (32, 255, 0)
    assert img[7, 7, 5] == 255 and img[..., 5].sum() == 255
    first = ImageObservation(HoseExploreEnv(TINY), channels_first=True)
    assert first.observation_space["image"].shape == (6, 120, 160)
    np.testing.assert_array_equal(first.observation(raw)["image"], img.transpose(2, 0, 1))
    with pytest.raises(ConfigError, match="depth_range"):
        ImageObservation(HoseExploreEnv(TINY), depth_range=(1.5, 0.5))


def test_fast_config() -> None:
    cfg = fast_config(budget=1)
    ep = cfg.episode_config(7)
    scene = cfg.episode.scene
    assert (scene.hoses.count, scene.camera.width, scene.camera.height) == (2, 160, 120)
    assert (cfg.episode.interaction.actions.periods, cfg.budget, scene.seed) == (1, 1, 2)
    assert ep.seed == 7 and ep.replace(seed=2) == cfg.episode  # only the episode seed differs
    assert ep.scene.physics.timestep == 0.008 and ep.interaction.actions.directions == ("along",)
    assert ep.interaction.capture.frame_rate == 10.0
    assert fast_config(scene_seed=5, hoses=3).episode.scene.hoses.count == 3
    with pytest.raises(ConfigError, match="bugdet"):
        fast_config(bugdet=1)
    # the oracle flow reads every frame's ground truth: labelling fewer frames is refused
    every = "episode.interaction.capture.truth_every"
    with pytest.raises(ConfigError, match="oracle") as err:
        fast_config().with_values({every: 4})
    assert err.value.field == every
    assert fast_config().with_values({"flow": "dis", every: 4}).flow == "dis"


# ---------------------------------------------------------------------- the environment
@pytest.mark.filterwarnings("ignore:.*is different from the unwrapped version")
def test_registered_box_env_passes_the_checkers() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    aimed = gym.make(BOX_ENV_ID, config=TINY, aimed=True, along=2.0)
    assert isinstance(aimed.unwrapped, HoseExploreEnv)
    layer, layers = aimed, []
    while layer is not aimed.unwrapped:
        layers.append(layer)
        layer = layer.env
    residual = [w for w in layers if isinstance(w, AimedBoxAction)]
    assert len(residual) == 1 and residual[0].along == 2.0
    assert isinstance(layers[layers.index(residual[0]) - 1], ImageObservation)
    # the checkers step with uniform random actions: on the plain Box action those are
    # mostly refused at once (unreachable), so this stays cheap
    env = gym.make(BOX_ENV_ID, config=fast_config())  # budget 2: check_env wants > 1 step
    try:
        assert env.action_space == gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        assert set(env.observation_space) == {"image", "gripper"}
        assert env.observation_space["image"].shape == (120, 160, 6)
        check_env(env.env.env)  # gymnasium's checker on the wrappers, not gym.make's own ones
        sb3_check_env(env, warn=False)
    finally:
        env.close()


@pytest.mark.slow
def test_aimed_zero_action_reaches_the_hose() -> None:
    """The zero residual is the aimed grasp: it earns a reward on the first step, which the
    raw environment's random actions almost never do."""
    env = make_box_env(fast_config(budget=1), aimed=True)
    try:
        obs, _ = env.reset(seed=3)
        assert obs["image"][..., 5].any()
        obs, reward, terminated, truncated, info = env.step(np.array([-1, 0, 0, 0], np.float32))
        assert info["success"], info["reason"]
        assert reward > 0.2 and info["dict_action"]["primitive"] == "grasp"
        assert truncated and not terminated
        assert obs["image"][..., 4].any()  # the merged votes are in the observation
    finally:
        env.close()


# ---------------------------------------------------------------------- Stable-Baselines3
@pytest.mark.slow
def test_sb3_ppo_learns_to_grasp_on_the_box_env(tmp_path) -> None:
    """The shipped example (``python -m cablesim.envs.train_ppo``): PPO (MultiInputPolicy, a
    CNN on the image) trains on the Box variant (fast configuration, aimed residual actions,
    one interaction per episode) for 32 steps (two updates of 16) and then beats a random
    policy on four held-out seeds, having moved its primitive switch towards grasping (pushes
    earn nothing in this configuration)."""
    import json

    import torch

    from cablesim.envs.train_ppo import main

    threads = torch.get_num_threads()
    try:
        argv = ["--steps", "32", "--n-steps", "16", "--seed", "0", "--torch-threads", "1"]
        assert main([*argv, "--eval-seeds", "1000,1001,1002,1003", "--out", str(tmp_path)]) == 0
    finally:
        torch.set_num_threads(threads)
    run = json.loads((tmp_path / "ppo.json").read_text())
    assert run["steps"] == 32 and len(run["train_episode_returns"]) > 0
    before, after = run["switch_before"], run["switch_after"]
    assert np.mean(after) < np.mean(before) - 0.05  # moved towards grasping (measured -0.11)
    assert all(s < 0 for s in after)  # the deterministic policy grasps
    assert run["trained_mean"] > run["random_mean"]
    assert run["trained_mean"] > 0.3


@pytest.mark.slow
def test_sb3_sac_accepts_the_box_env() -> None:
    """SAC (which also refuses the Dict action) takes the Box variant with a CNN and a replay
    buffer sized by the user (see the README for the bytes per transition)."""
    from stable_baselines3 import SAC
    from stable_baselines3.common.torch_layers import NatureCNN

    env = make_box_env(fast_config(budget=1))
    try:
        model = SAC("MultiInputPolicy", env, buffer_size=8, learning_starts=2, batch_size=2, seed=0)
        assert isinstance(model.policy.actor.features_extractor.extractors["image"], NatureCNN)
        model.learn(total_timesteps=3)
        assert model.num_timesteps == 3 and model.replay_buffer.size() == 3
    finally:
        env.close()
