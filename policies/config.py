"""Typed, seeded, printable configuration of an exploration (several interactions on one hose).

    cfg = ExploreConfig(seed=0, grasps=3, flow="dis")
    print(cfg)                                   # JSON; ExploreConfig.from_dict(...) rebuilds it
    cfg.episode_config()                         # the EpisodeConfig every interaction uses

``seed`` is the one seed: it is the scene seed, and its named streams (:mod:`cablesim.seeding`)
draw the hose of interest (when ``hose`` is None) and the start segment (``episode``, exactly
as :func:`cablesim.sim.session.simulate_episode` does), the neighbour perturbation
(``perturb``) and the random-grasp baseline (``baseline``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from cablesim.config import Config, check_fields, check_int
from cablesim.errors import ConfigError, InputError
from cablesim.perception.correlation import CorrelationParams
from cablesim.perception.flow import check_flow
from cablesim.perception.grasp_sampler import GraspSamplerParams
from cablesim.perception.methods import check_method
from cablesim.perception.refine import DEFAULT_REFINE, GrowParams, RefineParams
from cablesim.perception.segmentation import SegmentationParams
from cablesim.sim.perturb import PerturbConfig
from cablesim.sim.session import EpisodeConfig

STRATEGIES = ("sampler", "random", "push")
FLOWS = ("dis", "oracle", "farneback", "raft")
MERGES = ("dis", "oracle", "none")


@dataclass
class ExploreConfig(Config):
    """An exploration: start segment, then up to ``grasps`` interactions on the same hose.

    strategy: ``sampler`` (the thesis policy: grasp sampler on the merged votes),
    ``random`` (baseline: next grasp at a random voted pixel), ``push`` (pokes instead of
    grasps, next poke from the grasp sampler, motion segmentation by default).
    method: ``correlation``, ``segmentation`` or ``ablation``; None = correlation for grasps,
    segmentation for pushes.
    merge: how votes of earlier interactions are carried into the latest target frame:
    ``dis`` (DIS flow between the two target frames, ground-truth free; the default whatever
    the flow back end), ``oracle`` (the simulator's exact flow between them, an explicit
    ablation through the evaluation module), ``none`` (added in place).
    """

    seed: int = 0
    hose: int | None = None
    strategy: str = "sampler"
    grasps: int = 3  # successful interactions wanted
    max_attempts: int = 6  # interactions tried in total (failed ones included)
    method: str | None = None
    flow: str = "dis"
    merge: str = "dis"
    merged_votes: int = 1  # a pixel is in the merged mask with at least this many votes
    front_filter: bool = True  # keep the front-most part (depth) of a proposed segment
    # grow each mask along the target frame's colour (``cablesim.perception.refine.GrowParams``
    # colour, CIELAB distance); None: off (the default: it relies on distinctly coloured hoses)
    grow_colour: float | None = None
    random_tries: int = 30  # random baseline: voted pixels tried per proposal
    width: int | None = None  # image size; None = the scene's camera (640x480)
    height: int | None = None
    perturb: PerturbConfig = field(default_factory=PerturbConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    sampler: GraspSamplerParams = field(default_factory=GraspSamplerParams)
    correlation: CorrelationParams = field(default_factory=CorrelationParams)
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)
    progress: bool = True

    @property
    def kind(self) -> str:
        return "push" if self.strategy == "push" else "grasp"

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

    def episode_config(self) -> EpisodeConfig:
        """The simulated session: the scene of ``seed`` at the chosen image size, the
        interaction of ``strategy`` and the perturbation."""
        ep = self.episode
        scene = dataclasses.replace(ep.scene, seed=self.seed)
        cam = dataclasses.replace(scene.camera)
        if self.width is not None:
            cam.width = self.width
        if self.height is not None:
            cam.height = self.height
        scene = dataclasses.replace(scene, camera=cam)
        interaction = dataclasses.replace(ep.interaction, kind=self.kind)
        return dataclasses.replace(
            ep,
            seed=self.seed,
            hose=self.hose,
            scene=scene,
            interaction=interaction,
            perturb=self.perturb,
            progress=False,
        )

    def validate(self) -> ExploreConfig:
        check_fields(self)
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError("seed", f"must be a non-negative integer, got {self.seed!r}")
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
        for name in ("width", "height"):
            if getattr(self, name) is not None:
                check_int(name, getattr(self, name), 16)
        self.perturb.validate()
        self.episode_config().validate()
        return self
