"""``cablesim/HoseExplore-v0``: interactive perception of one hose as a Gymnasium environment.

    import gymnasium as gym
    import cablesim.envs  # registers the environment
    env = gym.make("cablesim/HoseExplore-v0", config=HoseExploreConfig.of(width=160, height=120))
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

Each episode is a simulated session (:class:`~cablesim.sim.session.SimSession`): the scene
``config.episode.scene`` (its seed, the shortcut ``scene_seed``, is fixed;
``randomize_scene=True`` uses the episode seed as scene seed instead) is reset to its settled
state; an episode seed drawn from the reset seed names the
random streams (:mod:`cablesim.seeding`) that draw the hose of interest and a visible,
graspable start segment of it (the stand-in for a person's click, given to the agent as
``obs["segment"]``) and the neighbour perturbation.  Every step is one interaction.

**Action** ``Dict``:

- ``primitive``: ``Discrete(2)``: 0 = grasp and move periodically (two actions, along and across
  the hose), 1 = push (poke) with the closed gripper;
- ``point``: ``Box(0, 1, (2,), float32)``: where, in normalised image coordinates
  (u / width, v / height) of the current image;
- ``angle``: ``Box(-1, 1, (1,), float32)``: the hose's direction in the image at that point,
  in units of pi/2 (``angle * pi/2`` radians from the image x axis, y down; -1 and 1 are the
  same direction); the fingers close across it.

An action that is not such a dict (a missing key, a primitive other than 0 or 1, a point or
angle that is not finite) raises ``InputError`` naming the key and the value; finite points
outside [0, 1] are clipped to the image.  The config is checked when it is made
(``ConfigError`` naming the field); configs are frozen, and ``reset`` refuses a config whose
image size is not the one the environment was made with.

The point and angle become a short line segment (``segment_length`` metres at the point's
depth), from which the episode runner estimates the grasp centre and axis from depth (SPEC 3.1).

**Observation** ``Dict`` (H x W = ``episode.scene.camera.height`` x ``.width``):

- ``rgb``: uint8 (H, W, 3), the current image (the last target frame);
- ``depth``: float32 (H, W), metres, 0 = invalid, clipped to [0, 10];
- ``votes``: uint8 (H, W), merged votes for the hose of interest so far, in the current image
  (each successful interaction adds up to one vote per action; earlier votes are carried into
  the latest target frame as in :mod:`cablesim.policies.merge`, with DIS flow by default or,
  with ``merge="oracle"``, the simulator's exact flow);
- ``segment``: uint8 (H, W), the start segment (1 on it), carried along like the votes;
- ``gripper``: float32 (4,), TCP position in the camera frame (m) and finger opening (m).

**Reward**: the gain in F_0.4 of the merged mask (``votes >= merged_votes``) of the hose of
interest against ground truth, current image (so a failed or useless interaction gives 0 or a
negative reward when the scene moved); computed by :mod:`cablesim.evaluation`, the only place
the environment reads ground truth.  **Truncation** after ``budget`` interactions;
**termination** only where the physics blew up in an interaction (``info["outcome"] ==
"diverged"``, reward 0, the last observation; a rare hose tear, seen at the fast config's 8 ms
step), after which ``step`` asks for a reset.  ``info``: ``hose``, ``success``, ``reason``,
``interactions``, ``merged`` (precision, recall, f0.4, iou, pixels) and, after a successful
interaction, ``scores`` (its own mask in its own target frame).  ``info`` holds no timings,
so a seeded episode reproduces it exactly.

``render_mode="rgb_array"``: the current image with the merged votes in green and the start
segment in magenta.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from cablesim.config import Config, check_int, check_number, moved_fields, to_dict
from cablesim.errors import (
    CablesimError,
    ConfigError,
    InputError,
    PhysicsDivergedError,
    UnreachableError,
)
from cablesim.evaluation import f04_reward
from cablesim.outcomes import Outcome
from cablesim.perception.flow import DISFlow
from cablesim.perception.geometry import line_segment_mask
from cablesim.perception.pipeline import segment_stream
from cablesim.policies.config import check_truth_for_flow
from cablesim.policies.merge import VoteMerger, warp_votes
from cablesim.sim.config import EPISODE_SHORTCUTS, EpisodeConfig
from cablesim.sim.session import SimSession
from cablesim.sim.world import World
from cablesim.viz import overlay_votes

PRIMITIVES = ("grasp", "push")
FLOWS = ("oracle", "dis", "farneback")  # RAFT needs a checkpoint: not offered here
MERGES = ("dis", "oracle", "none")
METHODS = ("correlation", "segmentation", "ablation")


#: Shortcut -> the nested field it writes (``HoseExploreConfig.of(width=320, hoses=2)``).
ENV_SHORTCUTS: Mapping[str, str] = {
    **{name: f"episode.{path}" for name, path in EPISODE_SHORTCUTS.items() if name != "seed"},
    "scene_seed": "episode.scene.seed",
    "hose": "episode.hose",
    "perturb": "episode.perturb",
}

#: Fields of the earlier layout (they overwrote ``episode``'s own) -> their place now.
MOVED: Mapping[str, str] = {
    "scene_seed": "episode.scene.seed",
    "hoses": "episode.scene.hoses.count",
    "width": "episode.scene.camera.width",
    "height": "episode.scene.camera.height",
    "periods": "episode.interaction.actions.periods",
    "hose": "episode.hose",
    "perturb": "episode.perturb",
}

#: The largest scene seed (reset draws episode seeds below 2**31 - 1).
MAX_SCENE_SEED = 2**31 - 2


def default_episode() -> EpisodeConfig:
    """The environment's session: 160x120 images and actions of 2 periods (the thesis uses
    3; 2 keeps steps short), 4 hoses, scene seed 0, every frame labelled (the default flow,
    the oracle, reads each frame's ground-truth flow)."""
    return EpisodeConfig.of(width=160, height=120, periods=2, truth_every=1)


@dataclass(frozen=True)
class HoseExploreConfig(Config):
    """Budget and perception of :class:`HoseExploreEnv`, and its session (``episode``: the
    scene with its seed, image size and hose count, the hose of interest, the interaction,
    the perturbation).  ``HoseExploreConfig.of(scene_seed=2, hoses=2, width=160, height=120,
    periods=1, budget=2)`` writes the shortcuts (:data:`ENV_SHORTCUTS`) into ``episode``."""

    SHORTCUTS = ENV_SHORTCUTS
    MOVED = MOVED

    randomize_scene: bool = False  # True: the episode seed is the scene seed (slower resets)
    budget: int = 3  # interactions per episode
    flow: str = "oracle"  # "oracle" | "dis" | "farneback"; small images favour the oracle
    merge: str = "dis"  # how votes are carried between images: "dis" | "oracle" | "none"
    grasp_method: str = "correlation"
    push_method: str = "segmentation"
    merged_votes: int = 1
    segment_length: float = 0.04  # m, the line segment made from (point, angle)
    episode: EpisodeConfig = field(default_factory=default_episode)

    def episode_config(self, seed: int) -> EpisodeConfig:
        """The session of an episode: ``episode`` with the episode seed ``seed`` naming its
        random streams (the world, built from ``episode.scene``, is reused)."""
        return self.episode.replace(scene=self.episode.scene.replace(seed=seed))

    def _validate(self) -> None:
        check_int("episode.scene.seed", self.episode.scene.seed, 0, MAX_SCENE_SEED)
        check_int("budget", self.budget, 1, 10_000)
        check_int("merged_votes", self.merged_votes, 1)
        for name, value, choices in (
            ("flow", self.flow, FLOWS),
            ("merge", self.merge, MERGES),
            ("grasp_method", self.grasp_method, METHODS),
            ("push_method", self.push_method, METHODS),
        ):
            if value not in choices:
                raise ConfigError(name, f"must be one of {choices}, got {value!r}")
        check_number("segment_length", self.segment_length, 1e-3, 0.5)
        check_truth_for_flow(self.flow, self.episode)

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """The earlier layout kept the scene seed, hose count, image size, periods, hose of
        interest and perturbation at the top; they overwrote ``episode``'s own at every reset.
        Such a file (its ``episode`` has a ``seed``) loads as it ran; a file that mixes
        layouts is refused where the two places disagree."""
        if not any(name in data for name in MOVED):
            return data
        episode = data.get("episode")
        old = isinstance(episode, dict) and "seed" in episode
        if old:
            assert isinstance(episode, dict)
            data["episode"] = {k: v for k, v in episode.items() if k not in ("seed", "progress")}
        elif episode is None:  # the old defaults were the environment's: start from them
            data["episode"] = default_episode().to_dict()
        return moved_fields(data, path, MOVED, old_layout=old)


def check_action(action: Any) -> tuple[int, np.ndarray, float]:
    """(primitive, point, angle) of an action dict, or ``InputError`` naming the key."""
    if not isinstance(action, Mapping):
        raise InputError(f"the action must be a dict, got {type(action).__name__}")
    missing = [k for k in ("primitive", "point", "angle") if k not in action]
    if missing:
        raise InputError(f"the action lacks {missing} (keys: primitive, point, angle)")
    p = action["primitive"]
    p = p.item() if isinstance(p, np.ndarray) and p.size == 1 else p
    if isinstance(p, bool | np.bool_) or not isinstance(p, int | np.integer):
        raise InputError(f"action primitive must be 0 (grasp) or 1 (push), got {p!r}")
    if not 0 <= int(p) < len(PRIMITIVES):
        raise InputError(f"action primitive must be 0 (grasp) or 1 (push), got {int(p)}")
    values = {}
    for key, n in (("point", 2), ("angle", 1)):
        try:
            v = np.asarray(action[key], dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as e:
            raise InputError(f"action {key} must be {n} number(s), got {action[key]!r}") from e
        if v.size != n:
            raise InputError(f"action {key} must be {n} number(s), got {v.size}")
        if not np.all(np.isfinite(v)):
            raise InputError(f"action {key} must be finite, got {v.tolist()}")
        values[key] = v
    return int(p), values["point"], float(values["angle"][0])


class HoseExploreEnv(gym.Env):
    """See the module docstring."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self, config: HoseExploreConfig | None = None, render_mode: str | None = None
    ) -> None:
        self.config = config or HoseExploreConfig()
        if not isinstance(self.config, HoseExploreConfig):
            raise ConfigError("config", f"expected a HoseExploreConfig, got {self.config!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                "render_mode",
                f"must be one of {self.metadata['render_modes']}, got {render_mode!r}",
            )
        self.render_mode = render_mode
        cam = self.config.episode.scene.camera
        h, w = cam.height, cam.width
        self.action_space = spaces.Dict(
            {
                "primitive": spaces.Discrete(2),
                "point": spaces.Box(0.0, 1.0, (2,), np.float32),
                "angle": spaces.Box(-1.0, 1.0, (1,), np.float32),
            }
        )
        self.observation_space = spaces.Dict(
            {
                "rgb": spaces.Box(0, 255, (h, w, 3), np.uint8),
                "depth": spaces.Box(0.0, 10.0, (h, w), np.float32),
                "votes": spaces.Box(0, 255, (h, w), np.uint8),
                "segment": spaces.Box(0, 1, (h, w), np.uint8),
                "gripper": spaces.Box(-10.0, 10.0, (4,), np.float32),
            }
        )
        self._world: Any = None  # the scene, built once per scene seed
        self._world_seed: int | None = None
        self._camera: Any = None
        self._session: Any = None
        self._evaluator: Any = None
        self._merger: Any = None
        self._segment: np.ndarray | None = None
        self._image: Any = None
        self._merged: dict[str, float] = {}
        self._count = 0
        self._ended = ""  # why the last episode ended early (step() then asks for a reset)
        self._last_obs: dict[str, np.ndarray] = {}
        self._prev_snap: Any = None
        self._dis: Any = None

    # ------------------------------------------------------------------ set-up
    def _scene(self, scene_seed: int) -> tuple[Any, Any]:
        """The world (and camera) of ``scene_seed``, built once and reused across resets."""

        if self._world is None or self._world_seed != scene_seed:
            if self._camera is not None:
                self._camera.close()
                self._camera = None
            self._world = World.build(self.config.episode.scene.replace(seed=scene_seed))
            self._world_seed = scene_seed
        return self._world, self._camera

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:

        if seed is not None and (not isinstance(seed, int | np.integer) or seed < 0):
            raise InputError(f"reset seed must be None or an integer >= 0, got {seed!r}")
        cfg = self.config
        if not isinstance(cfg, HoseExploreConfig):
            raise ConfigError("config", f"expected a HoseExploreConfig, got {cfg!r}")
        cam = cfg.episode.scene.camera
        if (cam.height, cam.width) != self.observation_space["rgb"].shape[:2]:
            raise ConfigError(
                "episode.scene.camera.width/height",
                f"{cam.width}x{cam.height} differs from the observation space the environment "
                "was made with; make a new environment",
            )
        super().reset(seed=None if seed is None else int(seed))
        episode_seed = int(self.np_random.integers(2**31 - 1))
        scene_seed = episode_seed if cfg.randomize_scene else cfg.episode.scene.seed
        world, camera = self._scene(scene_seed)
        # a reused world: the session's seed names only the episode's random streams
        session = SimSession.build(cfg.episode_config(episode_seed), world=world, camera=camera)
        self._session, self._camera = session, session.camera
        n = len(world.hoses)
        hose = cfg.episode.hose
        order = [hose] if hose is not None else list(session.rng.permutation(n))
        picked, reasons = None, []
        for hose in order:
            try:
                picked = session.pick_start(int(hose))
                break
            except UnreachableError as e:
                reasons.append(str(e))
        if picked is None:
            raise CablesimError("no hose has a graspable start segment: " + "; ".join(reasons))
        self._evaluator = session.evaluator()
        self._segment = picked.mask.astype(np.int16)
        self._merger = VoteMerger(None)  # flows are passed explicitly
        self._prev_snap = self._evaluator.snapshot() if cfg.merge == "oracle" else None
        self._dis = DISFlow()
        self._count, self._ended = 0, ""
        self._image = session.capture()
        self._merged = self._merged_scores()
        info = {"hose": session.hose, "interactions": 0, "merged": self._merged}
        return self._obs(), info

    # ------------------------------------------------------------------ step
    def step(
        self, action: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:

        if self._session is None:
            raise CablesimError(
                f"{self._ended}; call reset()"
                if self._ended
                else "call reset() before step() (and again after close())"
            )
        index, point, angle = check_action(action)
        cfg, session = self.config, self._session
        primitive = PRIMITIVES[index]
        segment = self._line_segment(point, angle)
        info: dict[str, Any] = {"hose": session.hose, "primitive": primitive}
        interaction = session.interaction_config().replace(kind=primitive)
        if segment is None:
            ok, reason, stream = False, "no valid depth at the point", None
        else:
            try:
                r = session.interact(segment, interaction)
            except PhysicsDivergedError as e:
                return self._diverged(e, info)
            ok, reason, stream = r.success, r.reason, r.stream
        self._count += 1
        scores: dict[str, float] | None = None
        now = session.capture()
        flow = self._flow_to_previous(now.rgb)
        if flow is not None:
            self._segment = warp_votes(self._segment, flow)
        if ok and stream is not None:
            method = cfg.grasp_method if primitive == "grasp" else cfg.push_method
            seg = segment_stream(stream, method=method, flow=cfg.flow, pipelined=False)
            self._merger.add(now.rgb, seg.votes, flow)
            scores = self._evaluator.score(seg.mask(1), self._evaluator.stream_truth(stream))
        else:
            self._merger.retarget(now.rgb, flow)
        self._image = now
        merged = self._merged_scores()
        reward = f04_reward(self._merged, merged)
        self._merged = merged
        info.update(success=bool(ok), reason=reason, interactions=self._count, merged=merged)
        if scores is not None:
            info["scores"] = scores
        truncated = self._count >= cfg.budget
        return self._obs(), reward, False, truncated, info

    def _diverged(
        self, error: PhysicsDivergedError, info: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """The physics blew up in the interaction (a rare hose tear at the fast config's 8 ms
        step, seen once in a random action of ``check_env``): the episode ends there
        (terminated, reward 0, the last observation) with the named outcome ``diverged``; the
        world is dropped, so the next reset builds the scene again."""
        self._count += 1
        obs = self._last_obs  # the last step's: the state the physics left is not shown
        self.close()  # the next reset builds the scene again
        self._ended = f"the episode ended: {Outcome.DIVERGED.value}: {error}"
        info.update(
            success=False,
            reason=str(error),
            outcome=Outcome.DIVERGED.value,
            interactions=self._count,
            merged=self._merged,
        )
        return obs, 0.0, True, False, info

    # ------------------------------------------------------------------ helpers
    def _line_segment(self, point: np.ndarray, angle: float) -> np.ndarray | None:

        cam = self.config.episode.scene.camera
        h, w = cam.height, cam.width
        pt = np.clip(point, 0.0, 1.0)
        img = self._image
        return line_segment_mask(
            img.depth,
            img.intrinsics,
            pt[0] * w,
            pt[1] * h,
            angle * math.pi / 2,
            self.config.segment_length,
        )

    def _flow_to_previous(self, new_rgb: np.ndarray) -> np.ndarray | None:
        """Flow from the new image to the previous one (new(p) = previous(p + f)): DIS
        (ground-truth free) by default, the simulator's exact flow with ``merge="oracle"``,
        none with ``merge="none"``."""
        if self.config.merge == "none":
            return None
        if self.config.merge != "oracle":
            return self._dis.compute(new_rgb, self._image.rgb)
        snap = self._evaluator.snapshot()
        prev, self._prev_snap = self._prev_snap, snap
        return self._evaluator.flow_between(snap, prev)

    def _merged_scores(self) -> dict[str, float]:
        ev = self._evaluator
        if self._merger is None or self._merger.votes is None:
            truth = ev.current_mask()
            return ev.score(np.zeros_like(truth), truth)
        return ev.score(self._merger.mask(self.config.merged_votes))

    def _obs(self) -> dict[str, np.ndarray]:
        img = self._image
        depth = np.clip(np.nan_to_num(img.depth, nan=0.0), 0.0, 10.0).astype(np.float32)
        votes = self._merger.votes if self._merger.votes is not None else None
        h, w = depth.shape
        v = np.zeros((h, w), np.uint8) if votes is None else np.clip(votes, 0, 255).astype(np.uint8)
        robot = self._session.robot
        pos_cam = robot.ee_pose_camera().position
        grip = np.array([*pos_cam, robot.gripper_opening], np.float32)
        self._last_obs = {
            "rgb": img.rgb.copy(),
            "depth": depth,
            "votes": v,
            "segment": (self._segment > 0).astype(np.uint8),
            "gripper": np.clip(grip, -10.0, 10.0),
        }
        return {k: a.copy() for k, a in self._last_obs.items()}

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self._image is None:
            return None

        votes = self._merger.votes if self._merger.votes is not None else None
        img = self._image.rgb if votes is None else overlay_votes(self._image.rgb, votes)
        img = img.copy()
        img[self._segment > 0] = (255, 0, 255)
        return img

    def close(self) -> None:
        if self._camera is not None:
            self._camera.close()
            self._camera = None
        self._session = None
        self._world = None  # a later reset builds the scene (and its camera) again
        self._world_seed = None

    def config_dict(self) -> dict[str, Any]:
        return to_dict(self.config)
