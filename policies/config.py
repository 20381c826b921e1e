"""Typed, seeded, printable configuration of an exploration (several interactions on one hose).

    cfg = ExploreConfig.of(seed=0, grasps=3, flow="dis", width=320, height=240)
    print(cfg)                                   # JSON; ExploreConfig.from_dict(...) rebuilds it
    cfg.episode                                  # the EpisodeConfig every interaction uses

Each field has one owner: the exploration's own fields sit at the top, everything about the
simulated session (the seed, the hose of interest, the scene with its image size and hose
count, the interaction, the perturbation) in ``episode``.  The shortcuts of :meth:`of`,
:meth:`~cablesim.config.Config.with_values` and the command line (``seed``, ``hose``,
``width``, ``height``, ``hoses``, ``periods``, ``perturb``, ...) write into those nested fields
(:data:`EXPLORE_SHORTCUTS`).

``episode.scene.seed`` is the one seed (``cfg.seed`` reads it): it is the scene seed, and its
named streams (:mod:`cablesim.seeding`) draw the hose of interest (when ``episode.hose`` is
None) and the start segment (``episode``, exactly as
:func:`cablesim.sim.session.simulate_episode` does), the neighbour perturbation (``perturb``)
and the random-grasp baseline (``baseline``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from cablesim.config import Config, check_int, moved_fields
from cablesim.errors import ConfigError, InputError
from cablesim.perception.correlation import CorrelationParams
from cablesim.perception.flow import check_flow, reads_ground_truth
from cablesim.perception.grasp_sampler import GraspSamplerParams
from cablesim.perception.methods import check_method
from cablesim.perception.refine import DEFAULT_REFINE, GrowParams, RefineParams
from cablesim.perception.segmentation import SegmentationParams
from cablesim.sim.config import EPISODE_SHORTCUTS, EpisodeConfig

STRATEGIES = ("sampler", "random", "push")
MERGES = ("dis", "oracle", "none")


#: Shortcut -> the nested field it writes (``ExploreConfig.of``, the command-line flags).
EXPLORE_SHORTCUTS: Mapping[str, str] = {
    **{name: f"episode.{path}" for name, path in EPISODE_SHORTCUTS.items()},
    "hose": "episode.hose",
    "perturb": "episode.perturb",
}

#: Fields of the earlier layout (a top-level copy that overwrote the nested one) -> their place.
MOVED: Mapping[str, str] = {
    "seed": "episode.scene.seed",
    "hose": "episode.hose",
    "width": "episode.scene.camera.width",
    "height": "episode.scene.camera.height",
    "perturb": "episode.perturb",
}


#: Explore labels every 8th kept frame (``episode.interaction.capture.truth_every``): it reads
#: only the target frame's labels and one ground-truth flow example (the picture), and the
#: other frames' label passes and flows cost about 3 s of a 20 s interaction.  Its votes,
#: masks and metrics are those of every frame labelled: perception never reads the labels.
#: (The interaction's own default is the same since issue 21; explore keeps its own value.)
EXPLORE_TRUTH_EVERY = 8


def explore_episode() -> EpisodeConfig:
    """The episode an :class:`ExploreConfig` runs by default: the default one, with
    :data:`EXPLORE_TRUTH_EVERY`."""
    return EpisodeConfig().with_values({"interaction.capture.truth_every": EXPLORE_TRUTH_EVERY})


def check_truth_for_flow(flow: str, episode: EpisodeConfig) -> None:
    """``ConfigError`` naming ``episode.interaction.capture.truth_every`` unless it is 1 where
    the flow back end ``flow`` reads every frame's ground-truth flow (the oracle)."""
    every = episode.interaction.capture.truth_every
    if every != 1 and reads_ground_truth(flow):
        raise ConfigError(
            "episode.interaction.capture.truth_every",
            f"must be 1 with flow {flow!r}: it reads every frame's ground-truth flow, got {every}",
        )


def kind_of(strategy: str) -> str:
    """The interaction kind a strategy runs: ``push`` pokes, the others grasp."""
    return "push" if strategy == "push" else "grasp"


@dataclass(frozen=True)
class ExploreConfig(Config):
    """An exploration: start segment, then up to ``grasps`` interactions on the same hose.

    strategy: ``sampler`` (the thesis policy: grasp sampler on the merged votes),
    ``random`` (baseline: next grasp at a random voted pixel), ``push`` (pokes instead of
    grasps, next poke from the grasp sampler, motion segmentation by default); the
    interaction's ``episode.interaction.kind`` must be the strategy's (``push`` for ``push``,
    else ``grasp``): setting ``strategy`` through ``of``, ``with_values``, ``--set`` or
    ``--strategy`` sets both.
    method: ``correlation``, ``segmentation`` or ``ablation``; None = correlation for grasps,
    segmentation for pushes.
    merge: how votes of earlier interactions are carried into the latest target frame:
    ``dis`` (DIS flow between the two target frames, ground-truth free; the default whatever
    the flow back end), ``oracle`` (the simulator's exact flow between them, an explicit
    ablation through the evaluation module), ``none`` (added in place).
    """

    SHORTCUTS = EXPLORE_SHORTCUTS
    MOVED = {**MOVED, "episode.seed": "episode.scene.seed"}

    strategy: str = "sampler"
    grasps: int = 3  # successful interactions wanted
    max_attempts: int = 6  # interactions tried in total (failed ones included)
    method: str | None = None
    flow: str = "dis"
    merge: str = "dis"
    merged_votes: int = 1  # a pixel is in the merged mask with at least this many votes
    # keep the front-most part (depth) of a proposed segment (on a surface that faces the
    # camera: the board; cablesim.episode.surface.Surface.faces_camera)
    front_filter: bool = True
    # grow each mask along the target frame's colour (``cablesim.perception.refine.GrowParams``
    # colour, CIELAB distance); None: off (the default: it relies on distinctly coloured hoses)
    grow_colour: float | None = None
    random_tries: int = 30  # random baseline: voted pixels tried per proposal
    episode: EpisodeConfig = field(default_factory=explore_episode)
    sampler: GraspSamplerParams = field(default_factory=GraspSamplerParams)
    correlation: CorrelationParams = field(default_factory=CorrelationParams)
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)
    progress: bool = True  # print progress lines

    @property
    def seed(self) -> int:
        """The exploration's seed: ``episode.scene.seed``."""
        return self.episode.scene.seed

    @property
    def kind(self) -> str:
        return kind_of(self.strategy)

    @property
    def resolved_method(self) -> str:
        if self.method is not None:
            return self.method
        return "segmentation" if self.kind == "push" else "correlation"

    def refine(self) -> RefineParams:
        """The bleed remedies of the perception (``cablesim.perception.refine``): the default
        ones, with the colour growth when ``grow_colour`` is set."""
        if self.grow_colour is None:
            return DEFAULT_REFINE
        return dataclasses.replace(DEFAULT_REFINE, grow=GrowParams(colour=self.grow_colour))

    def _validate(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ConfigError("strategy", f"must be one of {STRATEGIES}, got {self.strategy!r}")
        for name, check in (("method", check_method), ("flow", check_flow)):
            value = getattr(self, name)
            try:  # a registered name (built-in or plug-in) or MODULE:CLASS
                if value is not None:
                    check(value)
            except InputError as e:
                raise ConfigError(name, str(e)) from None
        if self.merge not in MERGES:
            raise ConfigError("merge", f"must be one of {MERGES}, got {self.merge!r}")
        check_truth_for_flow(self.flow, self.episode)
        if not isinstance(self.grasps, int) or self.grasps < 1:
            raise ConfigError("grasps", f"must be an integer >= 1, got {self.grasps!r}")
        if self.max_attempts < self.grasps:
            raise ConfigError("max_attempts", f"must be >= grasps ({self.grasps})")
        if self.merged_votes < 1:
            raise ConfigError("merged_votes", "must be >= 1")
        if self.grow_colour is not None and not 0 < self.grow_colour <= 255:
            raise ConfigError("grow_colour", f"must be in (0, 255] or None, got {self.grow_colour}")
        check_int("max_attempts", self.max_attempts, 1, 100)
        check_int("random_tries", self.random_tries, 1)
        kind = self.episode.interaction.kind
        if kind != self.kind:
            raise ConfigError(
                "episode.interaction.kind",
                f"{kind!r} does not fit strategy {self.strategy!r}, which runs {self.kind!r} "
                "interactions (set both, e.g. ExploreConfig.of(strategy=...) or --strategy)",
            )

    @classmethod
    def _implied(cls, changes: dict[str, Any]) -> dict[str, Any]:
        """Setting ``strategy`` sets the interaction kind it runs, and setting ``flow`` to a
        back end that reads ground truth (the oracle) labels every frame
        (``episode.interaction.capture.truth_every`` 1), unless those are given."""
        if "strategy" in changes and "episode.interaction.kind" not in changes:
            changes = {**changes, "episode.interaction.kind": kind_of(str(changes["strategy"]))}
        every = "episode.interaction.capture.truth_every"
        flow = changes.get("flow")
        if isinstance(flow, str) and every not in changes:
            try:
                truth = reads_ground_truth(flow)
            except InputError:
                truth = False  # _validate names the unknown back end
            if truth:
                changes = {**changes, every: 1}
        return changes

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """The earlier layout kept ``seed``, ``hose``, ``width``, ``height`` and ``perturb`` at
        the top, and they overwrote ``episode``'s own when the run began (as did the
        strategy's interaction kind and ``progress=False``).  Such a file (its ``episode`` has
        a ``seed``) reruns as it ran; a file that mixes layouts is refused where the two
        places disagree (:func:`~cablesim.config.moved_fields`)."""
        if not any(name in data for name in MOVED):
            return data
        episode = data.get("episode")
        old = isinstance(episode, dict) and "seed" in episode
        if old:
            assert isinstance(episode, dict)
            episode = {k: v for k, v in episode.items() if k not in ("seed", "progress")}
            interaction = dict(episode.get("interaction", {}))
            interaction["kind"] = kind_of(str(data.get("strategy", "sampler")))
            episode["interaction"] = interaction
            data["episode"] = episode
        return moved_fields(data, path, MOVED, old_layout=old, null_keeps=("width", "height"))
