"""Randomised scenes for datasets: background, hose count and colours, lighting and camera pose
drawn from the seed's ``dataset`` stream, the cable kinds from its ``dataset_kinds`` stream,
the cables' surface patterns from its ``dataset_patterns`` stream and whether they all wear one
colour from its ``dataset_same_colour`` stream (so a scene depends on its seed alone).

    scene = randomize_scene(1234, SceneConfig(), Randomization())
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

from cablesim.cables import DEFAULT_KIND, cable_kind, check_pattern
from cablesim.config import Config, check_positive
from cablesim.errors import ConfigError
from cablesim.seeding import stream
from cablesim.sim.config import BACKGROUNDS, MAX_HOSES, SceneConfig


@dataclass(frozen=True)
class Randomization(Config):
    """What :func:`randomize_scene` draws per scene (checked when made)."""

    backgrounds: tuple[str, ...] = BACKGROUNDS
    hoses: tuple[int, int] = (2, 6)  # inclusive range of hose counts
    random_colours: float = 0.5  # share of scenes with random (HSV) hose colours
    # share of scenes whose cables all wear one colour (``hoses.same_colour``): a tangle of
    # identical cables; 0 keeps the scenes of datasets made before it
    same_colour: float = 0.0
    light_jitter: float = 0.3  # LightConfig.jitter
    camera_position_jitter: float = 0.02  # metres, CameraConfig.position_jitter
    camera_look_at_jitter: float = 0.03
    # the kind of each cable, drawn uniformly per cable from these (one: every cable of it);
    # ``cablesim dataset`` draws from every kind unless ``--cable`` names one, the default
    # here keeps the jobs of datasets made before kinds existed what they were
    cable_kinds: tuple[str, ...] = (DEFAULT_KIND,)
    # the surface pattern of each cable, drawn uniformly per cable from these (empty: each
    # cable wears its kind's; ``cablesim dataset`` draws from every pattern unless
    # ``--pattern`` names one)
    cable_patterns: tuple[str, ...] = ()

    def _validate(self) -> None:
        for b in self.backgrounds:
            if b not in BACKGROUNDS:
                raise ConfigError("backgrounds", f"unknown {b!r}; choose from {BACKGROUNDS}")
        if not self.backgrounds:
            raise ConfigError("backgrounds", "need at least one background")
        lo, hi = self.hoses
        if not 1 <= lo <= hi <= MAX_HOSES:
            raise ConfigError("hoses", f"need 1 <= min <= max <= {MAX_HOSES}, got {self.hoses}")
        if not 0 <= self.random_colours <= 1:
            raise ConfigError("random_colours", f"must be in [0, 1], got {self.random_colours}")
        if not 0 <= self.same_colour <= 1:
            raise ConfigError("same_colour", f"must be in [0, 1], got {self.same_colour}")
        check_positive("light_jitter", self.light_jitter, allow_zero=True)
        check_positive("camera_position_jitter", self.camera_position_jitter, allow_zero=True)
        check_positive("camera_look_at_jitter", self.camera_look_at_jitter, allow_zero=True)
        if not self.cable_kinds:
            raise ConfigError("cable_kinds", "need at least one cable kind")
        for i, name in enumerate(self.cable_kinds):
            cable_kind(name, f"cable_kinds[{i}]")
        for i, name in enumerate(self.cable_patterns):
            check_pattern(name, f"cable_patterns[{i}]")


def randomize_scene(seed: int, base: SceneConfig, r: Randomization | None = None) -> SceneConfig:
    """``base`` with the randomised parts of scene ``seed`` (image size, robot and physics
    stay as in ``base``)."""
    r = r or Randomization()
    rng = stream(seed, "dataset")
    values: dict[str, object] = {"seed": int(seed)}
    # the background of what holds the cables: the board's, or the mat's on the table
    values[f"{base.surface}.background"] = r.backgrounds[int(rng.integers(len(r.backgrounds)))]
    values[f"{base.surface}.solid_rgb"] = tuple(float(x) for x in rng.uniform(0.2, 0.85, 3))
    values["hoses.count"] = int(rng.integers(r.hoses[0], r.hoses[1] + 1))
    if rng.random() < r.random_colours:
        values["hoses.colors"] = tuple(
            tuple(
                float(c)
                for c in colorsys.hsv_to_rgb(
                    rng.random(), rng.uniform(0.5, 1), rng.uniform(0.3, 0.95)
                )
            )
            for _ in range(8)
        )
    kinds = tuple(dict.fromkeys(r.cable_kinds))
    if len(kinds) == 1:
        values["hoses.kind"], values["hoses.kinds"] = kinds[0], ()
    else:  # its own stream: the draws above are those of datasets made before kinds existed
        pick = stream(seed, "dataset_kinds").integers(len(kinds), size=int(values["hoses.count"]))
        values["hoses.kinds"] = tuple(kinds[int(k)] for k in pick)
    patterns = tuple(dict.fromkeys(r.cable_patterns))
    if len(patterns) == 1:
        values["hoses.pattern"], values["hoses.patterns"] = patterns[0], ()
    elif patterns:  # its own stream, as the kinds'
        count = int(values["hoses.count"])
        pick = stream(seed, "dataset_patterns").integers(len(patterns), size=count)
        values["hoses.patterns"] = tuple(patterns[int(k)] for k in pick)
    # its own stream, as the kinds': the scene's other draws are those made without it
    if r.same_colour > 0 and stream(seed, "dataset_same_colour").random() < r.same_colour:
        values["hoses.same_colour"] = True
    values["light.jitter"] = float(r.light_jitter)
    values["camera.position_jitter"] = float(r.camera_position_jitter)
    values["camera.look_at_jitter"] = float(r.camera_look_at_jitter)
    return base.with_values(values)
