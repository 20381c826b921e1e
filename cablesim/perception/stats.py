"""What one pass over a stream leaves behind: the kept frames (jobs) and the per-action
statistics every segmentation method thresholds (:class:`StreamStatistics`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.frames import Frame, Stream
from cablesim.perception.actions import (
    action_direction,
    gripper_displacements,
    subsample_by_gripper,
)
from cablesim.perception.correlation import CorrelationResult
from cablesim.perception.published import PublishedResult, PublishedSegmentationResult
from cablesim.perception.refine import GrowParams
from cablesim.perception.segmentation import SegmentationResult


@dataclass
class Job:
    """One kept frame: its action, its index among kept samples, d_g and gripper depth."""

    action: int
    index: int
    frame: Frame
    d_g: float
    z: float


def plan_jobs(stream: Stream, delta_g: float = 0.001) -> list[Job]:
    """Kept frames of every action in stream order, with their d_g and gripper depth."""
    jobs: list[Job] = []
    _ = stream.target  # raises if the last frame is not a target frame
    for a in stream.actions:
        frames = stream.action_frames(a)
        kept = subsample_by_gripper(frames, delta_g)
        d_g = gripper_displacements(kept, action_direction(frames))
        for i, (f, d) in enumerate(zip(kept, d_g, strict=True)):
            jobs.append(Job(a, i, f, float(d), float(f.gripper[2])))
    return jobs


@dataclass
class StreamStatistics:
    """Per-action statistics of one stream, enough to threshold any method.

    The built-in methods keep theirs in the named fields (``correlation`` for motion
    correlation and its ablation, ``segmentation``, ``published``, ...); any other method's
    accumulated result is in ``results`` under its statistic's key
    (:attr:`cablesim.perception.methods.SegmentationMethod.key`)."""

    shape: tuple[int, int]
    actions: list[int]
    n_samples: dict[int, int]
    correlation: dict[int, CorrelationResult] = field(default_factory=dict)
    segmentation: dict[int, SegmentationResult] = field(default_factory=dict)
    directions: dict[int, np.ndarray] = field(default_factory=dict)
    flow: dict[str, Any] = field(default_factory=dict)
    published: dict[int, PublishedResult] = field(default_factory=dict)
    published_segmentation: dict[int, PublishedSegmentationResult] = field(default_factory=dict)
    published_meta: dict[str, Any] = field(default_factory=dict)
    # target pixels allowed to vote (``cablesim.perception.refine.support_mask``); None: all
    support: np.ndarray | None = None
    # the same for the published methods: only when a refine was asked for explicitly (by
    # default they stay the published code's)
    published_support: np.ndarray | None = None
    refine: dict[str, Any] = field(default_factory=dict)
    # colour growth of the current methods' masks (``RefineParams.grow``): the parameters and
    # the target frame in CIELAB (``cablesim.perception.refine.colour_guide``); None: off
    grow: GrowParams | None = None
    guide: np.ndarray | None = None
    # the accumulated results of methods other than the built-ins, by statistic key
    results: dict[str, Any] = field(default_factory=dict)
