"""Named random streams from one seed: the only seeding scheme in cablesim.

    rng = stream(seed, "episode")            # a numpy Generator
    rngs = streams(seed)                     # every named stream at once
    rng = stream(seed, "scene_resample", 2)  # numbered child 2 of a stream (the 2nd re-draw)

Each name is a child of ``SeedSequence(seed)`` with a fixed spawn key (its index in
:data:`STREAMS`), so adding a use of one stream never changes the numbers another draws, and
the same seed gives the same numbers on every machine and in every worker process.  New names
are appended at the end (an existing name's index never changes).
"""

from __future__ import annotations

import numpy as np

from cablesim.errors import ConfigError

#: Every named stream, in spawn-key order.  Append only.
STREAMS: tuple[str, ...] = (
    "hoses",  # hose lengths, colours, stiffness, attachment (scene layout)
    "camera",  # camera pose jitter
    "depth_noise",  # the simulated camera's depth noise
    "episode",  # hose of interest and start segment
    "perturb",  # neighbour perturbation (amplitude, period, phase, vertices)
    "baseline",  # the random-grasp baseline's choices
    "env",  # the Gymnasium environment's per-reset draws
    "rgb_noise",  # the simulated camera's RGB sensor noise
    "scene_resample",  # documented re-draws of a scene that does not meet its guarantees
    "grasp_retry",  # neighbouring points tried when a grasp does not hold
    "calibration",  # the board poses drawn by ``cablesim calibrate``
    "lighting",  # light jitter (LightConfig.jitter)
    "dataset",  # a dataset scene's randomised background, hoses, light and camera
    "dataset_kinds",  # a dataset scene's cable kinds, one per cable
    "dataset_patterns",  # a dataset scene's cable surface patterns, one per cable
    "dataset_motion",  # a MovingCables clip's action direction and amplitude
    "dataset_same_colour",  # whether a dataset scene's cables all wear one colour
    "dataset_h264",  # whether and how hard a MovingCables clip is H.264-compressed
)


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError("seed", f"must be a non-negative integer, got {seed!r}")
    return int(seed)


def stream(seed: int, name: str, *index: int) -> np.random.Generator:
    """The generator of stream ``name`` for ``seed``; with ``index``, its numbered child
    (spawn key ``(position of name, *index)``): independent of the stream itself and of every
    other child, e.g. one per re-draw of a scene."""
    if name not in STREAMS:
        raise ConfigError("seeding", f"unknown random stream {name!r}; known: {STREAMS}")
    for i in index:
        if isinstance(i, bool) or not isinstance(i, int | np.integer) or i < 0:
            raise ConfigError(
                "seeding", f"a stream index must be a non-negative integer, got {i!r}"
            )
    key = (STREAMS.index(name), *(int(i) for i in index))
    return np.random.default_rng(np.random.SeedSequence(_check_seed(seed), spawn_key=key))


def streams(seed: int, names: tuple[str, ...] = STREAMS) -> dict[str, np.random.Generator]:
    """A fresh generator for each of ``names``."""
    return {n: stream(seed, n) for n in names}
