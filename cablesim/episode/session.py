"""What a session is, simulated or real: a robot, a camera, a clock, an optional ground-truth
provider and the configuration of its interactions.

:class:`~cablesim.sim.session.SimSession` builds one from a seed; :class:`cablesim.real.
RealSession` from real devices and a calibration.  The exploration loop
(:class:`cablesim.policies.explore.Exploration`) and the Gymnasium environment use only what
this base class offers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cablesim.cables import cable_kind
from cablesim.camera.base import Camera, CameraImage
from cablesim.episode.config import InteractionConfig
from cablesim.episode.runner import InteractionOptions, InteractionResult, run_interaction
from cablesim.episode.surface import BOARD, Surface
from cablesim.panda.arm_mask import ArmMasker
from cablesim.panda.description import PARK_QPOS
from cablesim.progress import Say
from cablesim.robot.base import Robot


class Session:
    """A robot, a camera, a clock and an optional truth provider; ``cfg`` has the default
    ``interaction`` and the ``seed`` of the policy's random streams."""

    robot: Robot
    camera: Camera
    clock: Any
    cfg: Any
    truth: Any = None  # a TruthProvider (simulation, digital twin) or None (real robot)
    hose: int | None = None  # the hose of interest, when known
    retry_rng: np.random.Generator | None = None  # side of the first grasp retry (grasp_at)

    @property
    def T_world_camera(self) -> np.ndarray:
        T = self.camera.T_world_camera
        return np.asarray(T if T is not None else self.robot.T_world_camera, float)

    @property
    def T_world_base(self) -> np.ndarray:
        """The robot base in the world (from the arm model the robot plans on)."""
        arm = getattr(self.robot, "arm", None)
        base = getattr(arm, "base", None)
        return np.eye(4) if base is None else base.matrix()

    def cable_diameter(self) -> float | None:
        """The diameter (m) of the cable the interaction grasps, as the config describes it
        (``RealConfig.cable``, a simulated scene's cable kinds); None: not described (the
        default kind's)."""
        name = getattr(self.cfg, "cable", None)
        return None if name is None else 2 * cable_kind(name, "cable").radius

    def interaction_config(self, interaction: InteractionConfig | None = None) -> InteractionConfig:
        """``interaction`` (default: the config's) with its grasp fitted to the cable grasped
        (:meth:`cable_diameter`; ``GraspConfig.fitted``)."""
        return (interaction or self.cfg.interaction).fitted(self.cable_diameter())

    @property
    def park(self) -> tuple[float, ...]:
        """The joint configuration out of the camera's view."""
        return tuple(PARK_QPOS)

    @property
    def surface(self) -> Surface:
        """What holds the cables (the approach, the actions' plane): the board's here; a
        simulated session gives its scene's."""
        return BOARD

    def capture(self) -> CameraImage:
        return self.camera.capture()

    def evaluator(self) -> Any:
        """Ground truth for evaluation (None without a truth provider)."""
        return None

    def interact(
        self,
        segment: Any,
        interaction: InteractionConfig | None = None,
        sink: Any = None,
        say: Say | None = None,
    ) -> InteractionResult:
        """One interaction at ``segment`` of the current image (:func:`run_interaction`)."""
        interaction = self.interaction_config(interaction)
        options = InteractionOptions(
            sink=sink,
            say=say,
            hose=self.hose,
            park=self.park,
            arm_mask=self.arm_masker(interaction),
            retry_rng=self.retry_rng,
            surface=self.surface,
        )
        return run_interaction(
            self.robot, self.camera, self.clock, segment, interaction, self.truth, options
        )

    def arm_masker(self, interaction: InteractionConfig) -> Any:
        """``(tick) -> mask`` of the arm model through the camera when the interaction asks
        for arm masks (built once per session), else None."""
        if not interaction.capture.arm_masks:
            return None
        margin = interaction.capture.arm_mask_margin
        key = (id(self.robot), id(self.camera), margin)
        if getattr(self, "_arm_masker_key", None) != key:
            self._arm_masker = ArmMasker.for_robot(self.robot, self.camera, margin)
            self._arm_masker_key = key
        return self._arm_masker.for_tick

    def stop(self) -> None:
        """Stop the robot now (Ctrl-C)."""
        self.robot.stop()

    def close(self) -> None:
        masker = getattr(self, "_arm_masker", None)
        if masker is not None:
            masker.close()  # frees its OpenGL context on its own thread
            self._arm_masker, self._arm_masker_key = None, None
        self.camera.close()

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
