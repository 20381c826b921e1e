"""One interaction of the robot with a hose (SPEC section 3), in simulation, recorded.

    from cablesim.episode import EpisodeConfig, simulate_episode
    out = simulate_episode(EpisodeConfig(seed=2, hose=1), record_to="runs/ep2")
    out.result.stream                     # Frames: kept action samples ..., target frame last
    print(out.result.summary())           # gain per action, other hoses' displacement

Modules: ``config`` (EpisodeConfig), ``primitives`` (grasp/actions/push/release/retreat on the
Robot interface), ``trigger`` (camera ticks on simulated time), ``capture`` (kept frames and
ground truth), ``runner`` (run_episode), ``picker`` (random graspable start segment),
``recording`` (on-disk format, reader), ``simulate`` (all of it from a seed), ``cli``.
Importing this package does not import MuJoCo; ``runner``, ``picker`` and ``simulate`` do.
"""

from cablesim.episode.config import (
    ActionConfig,
    CaptureConfig,
    EpisodeConfig,
    GraspConfig,
    RetreatConfig,
)
from cablesim.episode.recording import (
    Recording,
    RecordingWriter,
    read_stream,
    write_stream,
)

__all__ = [
    "ActionConfig",
    "CaptureConfig",
    "EpisodeConfig",
    "GraspConfig",
    "Recording",
    "RecordingWriter",
    "RetreatConfig",
    "read_stream",
    "simulate_episode",
    "write_stream",
]


def __getattr__(name: str):  # lazy: simulate_episode imports MuJoCo
    if name == "simulate_episode":
        from cablesim.episode.simulate import simulate_episode

        return simulate_episode
    raise AttributeError(name)
