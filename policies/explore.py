"""The exploration policy of the thesis (chapter 6) and two baselines.

    from cablesim.policies import ExploreConfig, explore
    res = explore(ExploreConfig.of(seed=0, grasps=3), out="runs/demo")
    print(res.summary())               # precision, recall, F_0.4, IoU per interaction and merged

Loop (strategy ``sampler``): a start segment of the hose of interest (the seeded stand-in for a
person clicking, :func:`~cablesim.sim.picker.pick_segment`) -> interaction
(:func:`~cablesim.episode.runner.run_interaction`: grasp, two periodic actions, retreat,
target frame) -> segmentation of the stream (motion correlation by default) -> the votes are merged
with those of earlier interactions in the latest target frame (:class:`VoteMerger`) -> the
grasp sampler proposes the next grasp on the merged votes; its reachability callback is the
robot's ``check_reachable`` on the grasp and pre-grasp poses built from the proposal's
camera-frame centre and axis (and the action end points) -> repeat until ``grasps``
interactions succeeded or ``max_attempts`` were tried.  A failed interaction (slip,
unreachable, collision) blacklists its segment and the next proposal is tried.

Baselines: ``random`` picks the next grasp at a random voted pixel (the voted pixels within
3 cm of it form the segment) instead of asking the sampler; ``push`` pokes the hose (closed
gripper, pressed and back) and segments by motion segmentation.

Neighbouring hoses can be disturbed on purpose during the actions (``config.episode.perturb``, see
:mod:`cablesim.sim.perturb`).  Ground truth reaches the loop only through the evaluation module
(:class:`~cablesim.evaluation.Evaluator`: scores, grades of proposals, the explicit ``oracle``
merge); the start segment comes from the simulated session's picker.  The same loop
(:class:`Exploration`) runs on a real session, which has no evaluator.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from cablesim.config import to_dict
from cablesim.episode import primitives as prim
from cablesim.episode.surface import BOARD, Surface
from cablesim.errors import InputError, PhysicsDivergedError, SceneError
from cablesim.evaluation import scores_dict
from cablesim.formats.mcor import write_mcor, write_multigrasp
from cablesim.frames import Intrinsics, Stream
from cablesim.jsonutil import jsonable
from cablesim.perception.correlation import AblationParams, CorrelationParams
from cablesim.perception.flow import make_flow
from cablesim.perception.geometry import eccentricity, segment_pose
from cablesim.perception.grasp_sampler import GraspSampler
from cablesim.perception.pipeline import StreamSegmentation, segment_stream
from cablesim.perception.raft import check_checkpoint_file
from cablesim.progress import Progress, Say, quiet
from cablesim.recording import RecordingWriter
from cablesim.seeding import stream
from cablesim.sim.session import SimSession

from .config import ExploreConfig
from .merge import VoteMerger, dis_target_flow
from .report import ExplorationWriter


@dataclass
class Interaction:
    """One attempted interaction of an exploration."""

    index: int
    success: bool
    reason: str = ""
    source: str = "start"  # start | sampler | random
    segment: np.ndarray | None = None  # the segment it was aimed at (HxW bool)
    grade: str | None = None  # grading of the segment against ground truth
    grasped_hose: int | None = None  # which hose was actually held (ground truth)
    scores: dict[str, float] = field(default_factory=dict)  # its own mask, its own target
    merged: dict[str, float] = field(default_factory=dict)  # merged mask after it
    seg: StreamSegmentation | None = None
    target_rgb: np.ndarray | None = None
    target_depth: np.ndarray | None = None
    truth: np.ndarray | None = None  # hose-of-interest mask in its target frame
    flow_example: tuple[np.ndarray, np.ndarray] | None = None  # (estimated, ground truth)
    timings: dict[str, float] = field(default_factory=dict)
    episode: dict[str, Any] = field(default_factory=dict)
    outcome: str = ""  # named outcome (a cablesim.outcomes.Outcome)

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "success": self.success,
            "outcome": self.outcome,
            "reason": self.reason,
            "source": self.source,
            "grade": self.grade,
            "grasped_hose": self.grasped_hose,
            "segment_pixels": None if self.segment is None else int(self.segment.sum()),
            "scores": self.scores,
            "merged": self.merged,
            "timings_s": self.timings,
            "episode": self.episode,
        }


@dataclass
class ExplorationResult:
    config: ExploreConfig
    hose: int
    start_rgb: np.ndarray
    start_segment: np.ndarray
    interactions: list[Interaction] = field(default_factory=list)
    merged_votes: np.ndarray | None = None
    final_rgb: np.ndarray | None = None
    final_truth: np.ndarray | None = None
    stop_reason: str = ""
    # named outcome of a start that never came to an interaction (no scene draw served)
    start_outcome: str = ""
    scene_draws: dict[str, Any] = field(default_factory=dict)
    perturbations: list[dict[str, Any]] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    # SPEC section 7 grades of every proposal: the executed ones and those the robot's
    # reachability check turned down (graded ``correct_unreachable`` when on the hose)
    proposal_grades: dict[str, int] = field(default_factory=dict)

    def grade(self, grade: str) -> None:
        self.proposal_grades[grade] = self.proposal_grades.get(grade, 0) + 1

    @property
    def successes(self) -> list[Interaction]:
        return [i for i in self.interactions if i.success]

    @property
    def merged(self) -> dict[str, float]:
        ok = self.successes
        return ok[-1].merged if ok else {}

    @property
    def outcome(self) -> str:
        """``ok`` when an interaction succeeded, else the named outcome of the start (no scene
        draw served) or of the first interaction."""
        if self.successes:
            return "ok"
        if self.start_outcome:
            return self.start_outcome
        return self.interactions[0].outcome if self.interactions else ""

    def metrics(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "seed": self.config.seed,
            "hose": self.hose,
            "strategy": self.config.strategy,
            "method": self.config.resolved_method,
            "flow": self.config.flow,
            "merge": self.config.merge,
            "merged_votes_threshold": self.config.merged_votes,
            "perturb": self.config.episode.perturb.enabled,
            "interactions": [i.to_dict() for i in self.interactions],
            "successful_interactions": len(self.successes),
            "proposal_grades": dict(sorted(self.proposal_grades.items())),
            "merged": self.merged,
            "stop_reason": self.stop_reason,
            "outcome": self.outcome,
            "scene_draws": self.scene_draws,
            "perturbations": self.perturbations,
            "timings_s": self.timings,
            "config": to_dict(self.config),
        }
        if self.merged_votes is not None and self.final_truth is not None:
            top = int(self.merged_votes.max(initial=0))
            out["merged_by_threshold"] = {
                str(n): scores_dict(self.merged_votes >= n, self.final_truth)
                for n in range(1, max(top, 1) + 1)
            }
        return out

    def summary(self) -> str:
        lines = [
            f"exploration seed {self.config.seed}, hose {self.hose}, "
            f"strategy {self.config.strategy}, method {self.config.resolved_method}, "
            f"flow {self.config.flow}, perturbed neighbours "
            f"{'on' if self.config.episode.perturb.enabled else 'off'}"
        ]
        lines.append(
            f"{'#':>2} {'source':>7} {'result':<30} {'P':>6} {'R':>6} {'F0.4':>6} {'IoU':>6}"
        )
        for i in self.interactions:
            if i.success:
                s = i.scores
                lines.append(
                    f"{i.index:>2} {i.source:>7} {'ok (' + str(i.grade) + ')':<30} "
                    f"{s['precision']:6.3f} {s['recall']:6.3f} {s['f0.4']:6.3f} {s['iou']:6.3f}"
                )
            else:
                lines.append(f"{i.index:>2} {i.source:>7} failed: {i.reason[:70]}")
        m = self.merged
        if m:
            lines.append(
                f"{'merged':>10} ({len(self.successes)} interactions, votes >= "
                f"{self.config.merged_votes}){'':<7} {m['precision']:6.3f} {m['recall']:6.3f} "
                f"{m['f0.4']:6.3f} {m['iou']:6.3f}"
            )
        if self.proposal_grades:
            grades = ", ".join(f"{k} {v}" for k, v in sorted(self.proposal_grades.items()))
            lines.append(f"proposals graded: {grades}")
        lines.append(f"stopped: {self.stop_reason}")
        if not self.successes:
            lines.append(f"outcome: {self.outcome}")
        return "\n".join(lines)


# ---------------------------------------------------------------------- helpers
def grasp_reachability(
    robot: Any, T_world_camera: np.ndarray, cfg: Any, surface: Surface = BOARD
) -> Callable:
    """The sampler's reachability callback: :func:`~cablesim.episode.primitives.check_interaction`
    on the grasp built from a camera-frame (centre, axis) of a proposal, on ``surface``."""

    T = np.asarray(T_world_camera, float)
    cfg = cfg.fitted()  # a session's config is fitted already; a bare one: the default cable

    def reachable(centre_cam: np.ndarray, axis_cam: np.ndarray) -> tuple[bool, str]:
        centre = prim.grasp_centre(T, centre_cam, cfg.grasp.surface_offset)
        return prim.check_interaction(robot, centre, T[:3, :3] @ axis_cam, cfg, T, surface)

    return reachable


def random_segment(
    votes: np.ndarray,
    depth: np.ndarray,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    reachable: Callable,
    tries: int = 30,
    half_length: float = 0.03,
    previous: list[np.ndarray] | None = None,
    min_distance: float = 0.05,
) -> np.ndarray | None:
    """Random-grasp baseline: the voted pixels within ``half_length`` of a random voted pixel
    (connected to it), if elongated, with depth, away from previous grasps and reachable."""
    mask = votes > 0
    vv, uu = np.nonzero(mask & (depth > 0))
    if len(vv) == 0:
        return None
    h, w = mask.shape
    yy, xx = np.ogrid[:h, :w]
    for j in rng.permutation(len(vv))[:tries]:
        u, v = int(uu[j]), int(vv[j])
        r = max(3.0, half_length * intrinsics.f / float(depth[v, u]))
        lab, _ = ndimage.label(mask & ((xx - u) ** 2 + (yy - v) ** 2 <= r * r))
        seg = lab == lab[v, u]
        if seg.sum() < 10 or eccentricity(seg) < 0.8:
            continue
        try:
            sp = segment_pose(seg, depth, intrinsics)
        except InputError:  # too little depth under the segment
            continue
        if previous and min(np.linalg.norm(p - sp.centre) for p in previous) < min_distance:
            continue
        if reachable(sp.centre, sp.axis)[0]:
            return seg
    return None


def front_segment(
    mask: np.ndarray, depth: np.ndarray, tolerance: float = 0.008, min_pixels: int = 10
) -> np.ndarray:
    """The front-most part of a proposed segment: pixels with valid depth within ``tolerance``
    of the segment's near depth (its 10th percentile).  Votes from estimated flow bleed onto
    the board around a hose; the hose lies in front of the board, so this keeps the hose and
    the grasp point on it (ground-truth free).  Returns ``mask`` unchanged when too little
    would remain."""
    d = np.where(mask & (depth > 0) & np.isfinite(depth), depth, np.nan)
    if np.count_nonzero(~np.isnan(d)) < min_pixels:
        return mask
    near = float(np.nanpercentile(d, 10))
    keep = mask & (np.nan_to_num(d, nan=np.inf) <= near + tolerance)
    if keep.sum() < min_pixels:
        return mask
    lab, n = ndimage.label(keep)
    if n > 1:  # the largest connected piece
        sizes = ndimage.sum(keep, lab, range(1, n + 1))
        keep = lab == (1 + int(np.argmax(sizes)))
    return keep if keep.sum() >= min_pixels else mask


# ---------------------------------------------------------------------- the loop
class Exploration:
    """The exploration loop over a session (simulated or real): interactions on one hose,
    segmentation, merged votes, next proposal.  ``evaluator`` (simulation only) scores and
    grades; without one nothing is scored.  With ``record_to`` every interaction is recorded
    as it happens to ``record_to/interaction{k}`` (:mod:`cablesim.recording`).  Call
    :meth:`run`."""

    def __init__(
        self,
        session: Any,
        cfg: ExploreConfig,
        start_segment: np.ndarray,
        start_image: Any,
        evaluator: Any = None,
        writer: Any = None,
        say: Say = quiet,
        flow_kwargs: dict[str, Any] | None = None,
        record_to: Path | None = None,
    ) -> None:
        self.session, self.cfg, self.ev, self.writer, self.say = (
            session,
            cfg,
            evaluator,
            writer,
            say,
        )
        self.record_to = None if record_to is None else Path(record_to)
        self.published: list[str] = []  # sequences written in the published layout
        self.interaction_cfg = session.interaction_config()
        self.T = np.asarray(session.T_world_camera, float)
        self.flow = make_flow(cfg.flow, **(flow_kwargs or {}))
        self.reachable = grasp_reachability(
            session.robot, self.T, self.interaction_cfg, session.surface
        )
        self.sampler = GraspSampler(cfg.sampler, reachability=self.reachable)
        self.merger = VoteMerger(dis_target_flow() if cfg.merge == "dis" else None)
        self.baseline_rng = stream(session.cfg.seed, "baseline")
        self.params = _method_params(cfg)
        hose = evaluator.hose if evaluator is not None else getattr(session, "hose", None)
        self.result = ExplorationResult(cfg, hose, start_image.rgb, start_segment)
        self.segment, self.source = start_segment, "start"
        self.prev_snap = self._snapshot()
        self.previous_centres: list[np.ndarray] = []
        # the image the current segment lies in
        self.depth, self.K = start_image.depth, start_image.intrinsics

    def _snapshot(self) -> Any:
        return self.ev.snapshot() if self.ev is not None and self.cfg.merge == "oracle" else None

    def _oracle(self) -> np.ndarray | None:
        """Exact flow from the new image to the previous one (``merge="oracle"`` only)."""
        snap = self._snapshot()
        flow = self.ev.flow_between(snap, self.prev_snap) if snap is not None else None
        self.prev_snap = snap or self.prev_snap
        return flow

    def run(self) -> ExplorationResult:
        """Interactions until the budget is met (a progress bar of them when ``say`` is a
        :class:`~cablesim.progress.Progress`)."""
        bar = getattr(self.say, "bar", None)
        if bar is None:
            return self._run(None)
        with bar(self.cfg.grasps, "interactions", unit="grasp") as b:
            return self._run(b)

    def _run(self, bar: Any) -> ExplorationResult:
        cfg, res = self.cfg, self.result
        while len(res.successes) < cfg.grasps and len(res.interactions) < cfg.max_attempts:
            inter = self.attempt(len(res.interactions))
            if bar is not None:
                bar.update(int(inter.success))
                bar.set_postfix(
                    attempts=len(res.interactions),
                    failed=len(res.interactions) - len(res.successes),
                )
            if self.writer is not None and not inter.success:
                self.writer.failed(inter)
            if len(res.successes) >= cfg.grasps:
                res.stop_reason = f"budget of {cfg.grasps} interactions reached"
                break
            if len(res.interactions) >= cfg.max_attempts:
                res.stop_reason = f"{cfg.max_attempts} attempts tried"
                break
            if self.merger.votes is None:
                res.stop_reason = "the first interaction failed: no votes to propose from"
                break
            nxt = self.propose()
            if nxt is None:
                res.stop_reason = "no further reachable proposal"
                break
            front = cfg.front_filter and self.session.surface.faces_camera  # not the table
            self.segment = front_segment(nxt, self.depth) if front else nxt
        if not res.stop_reason:
            res.stop_reason = "done"
        return res

    def attempt(self, k: int) -> Interaction:
        """Interaction ``k`` on the current segment, then perception and merging."""
        res, say = self.result, self.say
        grade = self.ev.grade(self.segment, True) if self.ev is not None else None
        if self.source != "start" and grade is not None:
            res.grade(grade)
        say(f"interaction {k} ({self.source}, {grade}): on {int(self.segment.sum())} px")
        t0 = time.perf_counter()
        ep = self._interact(k)
        inter = Interaction(k, ep.success, ep.reason, self.source, self.segment, grade)
        inter.outcome = ep.outcome
        inter.timings["episode"] = time.perf_counter() - t0
        # the interaction's own stages (wall s): what an explore run spends where
        inter.timings.update(
            {f"episode_{n}": v for n, v in ep.timings.items() if not n.startswith("cpu_")}
        )
        inter.episode = {
            "grasp_retries": ep.grasp_retries,
            "actions": [a.to_dict() for a in ep.actions],
            "other_hoses_max_displacement_m": ep.other_hose_displacement(),
            "details": jsonable(ep.details),
        }
        inter.grasped_hose = ep.hose
        res.interactions.append(inter)
        centre_cam = self._centre_in_camera(ep)
        if not ep.success or ep.stream is None:
            say(f"interaction {k} failed: {ep.reason}")
            if centre_cam is not None:
                self.sampler.add_grasp(centre_cam, self.segment, blacklist=True)
            # the attempt may have moved things: carry the votes into the current image
            now = self.session.capture()
            self.merger.retarget(now.rgb, self._oracle())
            self.depth, self.K = now.depth, now.intrinsics
            return inter
        self._perceive(inter, ep.stream)
        if centre_cam is not None:
            self.sampler.add_grasp(centre_cam, self.segment, blacklist=True)
            self.previous_centres.append(centre_cam)
        return inter

    def _interact(self, k: int) -> Any:
        """One interaction on the current segment, recorded as it happens when asked."""
        if self.record_to is None:
            return self.session.interact(self.segment, self.interaction_cfg, say=self.say)

        meta = {"interaction_index": k, "source": self.source, "seed": self.session.cfg.seed}
        writer = RecordingWriter(self.record_to / f"interaction{k}", meta=meta)
        try:
            ep = self.session.interact(self.segment, self.interaction_cfg, writer, self.say)
        except BaseException:
            writer.close({"result": "interrupted"}, complete=False)
            raise
        final = dict(ep.stream.meta) if ep.stream is not None else {}
        final["result"] = ep.to_dict()
        writer.close(final, complete=ep.success)
        if ep.stream is not None:
            self._write_published(k, ep.stream)
        return ep

    def _write_published(self, k: int, stream: Stream) -> None:
        """The interaction again in the published motion-correlation layout (SPEC 8), with the
        exploration's sequences listed as one multi-grasp group."""

        assert self.record_to is not None
        masks = [f.arm_mask for f in stream.frames]
        write_mcor(
            self.record_to / "mcor" / f"interaction{k}",
            stream,
            segment=self.segment,
            arm_masks=dict(enumerate(masks)) if all(m is not None for m in masks) else None,
            base_to_camera=np.linalg.inv(self.T) @ self.session.T_world_base,
        )
        self.published.append(f"interaction{k}")
        write_multigrasp(self.record_to / "mcor" / "multigrasp_sequences.json", [self.published])

    def _centre_in_camera(self, ep: Any) -> np.ndarray | None:
        if ep.centre is not None:
            T = self.T
            return ((np.asarray(ep.centre)[None] - T[:3, 3]) @ T[:3, :3])[0]
        try:  # failed before the runner estimated it: blacklist the segment all the same
            return segment_pose(self.segment, self.depth, self.K).centre
        except InputError:
            return None

    def _perceive(self, inter: Interaction, stream: Stream) -> None:
        res, cfg = self.result, self.cfg
        target = stream.target
        t0 = time.perf_counter()
        seg = segment_stream(
            stream,
            method=cfg.resolved_method,
            flow=self.flow,
            params=self.params,
            refine=cfg.refine(),
        )
        inter.timings["perception"] = time.perf_counter() - t0
        truth = self.ev.stream_truth(stream) if self.ev is not None else None
        inter.seg, inter.target_rgb, inter.target_depth = seg, target.rgb, target.depth
        inter.truth = truth
        self.merger.add(target.rgb, seg.votes, self._oracle())
        if truth is not None:
            inter.scores = scores_dict(seg.mask(1), truth)
            inter.merged = scores_dict(self.merger.mask(cfg.merged_votes), truth)
            res.final_truth = truth
        res.merged_votes = self.merger.votes
        res.final_rgb = target.rgb
        if inter.scores:
            s, m = inter.scores, inter.merged
            self.say(
                f"interaction {inter.index}: P {s['precision']:.3f} R {s['recall']:.3f} "
                f"F0.4 {s['f0.4']:.3f}; merged P {m['precision']:.3f} "
                f"R {m['recall']:.3f} F0.4 {m['f0.4']:.3f}"
            )
        self.depth, self.K = target.depth, target.intrinsics
        if self.writer is not None:
            t0 = time.perf_counter()
            self.writer.interaction(inter, stream, self.merger.votes, self.flow)
            inter.timings["pictures_video"] = time.perf_counter() - t0

    def propose(self) -> np.ndarray | None:
        """The next segment on the merged votes (``None``: no reachable proposal)."""
        votes = self.merger.votes
        assert votes is not None
        if self.cfg.strategy == "random":
            self.source = "random"
            return random_segment(
                votes,
                self.depth,
                self.K,
                self.baseline_rng,
                self.reachable,
                self.cfg.random_tries,
                previous=self.previous_centres,
            )
        self.source = "sampler"
        sr = self.sampler.propose(votes, self.depth, self.K)
        if self.ev is not None:  # grade the candidates the robot could not reach
            unreachable = [
                c
                for c in sr.candidates
                if (c.rejected or "").startswith("unreachable") and c.mask.any()
            ]
            if unreachable:
                labels = self.ev.current_labels()
                for c in unreachable:
                    self.result.grade(self.ev.grade(c.mask, False, labels))
        if sr.proposal is None:
            self.say(f"grasp sampler: no proposal ({sr.rejections()})")
            return None
        return sr.proposal.mask


def _method_params(cfg: ExploreConfig) -> Any:
    method = cfg.resolved_method
    if method == "segmentation":
        return cfg.segmentation
    if method == "ablation":
        return AblationParams()
    if method == "correlation":
        return cfg.correlation
    return None  # any other method: its own defaults


def explore(
    config: ExploreConfig | None = None,
    out: str | Path | None = None,
    progress: Say | None = None,
    flow_kwargs: dict[str, Any] | None = None,
    record_to: str | Path | None = None,
) -> ExplorationResult:
    """Run one simulated exploration (see the module docstring); with ``out`` write pictures, a
    video and ``metrics.json`` there (:mod:`cablesim.policies.report`); with ``record_to``
    record every interaction's stream there."""

    cfg = config or ExploreConfig()
    if cfg.flow == "raft":  # the checkpoint is checked before the scene is built
        check_checkpoint_file((flow_kwargs or {}).get("checkpoint"))
    say = progress or Progress("explore", cfg.progress)
    t_start = time.perf_counter()
    try:
        session = SimSession.build(cfg.episode)
    except (SceneError, PhysicsDivergedError) as e:  # a named outcome, written, not raised
        say(f"no start segment: {e.outcome}: {e}")
        failed = ExplorationResult(cfg, cfg.episode.hose, None, None)  # type: ignore[arg-type]
        failed.start_outcome, failed.stop_reason = e.outcome, f"{e.outcome}: {e}"
        failed.scene_draws = {"turned_down": getattr(e, "resamples", [])}
        failed.timings["total"] = time.perf_counter() - t_start
        if out is not None:
            writer = ExplorationWriter(Path(out), cfg)
            writer.finish(failed)
            writer.close()
        return failed
    writer = ExplorationWriter(Path(out), cfg) if out is not None else None
    w, h = session.camera.width, session.camera.height
    try:
        hose = session.draw_hose()
        say(
            f"scene seed {cfg.seed} ({len(session.world.hoses)} hoses, {w}x{h}) "
            f"ready in {session.build_time:.1f} s; hose of interest {hose}"
        )
        t0 = time.perf_counter()
        start = session.capture()
        picked = session.pick_start()
        t_pick = time.perf_counter() - t0
        say(f"start segment: {int(picked.mask.sum())} px at {picked.centre_px}")
        if writer is not None:
            writer.start(start.rgb, picked.mask)
        run = Exploration(
            session,
            cfg,
            picked.mask,
            start,
            session.evaluator(),
            writer,
            say,
            flow_kwargs,
            None if record_to is None else Path(record_to),
        )
        run.result.timings["build"] = session.build_time
        run.result.timings["start_segment"] = t_pick
        run.result.scene_draws = session.describe_draws()
        result = run.run()
        result.perturbations = list(session.perturbation.log)
        result.timings["total"] = time.perf_counter() - t_start
        if writer is not None:
            writer.finish(result)
        return result
    finally:
        session.close()
        if writer is not None:
            writer.close()


__all__ = [
    "CorrelationParams",
    "ExplorationResult",
    "Interaction",
    "explore",
    "grasp_reachability",
    "random_segment",
    "scores_dict",
]
