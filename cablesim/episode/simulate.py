"""One seeded simulated episode end to end: scene, robot, camera, start segment, interaction,
optional recording.

    out = simulate_episode(EpisodeConfig(seed=3, hose=1), record_to="runs/ep3")
    print(out.result.summary())
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cablesim.camera.base import CameraImage
from cablesim.episode.config import EpisodeConfig
from cablesim.episode.picker import PickedSegment, pick_segment
from cablesim.episode.recording import RecordingWriter
from cablesim.episode.runner import EpisodeResult, run_episode
from cablesim.sim.layout import rng_streams


@dataclass
class SimulatedEpisode:
    result: EpisodeResult
    segment: PickedSegment
    world: Any
    robot: Any
    camera: Any
    build_time: float
    start_image: CameraImage  # the image the start segment was picked in

    def close(self) -> None:
        self.camera.close()


def simulate_episode(
    config: EpisodeConfig,
    record_to: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    width: int | None = None,
    height: int | None = None,
) -> SimulatedEpisode:
    """Build the scene of ``config.seed``, pick a start segment of ``config.hose`` (drawn when
    None) with the episode generator, and run the interaction.  With ``record_to`` the frames
    are written to that directory as they come (see :mod:`cablesim.episode.recording`)."""
    from cablesim.robot.sim_panda import SimPanda
    from cablesim.sim.camera import SimCamera
    from cablesim.sim.world import World

    cfg = config.validate()
    say = print if cfg.progress else (lambda *_: None)
    t0 = time.perf_counter()
    world = World.build(cfg.scene_config())
    robot = SimPanda(world)
    camera = SimCamera(world, width, height)
    build = time.perf_counter() - t0
    say(f"[episode] scene seed {cfg.seed} built in {build:.1f} s")
    rng = rng_streams(cfg.seed)["episode"]
    hose = cfg.hose if cfg.hose is not None else int(rng.integers(len(world.hoses)))
    start_image = camera.capture()
    segment = pick_segment(world, robot, camera, hose, rng, cfg)
    say(
        f"[episode] start segment: hose {hose}, {int(segment.mask.sum())} px at "
        f"{segment.centre_px} ({segment.tries} tries)"
    )
    if hose != cfg.hose:
        cfg = cfg.replace(hose=hose)
    if record_to is None:
        result = run_episode(world, robot, camera, segment.mask, cfg)
    else:
        meta = {"config": cfg.to_dict(), "segment_px": segment.pixels.tolist()}
        with RecordingWriter(Path(record_to), meta=meta, overwrite=overwrite) as writer:
            result = run_episode(world, robot, camera, segment.mask, cfg, sink=writer)
            final = dict(result.stream.meta) if result.stream is not None else {}
            final.update(meta, result=result.to_dict())
            writer.close(final, complete=result.success)
    return SimulatedEpisode(result, segment, world, robot, camera, build, start_image)
