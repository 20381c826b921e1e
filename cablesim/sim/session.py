"""One simulated session: everything an interaction needs, built from one config and one seed.

    session = SimSession.build(EpisodeConfig(seed=3))     # world, robot, camera, clock, truth
    start = session.pick_start()                           # seeded start segment of a hose
    result = session.interact(start.mask)                  # grasp, two actions, target frame
    session.close()

    out = simulate_episode(EpisodeConfig(seed=3, hose=1), record_to="runs/ep3")   # all of it

A session holds the world (settled, reset), ``SimPanda``, ``SimCamera``, the simulated clock
(frames on simulated time; the neighbour perturbation as its action hook), the ground-truth
provider (:class:`~cablesim.sim.truth.SimTruth`), the hose of interest and the named random
streams of the seed (:mod:`cablesim.seeding`): ``episode`` draws the hose of interest and the
start segment, ``perturb`` the perturbation.  ``simulate_episode``, ``explore``, the Gymnasium
environment, the dm_env adapter and the benchmarks all build their simulation here.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cablesim.camera.base import CameraImage
from cablesim.config import Config, check_fields
from cablesim.episode.config import InteractionConfig
from cablesim.episode.runner import InteractionResult
from cablesim.episode.session import Session
from cablesim.errors import ConfigError
from cablesim.progress import Progress, Say, quiet
from cablesim.seeding import stream
from cablesim.sim.config import SceneConfig
from cablesim.sim.perturb import PerturbConfig


@dataclass
class EpisodeConfig(Config):
    """A simulated interaction: the seed (scene and episode), the hose of interest, the scene,
    the interaction and the optional perturbation of the other hoses."""

    seed: int = 0
    hose: int | None = None  # None: drawn from the seed's ``episode`` stream
    scene: SceneConfig = field(default_factory=SceneConfig)
    interaction: InteractionConfig = field(default_factory=InteractionConfig)
    perturb: PerturbConfig = field(default_factory=PerturbConfig)
    progress: bool = False  # print progress lines

    def validate(self) -> EpisodeConfig:
        check_fields(self)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError("seed", f"must be a non-negative integer, got {self.seed!r}")
        if self.hose is not None and (
            isinstance(self.hose, bool)
            or not isinstance(self.hose, int)
            or not 0 <= self.hose < self.scene.hoses.count
        ):
            raise ConfigError("hose", f"{self.hose} is not one of {self.scene.hoses.count} hoses")
        self.scene_config().validate()
        self.interaction.validate()
        self.perturb.validate()
        return self

    def scene_config(self) -> SceneConfig:
        """The scene, with ``seed`` as its seed."""
        return dataclasses.replace(self.scene, seed=self.seed)


class SimSession(Session):
    """See the module docstring.  ``world`` and ``camera`` may be reused from an earlier
    session of the same scene (the world is reset to its settled state)."""

    def __init__(self, config: EpisodeConfig, world: Any = None, camera: Any = None) -> None:
        from cablesim.sim.camera import SimCamera
        from cablesim.sim.clock import SimClock
        from cablesim.sim.perturb import NeighbourPerturbation
        from cablesim.sim.sim_panda import SimPanda
        from cablesim.sim.truth import SimTruth
        from cablesim.sim.world import World

        self.cfg = config.validate()
        t0 = time.perf_counter()
        if world is None:
            world = World.build(self.cfg.scene_config())
        world.reset()
        self.world = world
        self.robot = SimPanda(world)  # fresh: no IK warm start carried between sessions
        self.camera = camera if camera is not None else SimCamera(world)
        self.truth = SimTruth(world, self.camera)
        self.rng = stream(self.cfg.seed, "episode")
        self.perturbation = NeighbourPerturbation(
            self.cfg.perturb, stream(self.cfg.seed, "perturb")
        )
        icfg = self.cfg.interaction
        grab = self.truth.capture if icfg.capture.ground_truth else self.camera.capture
        self.clock = SimClock(
            world, self.robot, grab, icfg.capture.frame_rate, action_hooks=[self.perturbation]
        )
        self.hose: int | None = self.cfg.hose
        self.build_time = time.perf_counter() - t0

    @classmethod
    def build(cls, config: EpisodeConfig, world: Any = None, camera: Any = None) -> SimSession:
        return cls(config, world, camera)

    # ------------------------------------------------------------------ parts
    @property
    def park(self) -> tuple[float, ...]:
        return tuple(self.world.cfg.robot.park_qpos)

    def draw_hose(self) -> int:
        """The hose of interest: the config's, else drawn from the ``episode`` stream (once)."""
        if self.hose is None:
            self.hose = int(self.rng.integers(len(self.world.hoses)))
        self.perturbation.hose_of_interest = self.hose
        return self.hose

    def pick_start(self, hose: int | None = None, interaction: InteractionConfig | None = None):
        """A seeded visible, graspable start segment of ``hose`` (default: the hose of
        interest) in the current image: the stand-in for a person's click."""
        from cablesim.sim.picker import pick_segment

        if hose is not None:
            self.hose = hose
        hose = self.draw_hose()
        icfg = interaction or self.cfg.interaction
        return pick_segment(self.world, self.robot, self.camera, hose, self.rng, icfg)

    def evaluator(self):
        """Ground truth for scores and grades of the hose of interest (evaluation only)."""
        from cablesim.evaluation import Evaluator

        return Evaluator(self.truth, self.draw_hose())


@dataclass
class SimulatedEpisode:
    result: InteractionResult
    segment: Any  # PickedSegment
    session: SimSession
    start_image: CameraImage  # the image the start segment was picked in

    @property
    def build_time(self) -> float:
        return self.session.build_time

    def close(self) -> None:
        self.session.close()


def simulate_episode(
    config: EpisodeConfig,
    record_to: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> SimulatedEpisode:
    """Build the session of ``config``, pick a start segment of ``config.hose`` (drawn when
    None) and run the interaction.  With ``record_to`` the frames are written to that directory
    as they come (see :mod:`cablesim.recording`)."""
    from cablesim.recording import RecordingWriter

    if record_to is not None:  # before the scene is built
        RecordingWriter.check_target(record_to, overwrite)
    say: Say = Progress("episode") if config.progress else quiet
    session = SimSession.build(config)
    cfg = session.cfg
    say(f"scene seed {cfg.seed} built in {session.build_time:.1f} s")
    start_image = session.capture()
    segment = session.pick_start()
    say(
        f"start segment: hose {session.hose}, {int(segment.mask.sum())} px at "
        f"{segment.centre_px} ({segment.tries} tries)"
    )
    cfg = cfg.replace(hose=session.hose)
    meta = {"seed": cfg.seed, "config": cfg.to_dict(), "segment_px": segment.pixels.tolist()}
    if record_to is None:
        result = session.interact(segment.mask, say=say)
    else:
        with RecordingWriter(Path(record_to), meta=meta, overwrite=overwrite) as writer:
            result = session.interact(segment.mask, sink=writer, say=say)
            final = dict(result.stream.meta) if result.stream is not None else {}
            final.update(meta, result=result.to_dict())
            writer.close(final, complete=result.success)
    if result.stream is not None:
        result.stream.meta.update(meta)
    return SimulatedEpisode(result, segment, session, start_image)
