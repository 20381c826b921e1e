"""One simulated session: everything an interaction needs, built from one config and one seed.

    session = SimSession.build(EpisodeConfig.of(seed=3))  # world, robot, camera, clock, truth
    start = session.pick_start()                           # seeded start segment of a hose
    result = session.interact(start.mask)                  # grasp, two actions, target frame
    session.close()

    out = simulate_episode(EpisodeConfig.of(seed=3, hose=1), record_to="runs/ep3")  # all of it

A session holds the world (settled, reset), ``SimPanda``, ``SimCamera``, the simulated clock
(frames on simulated time; the neighbour perturbation as its action hook), the ground-truth
provider (:class:`~cablesim.sim.truth.SimTruth`), the hose of interest and the named random
streams of the seed (:mod:`cablesim.seeding`): ``episode`` draws the hose of interest and the
start segment, ``perturb`` the perturbation, ``grasp_retry`` the side a failed grasp is
retried on first.  ``simulate_episode``, ``explore``, the Gymnasium environment, the dm_env
adapter and the benchmarks all build their simulation here.

**What a session guarantees, and the re-draw rule.**  A session built from a config alone
(no ``world`` given) hands out a scene that settled and a hose of interest with a visible,
reachable, graspable start segment that, by default (``EpisodeConfig.clutter``), crosses at
least one other hose in the image.  It gets there deterministically:

1. Draw k of the scene (``SceneConfig.draw``, starting at the config's, 0 by default: the
   seed's own layout; k > 0 takes the hoses from child k of the seed's ``scene_resample``
   stream, the camera stays) is built and settled.  A draw that does not settle
   (:class:`~cablesim.errors.SceneUnsettledError`) is turned down.
2. The hose of interest: the config's ``hose`` if set; else the ``episode`` stream draws one
   hose h (as it always did), and when h does not qualify, hoses h+1, h+2, ... (modulo the
   count) are tried in turn.  A drawn hose qualifies when it crosses another hose in the
   image (:func:`~cablesim.sim.layout.crossing_pairs`; skipped with ``clutter=False`` or a
   fixed ``hose``) and the picker finds a start segment on it
   (:func:`~cablesim.sim.picker.pick_segment`).  Draw 0 draws both from the ``episode``
   stream, draw k > 0 from its child k, so that a draw's choices do not depend on the draws
   before it.  When no hose qualifies, the draw is turned down.
3. A turned-down draw is followed by draw k+1, up to ``max_draws`` draws.  Then the last
   reason is raised as a named :class:`~cablesim.errors.SceneError`
   (``scene_unsettled`` or ``no_graspable_segment``, its ``outcome``), with every draw's
   reason in its message; runs record it as an outcome instead of stopping
   (:func:`simulate_episode`, ``explore``, :mod:`cablesim.sweep`).

``session.draws`` is the number of draws built (1 when the seed's own scene served),
``session.resamples`` says why each earlier draw was turned down, and ``session.cfg`` carries
the draw that served (``cfg.scene.draw``), so that printing and re-running the config rebuilds
the same scene, hose of interest and start segment at once.  Settled scenes and the outcome of
a draw that did not settle are cached (:mod:`cablesim.sim.settle`), so a re-run costs no
settling, and so is the verdict on a draw turned down for want of a graspable segment
(:mod:`cablesim.sim.draw_cache`), so a re-run does not plan its candidates again.

A session given a ``world`` (the environment and the tests reuse one) takes it as it is and
picks nothing in advance (``pick_start`` raises ``NoGraspableSegmentError`` when the hose has no
segment).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cablesim.camera.base import CameraImage
from cablesim.episode.config import InteractionConfig
from cablesim.episode.runner import InteractionResult
from cablesim.episode.session import Session
from cablesim.errors import (
    NoGraspableSegmentError,
    PhysicsDivergedError,
    SceneError,
    SceneUnsettledError,
)
from cablesim.evaluation import Evaluator
from cablesim.outcomes import Outcome
from cablesim.progress import Progress, Say, quiet
from cablesim.recording import RecordingWriter
from cablesim.seeding import stream
from cablesim.sim import draw_cache
from cablesim.sim.camera import SimCamera
from cablesim.sim.clock import SimClock
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.layout import crossed_by, crossing_pairs
from cablesim.sim.perturb import NeighbourPerturbation
from cablesim.sim.picker import pick_segment
from cablesim.sim.sim_panda import SimPanda
from cablesim.sim.truth import SimTruth
from cablesim.sim.world import World


class SimSession(Session):
    """See the module docstring.  ``world`` and ``camera`` may be reused from an earlier
    session of the same scene (the world is reset to its settled state)."""

    def __init__(self, config: EpisodeConfig, world: Any = None, camera: Any = None) -> None:
        self.cfg = config
        t0 = time.perf_counter()
        self.rng = stream(self.cfg.seed, "episode")
        self.retry_rng = stream(self.cfg.seed, "grasp_retry")
        self.hose: int | None = self.cfg.hose
        self.start: Any = None  # the PickedSegment prepared at build (guaranteed sessions)
        self.draws = 0  # scene draws built
        self.resamples: list[dict[str, Any]] = []  # why each turned-down draw was
        if world is not None:
            self._assemble(world, camera)
        else:
            self._guarantee()
        self.build_time = time.perf_counter() - t0

    @classmethod
    def build(cls, config: EpisodeConfig, world: Any = None, camera: Any = None) -> SimSession:
        return cls(config, world, camera)

    def cable_diameter(self) -> float | None:
        """The diameter of the hose of interest (of the thickest cable while none is drawn),
        as its cable kind gives it."""
        hoses = self.cfg.scene.hoses
        if self.hose is None:
            return hoses.max_diameter()
        return 2 * hoses.cable(int(self.hose)).radius

    def _assemble(self, world: Any, camera: Any = None) -> None:
        """Robot, camera, truth, perturbation and clock on ``world`` (reset)."""

        world.reset()
        self.world = world
        self.robot = SimPanda(world)  # fresh: no IK warm start carried between sessions
        self.camera = camera if camera is not None else SimCamera(world)
        self.truth = SimTruth(world, self.camera)
        self.perturbation = NeighbourPerturbation(
            self.cfg.perturb, stream(self.cfg.seed, "perturb")
        )
        icfg = self.cfg.interaction
        grab = self.truth.capture if icfg.capture.ground_truth else self.camera.capture
        self.clock = SimClock(
            world, self.robot, grab, icfg.capture.frame_rate, action_hooks=[self.perturbation]
        )

    def _guarantee(self) -> None:
        """Draw scenes until one settles and has a qualifying hose of interest (module
        docstring); raises the last draw's named ``SceneError`` after ``max_draws``."""

        cfg = self.cfg
        last: SceneError | None = None
        reasons: dict[str, int] = {}  # why candidates were turned down, over every draw
        for k in range(cfg.max_draws):
            scene = cfg.scene.replace(draw=cfg.scene.draw + k)
            self.draws += 1
            # each draw picks with its own stream: re-running its config repeats its choices
            self.rng = stream(cfg.seed, "episode", *((scene.draw,) if scene.draw else ()))
            try:
                world = World.build(scene)
            except SceneUnsettledError as e:
                last = e
                self.resamples.append({"draw": scene.draw, "outcome": e.outcome, "reason": str(e)})
                continue
            # a draw already planned and turned down is not planned again (sim.draw_cache)
            use_cache = scene.physics.cache
            key = draw_cache.key_description(world, cfg.replace(scene=scene)) if use_cache else {}
            known = draw_cache.read_turned_down(key) if use_cache else None
            turned: NoGraspableSegmentError | None = None
            if known is not None:
                turned = NoGraspableSegmentError(*known)
            else:
                self._assemble(world)
                try:
                    self.start = self._choose_start(scene.draw)
                except NoGraspableSegmentError as no_segment:
                    turned = no_segment
                    self.camera.close()
                    if use_cache:
                        draw_cache.write_turned_down(key, str(turned), turned.reasons)
            if turned is not None:
                last = turned
                for r, n in turned.reasons.items():
                    reasons[r] = reasons.get(r, 0) + n
                self.resamples.append(
                    {"draw": scene.draw, "outcome": turned.outcome, "reason": str(turned)}
                )
                continue
            self.cfg = cfg.replace(scene=scene)
            return
        assert last is not None
        why = "; ".join(r["reason"] for r in self.resamples)
        message = f"seed {cfg.seed}: no usable scene in {cfg.max_draws} draws ({why})"
        if isinstance(last, SceneUnsettledError):
            err: SceneError = SceneUnsettledError(message, last.speed, last.limit)
        else:
            err = NoGraspableSegmentError(message, reasons)
        err.resamples = list(self.resamples)  # type: ignore[attr-defined]
        raise err

    def _choose_start(self, draw: int) -> Any:
        """The hose of interest and its start segment in the current world (module docstring,
        rule 2); raises ``NoGraspableSegmentError`` when no hose qualifies."""
        hose, picked = choose_start(
            self.world, self.robot, self.camera, self.rng, self.cfg, f"draw {draw}"
        )
        self.hose = hose
        self.perturbation.hose_of_interest = hose
        return picked

    # ------------------------------------------------------------------ parts
    @property
    def park(self) -> tuple[float, ...]:
        return tuple(self.world.cfg.robot.park_qpos)

    @property
    def surface(self) -> Any:
        return self.world.surface

    def draw_hose(self) -> int:
        """The hose of interest: the one chosen at build, the config's, else drawn from the
        ``episode`` stream (once)."""
        if self.hose is None:
            self.hose = int(self.rng.integers(len(self.world.hoses)))
        self.perturbation.hose_of_interest = self.hose
        return self.hose

    def pick_start(self, hose: int | None = None, interaction: InteractionConfig | None = None):
        """A seeded visible, graspable start segment of ``hose`` (default: the hose of
        interest) in the current image: the stand-in for a person's click.  The segment
        prepared at build is handed out for the hose of interest with the session's own
        interaction config."""

        if (
            self.start is not None
            and hose in (None, self.start.hose)
            and interaction in (None, self.cfg.interaction)
        ):
            return self.start
        if hose is not None:
            self.hose = hose
        hose = self.draw_hose()
        icfg = interaction or self.cfg.interaction  # pick_segment fits it to the hose
        return pick_segment(self.world, self.robot, self.camera, hose, self.rng, icfg)

    def evaluator(self):
        """Ground truth for scores and grades of the hose of interest (evaluation only)."""

        return Evaluator(self.truth, self.draw_hose())

    def describe_draws(self) -> dict[str, Any]:
        """The draw that served, how many were built and why earlier ones were turned down."""
        return {
            "draw": self.world.cfg.draw,
            "draws": self.draws,
            "resamples": self.draws - 1 if self.draws else 0,
            "turned_down": list(self.resamples),
        }


@dataclass
class SimulatedEpisode:
    """One simulated interaction.  When no scene draw served (``result.outcome`` is
    ``scene_unsettled`` or ``no_graspable_segment``) there is no session, segment or image."""

    result: InteractionResult
    segment: Any  # PickedSegment, or None when no scene draw served
    session: SimSession | None
    start_image: CameraImage | None  # the image the start segment was picked in
    draws: dict[str, Any] = field(default_factory=dict)  # SimSession.describe_draws()

    @property
    def build_time(self) -> float:
        return self.session.build_time if self.session is not None else math.nan

    def close(self) -> None:
        if self.session is not None:
            self.session.close()


def simulate_episode(
    config: EpisodeConfig,
    record_to: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> SimulatedEpisode:
    """Build the session of ``config``, pick a start segment of ``config.hose`` (drawn when
    None) and run the interaction.  With ``record_to`` the frames are written to that directory
    as they come (see :mod:`cablesim.recording`); ``progress`` prints progress lines.  A scene no draw of which serves (module
    docstring), or whose physics diverged while settling, comes back as a failed result with
    its named ``outcome`` (``scene_unsettled``, ``no_graspable_segment``, ``diverged``), not as
    an error."""

    if record_to is not None:  # before the scene is built
        RecordingWriter.check_target(record_to, overwrite)
    say: Say = Progress("episode") if progress else quiet
    try:
        session = SimSession.build(config)
    except (SceneError, PhysicsDivergedError) as e:
        say(f"no interaction: {e.outcome}: {e}")
        draws = {
            "draw": None,
            "draws": config.max_draws,
            "turned_down": getattr(e, "resamples", []),
        }
        draws["resamples"] = draws["draws"]
        result = InteractionResult(False, reason=str(e), outcome=e.outcome, hose=config.hose)
        result.details["scene_draws"] = draws
        return SimulatedEpisode(result, None, None, None, draws)
    cfg = session.cfg
    draws = session.describe_draws()
    say(
        f"scene seed {cfg.seed} built in {session.build_time:.1f} s"
        + (f" (draw {cfg.scene.draw}: {session.draws - 1} re-draws)" if session.draws > 1 else "")
    )
    start_image = session.capture()
    segment = session.pick_start()
    say(
        f"start segment: hose {session.hose}, {int(segment.mask.sum())} px at "
        f"{segment.centre_px} ({segment.tries} tries)"
    )
    cfg = cfg.replace(hose=session.hose)
    meta = {
        "seed": cfg.seed,
        "config": cfg.to_dict(),
        "segment_px": segment.pixels.tolist(),
        "scene_draws": draws,
    }
    if record_to is None:
        result = _interact(session, segment.mask, say)
    else:
        with RecordingWriter(Path(record_to), meta=meta, overwrite=overwrite) as writer:
            result = _interact(session, segment.mask, say, writer)
            final = dict(result.stream.meta) if result.stream is not None else {}
            final.update(meta, result=result.to_dict())
            writer.close(final, complete=result.success)
    result.details["scene_draws"] = draws
    if result.stream is not None:
        result.stream.meta.update(meta)
    return SimulatedEpisode(result, segment, session, start_image, draws)


def _interact(session: SimSession, mask: Any, say: Say, sink: Any = None) -> InteractionResult:
    """The session's interaction; physics that diverged on the way (NaN, a MuJoCo warning, a
    hose stretched apart: :meth:`World.check_diverged`) is the named outcome ``diverged``."""
    try:
        return session.interact(mask, sink=sink, say=say)
    except PhysicsDivergedError as e:
        say(f"interaction stopped: diverged: {e}")
        return InteractionResult(False, reason=str(e), outcome=Outcome.DIVERGED, hose=session.hose)


def choose_start(
    world: Any, robot: Any, camera: Any, rng: Any, cfg: EpisodeConfig, where: str
) -> tuple[int, Any]:
    """The hose of interest and its start segment in ``world`` as seen by ``camera`` (module
    docstring, rule 2): ``cfg.hose`` or, from ``rng``, a first hose and the others in turn,
    each taken only when it crosses another hose in the image (``cfg.clutter``, with two
    hoses or more) and shows a graspable segment.  Shared by :class:`SimSession` and the
    digital twin; raises ``NoGraspableSegmentError`` (``where`` names the draw) when no hose
    qualifies."""

    n = len(world.hoses)
    if cfg.hose is not None:
        candidates, pairs = [cfg.hose], None
    else:
        first = int(rng.integers(n))
        candidates = [(first + i) % n for i in range(n)]
        pairs = None
        if cfg.clutter and n > 1:  # one hose alone crosses nothing
            K = camera.intrinsics
            pairs = crossing_pairs(
                [world.hose_vertices(i) for i in range(n)],
                camera.T_world_camera,
                K.f,
                K.cx,
                K.cy,
                K.width,
                K.height,
            )
    reasons: dict[str, int] = {}
    why = []
    for h in candidates:
        if pairs is not None and not crossed_by(pairs, h):
            reasons["crosses no other hose"] = reasons.get("crosses no other hose", 0) + 1
            why.append(f"hose {h} crosses no other hose")
            continue
        try:
            picked = pick_segment(world, robot, camera, h, rng, cfg.interaction)
        except NoGraspableSegmentError as e:
            for r, c in e.reasons.items():
                reasons[r] = reasons.get(r, 0) + c
            why.append(str(e))
            continue
        return h, picked
    raise NoGraspableSegmentError(
        f"no hose of interest qualifies in {where} ({'; '.join(why)})", reasons
    )
