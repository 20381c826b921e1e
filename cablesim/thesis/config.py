"""The job description of ``cablesim benchmark thesis``: one typed config, turned into jobs.

    cfg = ThesisConfig(validation=(1000, 1008), test=(2000, 2012), workers=2)
    print(cfg)                       # JSON; ThesisConfig.from_dict(...) rebuilds it
    cfg.interaction_jobs()           # one job per scene and perturbation setting

The config is checked when it is made (``ConfigError`` naming the field) and frozen
(``replace`` / ``with_values`` make checked copies).

Scene ranges are seeds ``[A, B)``; validation and test must not overlap (SPEC section 7:
thresholds are tuned on validation, reported on test).  The defaults are the full protocol
(``docs/cluster_plan.md`` says what they cost); tests and quick looks shrink the ranges and the
image.  The same config runs locally (worker processes) or on a Ray cluster (``ray``) and gives
the same result files.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from cablesim.cables import DEFAULT_KIND, cable_kind, check_pattern
from cablesim.config import Config, to_dict
from cablesim.errors import ConfigError, InputError
from cablesim.jobs import Job
from cablesim.perception.flow import FLOW_BACKENDS
from cablesim.perception.methods import SEGMENTATION_METHODS
from cablesim.perception.metrics import BETAS
from cablesim.sim.config import SURFACES

#: the flow back ends the thesis's tables were made with (any spec of
#: :data:`~cablesim.perception.flow.FLOW_BACKENDS` may be given: a plug-in's name, or
#: ``MODULE:CLASS``; its rows are named after the spec)
FLOWS = ("oracle", "dis", "farneback")
#: the thesis's methods (tables 6.3-6.5); a user's method is added by its spec
METHODS = ("segmentation", "ablation", "correlation")
#: the published code's Farneback (``cablesim.formats.movingcables``) beside the registry's
CLIP_ONLY_FLOWS = ("farneback-movingcables",)
CLIP_FLOWS = ("farneback-movingcables", "farneback", "dis")
SPLITS = ("validation", "test")


def _check_specs(field_name: str, specs: tuple[str, ...], registry, extra=()) -> None:
    """``ConfigError`` naming the field unless every spec builds (all its required
    parameters given) and none repeats."""
    for spec in specs:
        if spec in extra:
            continue
        try:
            registry.check(spec, complete=True)
        except InputError as e:
            raise ConfigError(field_name, str(e)) from None
    seen = [s for i, s in enumerate(specs) if s in specs[:i]]
    if seen:
        raise ConfigError(field_name, f"{seen[0]!r} is given twice")


@dataclass(frozen=True)
class SceneSize(Config):
    """The simulated scene of every job (image size, hoses, action periods): what each job's
    ``EpisodeConfig`` is made of (:func:`cablesim.dataset.generate.scene_from`)."""

    SECTION = "scene"

    width: int = 640
    height: int = 480
    hoses: int = 4
    periods: int = 3  # K_p
    cable: str = DEFAULT_KIND  # the kind of every cable (cablesim.cables)
    pattern: str | None = None  # the surface pattern of every cable (None: the kind's)
    surface: str = "board"  # what holds the cables: board or table (SceneConfig.surface)

    def _validate(self) -> None:
        for name in ("width", "height", "hoses", "periods"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"scene.{name}", f"must be a positive integer, got {v!r}")
        cable_kind(self.cable, "scene.cable")
        if self.pattern is not None:
            check_pattern(self.pattern, "scene.pattern")
        if self.surface not in SURFACES:
            raise ConfigError(
                "scene.surface", f"unknown surface {self.surface!r}; choose one of {SURFACES}"
            )


@dataclass(frozen=True)
class ThesisConfig(Config):
    """``cablesim benchmark thesis``: tables 6.4/6.5, 6.8, 6.9 and chapter 5 in simulation."""

    validation: tuple[int, int] = (1000, 1050)  # seeds [A, B)
    test: tuple[int, int] = (2000, 2200)
    flows: tuple[str, ...] = ("oracle", "dis")  # ground truth and the default CPU flow
    methods: tuple[str, ...] = METHODS  # a user's method: its spec (MODULE:CLASS, a plug-in)
    perturb: tuple[bool, ...] = (True, False)  # neighbour perturbation on / off
    betas: tuple[float, ...] = BETAS
    action_thresholds: tuple[int, ...] = (1, 2)  # union (table 6.4), intersection (6.5)
    scene: SceneSize = field(default_factory=SceneSize)
    # tables 6.8 and 6.9: explorations of two grasps on the test scenes
    explore: bool = True
    explore_flow: str = "dis"
    explore_perturb: bool = True
    explore_grasps: int = 2
    # "tuned": motion correlation's thresholds tuned for beta 0.4 on validation with
    # ``explore_flow``; "thesis": the thesis's table 6.3 (c0 0.18, R^2 0.86)
    explore_thresholds: str = "tuned"
    # chapter 5: one hose moved by the gripper, nothing else moving, MovingCables protocol
    clips: bool = True
    clip_validation: tuple[int, int] = (3000, 3020)
    clip_test: tuple[int, int] = (4000, 4050)
    clip_flows: tuple[str, ...] = CLIP_FLOWS
    clip_taus: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 7.5, 10.0, 15.0, 20.0)
    clip_periods: int = 1
    cache_streams: bool = True  # record each interaction once; perception reruns from it
    workers: int = 2
    ray: str | None = None  # None: local processes; "auto", an address, or "local"
    out: str = "runs/thesis"

    def _validate(self) -> None:
        ranges = {
            "validation": self.validation,
            "test": self.test,
            "clip_validation": self.clip_validation,
            "clip_test": self.clip_test,
        }
        for name, r in ranges.items():
            if len(r) != 2 or not all(isinstance(x, int) for x in r) or not 0 <= r[0] < r[1]:
                raise ConfigError(name, f"must be seeds (A, B) with 0 <= A < B, got {r!r}")
        for a, b in (("validation", "test"), ("clip_validation", "clip_test")):
            ra, rb = ranges[a], ranges[b]
            if ra[0] < rb[1] and rb[0] < ra[1]:
                raise ConfigError(b, f"the {b} seeds {rb} overlap the {a} seeds {ra}")
        if not self.flows or not self.perturb:
            raise ConfigError("flows", "need at least one flow and one perturbation setting")
        _check_specs("flows", tuple(self.flows), FLOW_BACKENDS)
        _check_specs("explore_flow", (self.explore_flow,), FLOW_BACKENDS)
        _check_specs("clip_flows", tuple(self.clip_flows), FLOW_BACKENDS, CLIP_ONLY_FLOWS)
        if not self.methods:
            raise ConfigError("methods", "need at least one method (e.g. correlation)")
        _check_specs("methods", tuple(self.methods), SEGMENTATION_METHODS)
        for b in self.betas:
            if b not in BETAS:
                raise ConfigError("betas", f"{b} is not one of {BETAS}")
        if not self.action_thresholds or any(n not in (1, 2) for n in self.action_thresholds):
            raise ConfigError("action_thresholds", "each must be 1 (union) or 2 (intersection)")
        if self.explore_thresholds not in ("tuned", "thesis"):
            raise ConfigError("explore_thresholds", "must be 'tuned' or 'thesis'")
        if (
            self.explore
            and self.explore_thresholds == "tuned"
            and "correlation" not in self.methods
        ):
            raise ConfigError(
                "methods",
                "the explorations' thresholds are tuned for motion correlation: keep "
                "'correlation' among the methods or set explore_thresholds 'thesis'",
            )
        if (
            self.explore
            and self.explore_thresholds == "tuned"
            and self.explore_flow not in self.flows
        ):
            raise ConfigError(
                "explore_flow",
                f"thresholds for {self.explore_flow!r} are tuned only if it is "
                f"one of flows {self.flows}",
            )
        if not isinstance(self.explore_grasps, int) or self.explore_grasps < 1:
            raise ConfigError("explore_grasps", f"must be >= 1, got {self.explore_grasps!r}")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 0:
            raise ConfigError("workers", f"must be a non-negative integer, got {self.workers!r}")
        if not self.clip_taus or any(t <= 0 for t in self.clip_taus):
            raise ConfigError("clip_taus", "need positive motion thresholds")

    # ------------------------------------------------------------------ jobs
    def seeds(self, split: str) -> range:
        return range(*(self.validation if split == "validation" else self.test))

    def clip_seeds(self, split: str) -> range:
        return range(*(self.clip_validation if split == "validation" else self.clip_test))

    def _scene(self) -> dict:
        scene = to_dict(self.scene)
        if scene["cable"] == DEFAULT_KIND:  # the jobs of runs made before kinds existed
            del scene["cable"]
        if scene["pattern"] is None:  # ... and before patterns existed
            del scene["pattern"]
        if scene["surface"] == "board":  # ... and before the table existed
            del scene["surface"]
        return scene

    def interaction_jobs(self) -> list[Job]:
        """One job per scene of both splits and perturbation setting; every flow and method
        is computed in it from one simulated interaction."""
        jobs = []
        for split in SPLITS:
            for seed in self.seeds(split):
                for p in self.perturb:
                    params = {
                        "seed": seed,
                        "split": split,
                        "perturb": bool(p),
                        "scene": self._scene(),
                        "flows": list(self.flows),
                        "cache_streams": self.cache_streams,
                    }
                    if tuple(self.methods) != METHODS:  # the thesis's jobs keep their keys
                        params["methods"] = list(self.methods)
                    key = f"interaction-{_digest(params)}-s{seed:06d}-p{int(p)}"
                    jobs.append(Job("thesis.interaction", key, params))
        return jobs

    def exploration_jobs(self, c0_min: float, r2_min: float) -> list[Job]:
        """Two-grasp explorations of the test scenes with motion correlation's thresholds."""
        jobs = []
        for seed in self.seeds("test"):
            params = {
                "seed": seed,
                "scene": self._scene(),
                "flow": self.explore_flow,
                "perturb": self.explore_perturb,
                "grasps": self.explore_grasps,
                "c0_min": round(float(c0_min), 6),
                "r2_min": round(float(r2_min), 6),
            }
            jobs.append(Job("thesis.explore", f"explore-{_digest(params)}-s{seed:06d}", params))
        return jobs

    def clip_jobs(self) -> list[Job]:
        """MovingCables clips (one hose moved by the gripper) of both clip splits."""
        jobs = []
        for split in SPLITS:
            for seed in self.clip_seeds(split):
                params = {
                    "seed": seed,
                    "split": split,
                    "scene": self._scene(),
                    "periods": self.clip_periods,
                    "flows": list(self.clip_flows),
                    "taus": [float(t) for t in self.clip_taus],
                    "dataset": str(Path(self.out).resolve() / "movingcables"),
                }
                jobs.append(Job("thesis.clip", f"clip-{_digest(params)}-s{seed:06d}", params))
        return jobs


def _digest(params: dict) -> str:
    """Short hash of a job's parameters: a changed setting is a new job, not a stale result."""
    blob = json.dumps(params, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:8]
