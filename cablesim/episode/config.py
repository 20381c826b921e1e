"""Typed, printable configuration of one interaction (SPEC section 3), for the simulated and the
real robot alike.

    cfg = InteractionConfig()            # grasp, two periodic actions, release, retreat
    print(cfg)                           # JSON
    InteractionConfig.from_dict(cfg.to_dict()) == cfg
    cfg.with_values({"actions.periods": 2})   # a new, checked config (configs are frozen)

Every config here is checked when it is made (:class:`cablesim.config.Config`): an impossible
value is a ``ConfigError`` naming the field.  The simulated session's config
(:class:`cablesim.sim.config.EpisodeConfig`: scene, hose, perturbation) holds one of these; so
does a real-robot exploration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cablesim.cables import CABLE_KINDS, DEFAULT_KIND
from cablesim.config import Config, check_int, check_positive, check_vector
from cablesim.errors import ConfigError
from cablesim.panda.description import PARK_QPOS

#: What an interaction does with the hose.
KINDS = ("grasp", "push")
#: What an unfitted grasp closes on: the default cable kind's diameter (m).
DEFAULT_DIAMETER = 2 * CABLE_KINDS[DEFAULT_KIND].radius
#: A fitted grasp accepts an opening within this fraction of the diameter around it (the
#: 15 mm hose: 12 mm, the value of the thesis's setup).
GRASP_EPSILON_RATIO = 0.8
#: Named action directions (see :func:`cablesim.episode.primitives.action_direction`).
DIRECTION_NAMES = ("along", "across", "normal", "vertical", "horizontal")


@dataclass(frozen=True)
class GraspConfig(Config):
    """Pre-grasp, approach along the board normal, close, verify the hold."""

    SECTION = "grasp"

    pregrasp_offset: float = 0.08  # m in front of the grasp point, against the approach
    # m further back where the joint motion to the pre-grasp ends (then a straight line), so
    # that the arm does not sweep through the hoses in front of the board (measured: 0.12 m
    # still let the turning hand push a hose 2.7 cm; 0.2 m did not)
    standoff: float = 0.2
    # m from the seen surface to the cable axis; None: the grasped cable's radius
    surface_offset: float | None = None
    approach_speed: float = 0.05  # m/s for the last straight approach
    travel_speed: float = 0.25  # m/s for free motions
    width: float | None = None  # m the gripper closes on; None: the grasped cable's diameter
    force: float = 70.0  # N
    # m, accepted opening around ``width`` (franky epsilon); None: 0.8 x the cable's diameter
    epsilon: float | None = None
    hold_check_distance: float = 0.01  # m pulled back from the board to test the hold
    hold_tolerance: float = 0.005  # m, hose point vs hand displacement (sim verification)
    open_width: float = 0.08
    # a grasp that does not hold is retried: open, back out, re-approach a neighbouring point
    # of the segment, ``retry_shift`` further along its axis each time, alternating sides
    retries: int = 2
    retry_shift: float = 0.01  # m
    # with ground truth (simulation): an action during which the grasped hose point follows
    # the hand with R^2 below this failed (outcome ``grasp_not_held``: the hose slipped in the
    # fingers or was pulled loose); 0 turns the check off.  Measured on 27 recorded
    # interactions with perturbed neighbours: every held grasp >= 0.959 in each action, the
    # one that went wrong 0.34 (its hoses moved up to 0.68 m).
    min_follow_r2: float = 0.9

    def fitted(self, diameter: float | None = None) -> GraspConfig:
        """This config with ``width``, ``epsilon`` and ``surface_offset`` that are None made
        those of a cable of ``diameter`` (m): the diameter, 0.8 of it and its half.  A
        session fits its interaction to the cable it grasps (``Session.interaction_config``);
        ``diameter`` None is the default cable kind's (the 15 mm garden hose: 15, 12 and
        7.5 mm), what a config not fitted by a session closes on."""
        if diameter is None:
            diameter = DEFAULT_DIAMETER
        check_positive("grasp diameter", diameter)
        values = {
            "width": diameter if self.width is None else self.width,
            "epsilon": GRASP_EPSILON_RATIO * diameter if self.epsilon is None else self.epsilon,
            "surface_offset": diameter / 2 if self.surface_offset is None else self.surface_offset,
        }
        if all(getattr(self, k) == v for k, v in values.items()):
            return self
        return self.replace(**values)

    def _validate(self) -> None:
        for name in (
            "pregrasp_offset",
            "approach_speed",
            "travel_speed",
            "force",
            "open_width",
        ):
            check_positive(f"grasp.{name}", getattr(self, name))
        for name in ("width", "epsilon"):
            if getattr(self, name) is not None:
                check_positive(f"grasp.{name}", getattr(self, name))
        if self.surface_offset is not None:
            check_positive("grasp.surface_offset", self.surface_offset, allow_zero=True)
        check_positive("grasp.standoff", self.standoff, allow_zero=True)
        check_positive("grasp.hold_check_distance", self.hold_check_distance, allow_zero=True)
        check_positive("grasp.hold_tolerance", self.hold_tolerance)
        check_positive("grasp.retry_shift", self.retry_shift)
        if not 0.0 <= self.min_follow_r2 <= 1.0:
            raise ConfigError(
                "grasp.min_follow_r2", f"must be in [0, 1], got {self.min_follow_r2!r}"
            )
        if isinstance(self.retries, bool) or not isinstance(self.retries, int) or self.retries < 0:
            raise ConfigError("grasp.retries", f"must be an integer >= 0, got {self.retries!r}")


@dataclass(frozen=True)
class ActionConfig(Config):
    """Periodic actions g1 -> g1+D -> g1 -> g1-D -> g1, ``periods`` times, per direction."""

    SECTION = "actions"

    directions: tuple[str, ...] = ("along", "across")
    extra_directions: tuple[tuple[float, float, float], ...] = ()  # world vectors
    amplitude: float = 0.02  # |D| in metres
    periods: int = 3  # K_p
    speed: float = 0.05  # m/s peak TCP speed of each stroke
    stroke_tolerance: float = 0.01  # m a stroke may end off its target (a taut hose pulls back)
    # a stroke that ends further off still counts when the hand covered at least this share
    # of it along its direction (a taut hose stopped it; the frames record where it went)
    min_stroke_coverage: float = 0.25

    def _validate(self) -> None:
        for d in self.directions:
            if d not in DIRECTION_NAMES:
                raise ConfigError("actions.directions", f"unknown {d!r}; use {DIRECTION_NAMES}")
        for i, v in enumerate(self.extra_directions):
            check_vector(f"actions.extra_directions[{i}]", v, 3)
            if sum(x * x for x in v) < 1e-12:
                raise ConfigError(f"actions.extra_directions[{i}]", f"bad vector {v!r}")
        if not self.directions and not self.extra_directions:
            raise ConfigError("actions.directions", "need at least one action direction")
        check_positive("actions.amplitude", self.amplitude)
        check_positive("actions.speed", self.speed)
        check_positive("actions.stroke_tolerance", self.stroke_tolerance, allow_zero=True)
        if not 0 < self.min_stroke_coverage <= 1:
            raise ConfigError(
                "actions.min_stroke_coverage", f"must be in (0, 1], got {self.min_stroke_coverage}"
            )
        if not isinstance(self.periods, int) or self.periods < 1:
            raise ConfigError("actions.periods", f"must be an integer >= 1, got {self.periods!r}")


@dataclass(frozen=True)
class CaptureConfig(Config):
    """Camera triggering on simulated time and the kept-sample rule (SPEC 3.5)."""

    SECTION = "capture"

    frame_rate: float = 15.0  # frames per second of simulated time (RealSense rate)
    min_gripper_step: float = 0.001  # delta_g in metres; 0 keeps every frame
    ground_truth: bool = True  # labels and flow in FrameTruth (simulation only)
    # with ground truth: labels (and later ground-truth flow to the target frame) for the first
    # kept frame of each action and every ``truth_every``-th after it, and for the target
    # frame; the frames in between carry none (``Frame.truth`` None) and cost one render pass
    # instead of two, with the same images bit for bit.  The interaction itself reads only
    # the target frame's labels, and the image-based perception none, so the default (8,
    # since issue 21: about 3 s of CPU less per interaction) labels every 8th frame; 1
    # labels every frame, as the datasets, the learned flow's clips, the thesis benchmark
    # and every ground-truth (oracle) flow need: they set it
    truth_every: int = 8
    # the arm model rendered at each frame's joint state through the camera: Frame.arm_mask
    # (on with the real robot; ~20 ms per 640x480 frame, so off by default in simulation)
    arm_masks: bool = False
    arm_mask_margin: int = 3  # pixels the arm mask is dilated by

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """A file without ``truth_every`` was written before it existed or while every frame
        was labelled by default (before issue 21): it reruns as it ran, with 1."""
        data.setdefault("truth_every", 1)
        return data

    def _validate(self) -> None:
        check_positive("capture.frame_rate", self.frame_rate)
        if isinstance(self.arm_mask_margin, bool) or not isinstance(self.arm_mask_margin, int):
            raise ConfigError(
                "capture.arm_mask_margin", f"must be an integer, got {self.arm_mask_margin!r}"
            )
        check_positive("capture.arm_mask_margin", self.arm_mask_margin, allow_zero=True)
        check_positive("capture.min_gripper_step", self.min_gripper_step, allow_zero=True)
        check_int("capture.truth_every", self.truth_every, lo=1)


@dataclass(frozen=True)
class RetreatConfig(Config):
    """Release, back off, move to a joint configuration out of view, wait until the hoses are
    still, then take the target frame.

    Stillness: in simulation the physics settle (every hose vertex slower than
    ``settle_speed``); on a real camera, consecutive frames that differ by less than
    ``still_rgb`` (mean absolute grey-level change) and in which at most ``still_depth_fraction``
    of the valid pixels change depth by more than ``still_depth`` for ``still_time`` seconds.
    Either gives up after ``settle_max_time`` seconds with a named outcome.
    """

    SECTION = "retreat"

    # m pulled back along -approach after release.  At 0.12 the joint motion out of view began
    # among the hanging cables and the hand and link7 dragged a neighbour until it tore
    # (``diverged``): of such seeds on the board, 9452, 9469, 9483 (electrical cable) and
    # 9623, 9646, 9652, 9673 (rope), all seven held at 0.25 (thin-wire seeds 9543 and 9587
    # tear at the same moment either way, before the joint motion)
    back_off: float = 0.25
    # joint configuration out of view; None: the set-up's park configuration (the scene's
    # ``robot.park_qpos`` in simulation, ``PARK_QPOS`` otherwise).  With ground truth the
    # target frame is checked for zero robot pixels.
    qpos: tuple[float, ...] | None = None
    speed_factor: float = 0.5
    verify: bool = True  # with ground truth: insist on zero robot pixels in the target frame
    settle_speed: float = 0.001  # m/s, every hose vertex slower than this (simulation)
    settle_max_time: float = 6.0  # s to wait for stillness
    settle_check_every: float = 0.1  # s (simulation)
    still_rgb: float = 1.5  # grey levels, mean absolute change between frames (camera)
    still_depth: float = 0.005  # m, a depth change larger than this counts as motion (camera)
    still_depth_fraction: float = 0.005  # of valid pixels allowed to change depth (camera)
    still_time: float = 1.0  # s the frames must stay still (camera)

    def __post_init__(self) -> None:
        if isinstance(self.qpos, list | tuple):  # from JSON: a list
            try:
                qpos = tuple(float(q) for q in self.qpos)
            except (TypeError, ValueError):  # named by the checks
                qpos = tuple(self.qpos)
            object.__setattr__(self, "qpos", qpos)
        super().__post_init__()

    def joint_target(self, park: tuple[float, ...] | None = None) -> tuple[float, ...]:
        """The retreat joint configuration: ``qpos``, else ``park``, else ``PARK_QPOS``."""
        if self.qpos is not None:
            return tuple(self.qpos)
        return tuple(park) if park is not None else tuple(PARK_QPOS)

    def _validate(self) -> None:
        if self.qpos is not None and len(self.qpos) != 7:
            raise ConfigError("retreat.qpos", f"need 7 joint angles, got {len(self.qpos)}")
        check_positive("retreat.back_off", self.back_off, allow_zero=True)
        if not 0 < self.speed_factor <= 1:
            raise ConfigError("retreat.speed_factor", f"must be in (0, 1], got {self.speed_factor}")
        for name in (
            "settle_check_every",
            "settle_speed",
            "settle_max_time",
            "still_rgb",
            "still_depth",
            "still_time",
        ):
            check_positive(f"retreat.{name}", getattr(self, name))
        check_positive("retreat.still_depth_fraction", self.still_depth_fraction, allow_zero=True)


@dataclass(frozen=True)
class InteractionConfig(Config):
    """One interaction: grasp (or push), actions, capture, retreat."""

    kind: str = "grasp"  # "grasp" or "push"
    push_depth: float = 0.02  # m pressed into the hose by a push, along the approach
    grasp: GraspConfig = field(default_factory=GraspConfig)
    actions: ActionConfig = field(default_factory=ActionConfig)
    capture: CaptureConfig = field(default_factory=CaptureConfig)
    retreat: RetreatConfig = field(default_factory=RetreatConfig)

    def fitted(self, diameter: float | None = None) -> InteractionConfig:
        """This interaction with its grasp fitted to a cable of ``diameter`` (m; see
        :meth:`GraspConfig.fitted`)."""
        grasp = self.grasp.fitted(diameter)
        return self if grasp is self.grasp else self.replace(grasp=grasp)

    def _validate(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError("kind", f"must be one of {KINDS}, got {self.kind!r}")
        check_positive("push_depth", self.push_depth)
