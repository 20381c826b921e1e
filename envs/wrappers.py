"""Wrappers that make ``cablesim/HoseExplore-v0`` usable by off-the-shelf RL libraries.

Stable-Baselines3 (2.9) refuses ``Dict`` action spaces (PPO and SAC), Gymnasium's
``flatten_space``/``unflatten`` of a ``Dict`` with a ``Discrete`` member turns continuous samples
into member 0, and SB3 treats an observation as an image (a CNN) only when it is uint8 in
[0, 255] with a channel axis; the raw ``HxW`` depth, votes and segment would go through an MLP.
So, in one line each::

    from cablesim.envs.wrappers import AimedBoxAction, BoxAction, ImageObservation
    env = ImageObservation(BoxAction(HoseExploreEnv(config)))         # Box action, image obs
    env = ImageObservation(AimedBoxAction(HoseExploreEnv(config)))    # residual around the aim

or ``gym.make("cablesim/HoseExploreBox-v0", config=..., aimed=True)`` (see
:mod:`cablesim.envs.box`), which applies exactly these.

**BoxAction**: ``Box(-1, 1, (4,), float32)`` = (primitive, u, v, angle):

- ``a[0] < 0``: grasp, ``a[0] >= 0``: push (a logit-like switch; a zero-mean Gaussian policy
  starts at an even mix);
- point = ((a[1] + 1) / 2, (a[2] + 1) / 2) in normalised image coordinates (u / width,
  v / height);
- angle = a[3] (the hose direction in units of pi/2, as in the ``Dict`` action).

**AimedBoxAction** (residual): the same ``Box(-1, 1, (4,))``, but relative to the aimed action
of the current observation (:func:`cablesim.envs.aim.aim_parameters`: the start segment's
centre and direction): the point moves ``along`` pixels * a[1] along the aimed direction and
``across`` pixels * a[2] across it (clipped to the image), the angle is aim + ``angle_scale`` *
a[3] (units of pi/2, wrapped into [-1, 1): -1 and 1 are the same direction), ``a[0]`` chooses
the primitive as above.  The zero action is an aimed grasp or push, so an agent earns rewards
from its first steps; what it learns is the primitive and how far to deviate from the aim.
The defaults (3 px along, 0.5 px across, 0.25 * pi/2 in angle) keep a unit-variance Gaussian
policy mostly on the hose, which is only 1-2 px wide in the fast configuration's 160x120
images: a point a pixel or two beside it lands on the board, where the grasp is refused as
unreachable (a cheap step) or closes on nothing (reward 0 either way).  Measured on 16 seeds
of the fast configuration: the zero residual grasp reached the hose in 13, a unit Gaussian
residual in 9 (``benchmarks/bench_env.py`` has the costs).

Values outside [-1, 1] are clipped; a wrong shape or a non-finite value raises
:class:`~cablesim.errors.InputError`.  Both add ``info["dict_action"]`` (the action that was
executed, as lists) to every step.

**ImageObservation**: ``Dict(image=Box(0, 255, (H, W, 6), uint8), gripper=Box((4,), float32))``
(``channels_first=True``: ``(6, H, W)``).  The six channels, all uint8 so that SB3's
``MultiInputPolicy`` gives ``image`` a CNN (it moves the channel axis first itself):

0-2. ``rgb``;
3. ``depth``: 0 = no valid depth, else ``1 + round(254 * (clip(d, lo, hi) - lo) / (hi - lo))``
   with ``depth_range = (lo, hi)`` metres (default (0.5, 1.5): the board is about 1 m from the
   camera; one level is about 3.9 mm);
4. ``votes``: ``min(255, votes * vote_step)`` (default ``vote_step`` 32: one level per merged
   vote, saturating at 8 votes);
5. ``segment``: 255 on the start segment, else 0.

``gripper`` stays float32 (TCP position in the camera frame in metres and finger opening).
The image space has the layout and bounds that SB3's ``is_image_space`` accepts.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from cablesim.errors import ConfigError, InputError

from .aim import aim_parameters
from .hose_explore import PRIMITIVES

#: The channels of ``ImageObservation``'s ``image``, in order.
IMAGE_CHANNELS = ("red", "green", "blue", "depth", "votes", "segment")
#: Box action layout: (primitive switch, u, v, angle), each in [-1, 1].
BOX_ACTION_FIELDS = ("primitive", "u", "v", "angle")


def _box_action(action: Any) -> np.ndarray:
    a = np.asarray(action, dtype=np.float64)
    if a.shape != (4,):
        raise InputError(f"action: expected shape (4,) {BOX_ACTION_FIELDS}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"action: values must be finite, got {a.tolist()}")
    return np.clip(a, -1.0, 1.0)


def _primitive(switch: float) -> int:
    """``a[0] < 0`` is a grasp (index 0), else a push (index 1)."""
    return PRIMITIVES.index("grasp") if switch < 0 else PRIMITIVES.index("push")


def _dict_action(primitive: int, u: float, v: float, angle: float) -> dict[str, Any]:
    return {
        "primitive": int(primitive),
        "point": np.clip(np.array([u, v], np.float32), 0.0, 1.0),
        "angle": np.array([angle], np.float32),
    }


def _listed(action: dict[str, Any]) -> dict[str, Any]:
    return {
        "primitive": PRIMITIVES[action["primitive"]],
        "point": [float(x) for x in action["point"]],
        "angle": float(action["angle"][0]),
    }


def _check_dict_env(env: gym.Env, who: str) -> None:
    space = env.action_space
    if not (isinstance(space, spaces.Dict) and {"primitive", "point", "angle"} <= set(space)):
        raise InputError(f"{who}: needs HoseExploreEnv's Dict action space, got {space}")


def _box_space() -> spaces.Box:
    return spaces.Box(-1.0, 1.0, (4,), np.float32)


class BoxAction(gym.ActionWrapper):
    """``Box(-1, 1, (4,))`` actions (primitive switch, u, v, angle); see the module docstring."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        _check_dict_env(env, "BoxAction")
        self.action_space = _box_space()

    def action(self, action: Any) -> dict[str, Any]:
        a = _box_action(action)
        return _dict_action(_primitive(a[0]), (a[1] + 1) / 2, (a[2] + 1) / 2, a[3])

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        act = self.action(action)
        obs, reward, terminated, truncated, info = self.env.step(act)
        return obs, reward, terminated, truncated, {**info, "dict_action": _listed(act)}


class AimedBoxAction(gym.Wrapper):
    """``Box(-1, 1, (4,))`` residual actions around the aimed action of the current
    observation; see the module docstring."""

    def __init__(
        self, env: gym.Env, along: float = 3.0, across: float = 0.5, angle_scale: float = 0.25
    ) -> None:
        super().__init__(env)
        _check_dict_env(env, "AimedBoxAction")
        for name, value in (("along", along), ("across", across), ("angle_scale", angle_scale)):
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not np.isfinite(value)
                or value < 0
            ):
                raise ConfigError(name, f"must be a finite number >= 0, got {value!r}")
        self.along, self.across = float(along), float(across)
        self.angle_scale = float(angle_scale)
        self.action_space = _box_space()
        self._last_obs: dict[str, np.ndarray] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._last_obs = obs
        return obs, info

    def action(self, action: Any) -> dict[str, Any]:
        """The ``Dict`` action that ``action`` stands for in the current observation."""
        if self._last_obs is None:
            raise InputError("AimedBoxAction: call reset() before step()")
        a = _box_action(action)
        aim = aim_parameters(self._last_obs)
        h, w = self._last_obs["segment"].shape[:2]
        t = aim.angle * np.pi / 2  # aimed direction in the image (u right, v down)
        du = self.along * a[1] * np.cos(t) - self.across * a[2] * np.sin(t)
        dv = self.along * a[1] * np.sin(t) + self.across * a[2] * np.cos(t)
        u, v = aim.u + du / w, aim.v + dv / h
        angle = (aim.angle + self.angle_scale * a[3] + 1.0) % 2.0 - 1.0
        return _dict_action(_primitive(a[0]), u, v, angle)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        act = self.action(action)
        obs, reward, terminated, truncated, info = self.env.step(act)
        self._last_obs = obs
        return obs, reward, terminated, truncated, {**info, "dict_action": _listed(act)}


class ImageObservation(gym.ObservationWrapper):
    """``Dict(image uint8 HxWx6, gripper float32 (4,))``; see the module docstring."""

    def __init__(
        self,
        env: gym.Env,
        depth_range: tuple[float, float] = (0.5, 1.5),
        vote_step: int = 32,
        channels_first: bool = False,
    ) -> None:
        super().__init__(env)
        space = env.observation_space
        need = {"rgb", "depth", "votes", "segment", "gripper"}
        if not (isinstance(space, spaces.Dict) and need <= set(space)):
            raise InputError(f"ImageObservation: needs HoseExploreEnv's observation, got {space}")
        lo, hi = (float(x) for x in depth_range)
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
            raise ConfigError("depth_range", f"need 0 <= lo < hi metres, got {depth_range!r}")
        if isinstance(vote_step, bool) or not isinstance(vote_step, int) or vote_step < 1:
            raise ConfigError("vote_step", f"must be an integer >= 1, got {vote_step!r}")
        self.depth_range = (lo, hi)
        self.vote_step = vote_step
        self.channels_first = bool(channels_first)
        h, w = space["rgb"].shape[:2]
        shape = (len(IMAGE_CHANNELS), h, w) if channels_first else (h, w, len(IMAGE_CHANNELS))
        self.observation_space = spaces.Dict(
            {"image": spaces.Box(0, 255, shape, np.uint8), "gripper": space["gripper"]}
        )

    def depth_to_uint8(self, depth: np.ndarray) -> np.ndarray:
        """Metres to the ``depth`` channel (0 = invalid; 1..255 over ``depth_range``)."""
        lo, hi = self.depth_range
        d = np.asarray(depth, np.float64)
        valid = np.isfinite(d) & (d > 0)
        scaled = 1.0 + np.rint(254.0 * (np.clip(np.where(valid, d, lo), lo, hi) - lo) / (hi - lo))
        return np.where(valid, scaled, 0).astype(np.uint8)

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        votes = np.minimum(observation["votes"].astype(np.int32) * self.vote_step, 255)
        image = np.concatenate(
            [
                observation["rgb"],
                self.depth_to_uint8(observation["depth"])[..., None],
                votes.astype(np.uint8)[..., None],
                np.where(observation["segment"] > 0, 255, 0).astype(np.uint8)[..., None],
            ],
            axis=-1,
        )
        if self.channels_first:
            image = np.ascontiguousarray(image.transpose(2, 0, 1))
        return {"image": image, "gripper": observation["gripper"].astype(np.float32)}
