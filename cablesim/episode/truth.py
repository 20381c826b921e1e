"""What only a simulator (or a digital twin) can measure about an interaction.

The runner works without any of it (a real robot has none); given a provider it also verifies
the grasp (does the hose follow the hand?), measures how well the hose followed each action and
how far the other hoses moved, and attaches labels and ground-truth flow to the frames.
Perception never sees any of it: only evaluation reads ``Frame.truth``.

:class:`~cablesim.sim.truth.SimTruth` implements it for the simulated world.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from cablesim.camera.base import CameraImage
from cablesim.episode.clock import Tick
from cablesim.frames import Frame, FrameTruth
from cablesim.pose import Pose

HosePointProbe = Callable[[], np.ndarray]


@dataclass
class ActionTruth:
    """How the grasped hose followed one action, and how far every hose moved."""

    gain: float  # hose point displacement / gripper displacement along the direction
    gain_r2: float
    hose_displacement: list[float]  # m, largest vertex displacement of every hose


class FrameSink(Protocol):
    """Where finished frames go as soon as they exist (e.g. a recording writer)."""

    def add_frame(self, index: int, frame: Frame) -> None: ...

    def add_flow(self, index: int, flow: np.ndarray, valid: np.ndarray) -> None: ...


class TruthProvider(Protocol):
    def hose_under(self, mask: np.ndarray) -> int | None:
        """The hose most pixels of ``mask`` show in the current image (None: no hose)."""

    def grasp_probe(self, pose: Pose, hose: int | None) -> HosePointProbe | None:
        """A probe of the material hose point between the fingers at ``pose`` (None when no
        hose is there): the grasp is held when it follows the hand."""

    def label_next(self, on: bool) -> None:
        """Whether the frames grabbed from now on get labels (and later ground-truth flow):
        the collector's ``capture.truth_every`` rule; an unlabelled frame's truth is None."""

    def begin_interaction(self, hose: int | None, grasp: Pose | None) -> None:
        """The interaction on ``hose`` starts from ``grasp`` (after the grasp)."""

    def on_tick(self, action: int, tick: Tick) -> None:
        """Every camera tick of an action (kept or not)."""

    def action_truth(self, action: int, direction: np.ndarray) -> ActionTruth:
        """The measurements of one finished action."""

    def frame_truth(self, image: CameraImage) -> FrameTruth | None:
        """Labels of a captured frame (the state it was captured in)."""

    def finish(
        self, frames: Sequence[Frame], sink: FrameSink | None, say: Callable[[str], None]
    ) -> float:
        """After the target frame: flow from the target to every frame; the seconds spent."""
