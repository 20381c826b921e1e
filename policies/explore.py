"""The exploration policy of the thesis (chapter 6) and two baselines, in simulation.

    from cablesim.policies import ExploreConfig, explore
    res = explore(ExploreConfig(seed=0, grasps=3), out="runs/demo")
    print(res.summary())               # precision, recall, F_0.4, IoU per interaction and merged

Loop (strategy ``sampler``): a start segment of the hose of interest (the seeded stand-in for a
person clicking, :func:`~cablesim.episode.picker.pick_segment`) -> interaction
(:func:`~cablesim.episode.runner.run_episode`: grasp, two periodic actions, retreat, target
frame) -> segmentation of the stream (motion correlation by default) -> the votes are merged
with those of earlier interactions in the latest target frame (:class:`VoteMerger`) -> the
grasp sampler proposes the next grasp on the merged votes; its reachability callback is the
robot's ``check_reachable`` on the grasp and pre-grasp poses built from the proposal's
camera-frame centre and axis (and the action end points) -> repeat until ``grasps``
interactions succeeded or ``max_attempts`` were tried.  A failed interaction (slip,
unreachable, collision) blacklists its segment and the next proposal is tried.

Baselines: ``random`` picks the next grasp at a random voted pixel (the voted pixels within
3 cm of it form the segment) instead of asking the sampler; ``push`` pokes the hose (closed
gripper, pressed and back) and segments by motion segmentation.

Neighbouring hoses can be disturbed on purpose during the actions (``config.perturb``, see
:mod:`cablesim.policies.perturb`).  Ground truth is used for evaluation only (scores, grading
of proposals) and by the start-segment picker.
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
from cablesim.errors import InputError
from cablesim.perception.correlation import CorrelationParams
from cablesim.perception.frames import Intrinsics
from cablesim.perception.geometry import eccentricity, segment_pose
from cablesim.perception.grasp_sampler import GraspSampler
from cablesim.perception.metrics import grade_proposal, score_mask
from cablesim.perception.pipeline import StreamSegmentation, segment_stream

from .config import ExploreConfig
from .merge import VoteMerger, dis_target_flow

Say = Callable[[str], None]


def scores_dict(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    s = score_mask(pred, truth)
    return {
        "precision": s.precision,
        "recall": s.recall,
        "f0.4": s.f[0.4],
        "f1": s.f[1.0],
        "iou": s.iou,
        "pixels": int(pred.sum()),
        "truth_pixels": int(truth.sum()),
    }


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

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "success": self.success,
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

    def metrics(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "seed": self.config.seed,
            "hose": self.hose,
            "strategy": self.config.strategy,
            "method": self.config.resolved_method,
            "flow": self.config.flow,
            "merge": self.config.resolved_merge,
            "merged_votes_threshold": self.config.merged_votes,
            "perturb": self.config.perturb.enabled,
            "interactions": [i.to_dict() for i in self.interactions],
            "successful_interactions": len(self.successes),
            "proposal_grades": dict(sorted(self.proposal_grades.items())),
            "merged": self.merged,
            "stop_reason": self.stop_reason,
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
            f"{'on' if self.config.perturb.enabled else 'off'}"
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
        return "\n".join(lines)


# ---------------------------------------------------------------------- helpers
def grasp_reachability(robot: Any, T_world_camera: np.ndarray, ep_cfg: Any) -> Callable:
    """The sampler's reachability callback: the robot's ``check_reachable`` on the grasp and
    pre-grasp poses built from a camera-frame (centre, axis), and on the action end points."""
    from cablesim.episode import primitives as prim

    T = np.asarray(T_world_camera, float)
    approach = np.asarray(prim.DEFAULT_APPROACH, float)

    def reachable(centre_cam: np.ndarray, axis_cam: np.ndarray) -> tuple[bool, str]:
        R, t = T[:3, :3], T[:3, 3]
        ray = R @ (centre_cam / np.linalg.norm(centre_cam))
        centre = R @ centre_cam + t + ep_cfg.grasp.surface_offset * ray
        axis = R @ axis_cam
        g, why = prim.choose_grasp_pose(robot, centre, axis, approach, ep_cfg.grasp.pregrasp_offset)
        if g is None:
            return False, why
        if ep_cfg.kind == "grasp":
            for label, u in prim.action_directions(ep_cfg.actions, axis, T, approach):
                for s in (1.0, -1.0):
                    ok, why = robot.check_reachable(g.translated(s * ep_cfg.actions.amplitude * u))
                    if not ok:
                        return False, f"action {label} end point: {why}"
        return True, ""

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


class _Progress:
    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if self.enabled:
            print(f"[explore {time.perf_counter() - self.t0:6.1f}s] {msg}", flush=True)


# ---------------------------------------------------------------------- the loop
def explore(
    config: ExploreConfig | None = None,
    out: str | Path | None = None,
    progress: Say | None = None,
    flow_kwargs: dict[str, Any] | None = None,
) -> ExplorationResult:
    """Run one exploration (see the module docstring); with ``out`` write pictures, a video
    and ``metrics.json`` there (:mod:`cablesim.policies.report`)."""
    from cablesim.episode.picker import pick_segment
    from cablesim.episode.runner import run_episode
    from cablesim.robot.sim_panda import SimPanda
    from cablesim.sim.camera import SimCamera
    from cablesim.sim.layout import rng_streams
    from cablesim.sim.world import World

    from .perturb import PerturbedWorld
    from .report import ExplorationWriter

    cfg = (config or ExploreConfig()).validate()
    say = progress or _Progress(cfg.progress)
    ep_cfg = cfg.episode_config()
    t_start = time.perf_counter()
    world = World.build(ep_cfg.scene_config())
    world.reset()
    streams = rng_streams(cfg.seed)
    rng = streams["episode"]
    hose = cfg.hose if cfg.hose is not None else int(rng.integers(len(world.hoses)))
    ep_cfg = ep_cfg.replace(hose=hose)
    pw = PerturbedWorld(world, cfg.perturb, hose_of_interest=hose, seed=cfg.seed)
    robot = SimPanda(pw)
    camera = SimCamera(pw)
    T = np.asarray(camera.T_world_camera, float)
    writer = ExplorationWriter(Path(out), cfg) if out is not None else None
    build_s = time.perf_counter() - t_start
    say(
        f"scene seed {cfg.seed} ({len(world.hoses)} hoses, {camera.width}x{camera.height}) "
        f"ready in {build_s:.1f} s; hose of interest {hose}"
    )
    try:
        start = camera.capture()
        picked = pick_segment(pw, robot, camera, hose, rng, ep_cfg)
        say(f"start segment: {int(picked.mask.sum())} px at {picked.centre_px}")
        result = ExplorationResult(cfg, hose, start.rgb, picked.mask)
        result.timings["build"] = build_s
        if writer is not None:
            writer.start(start.rgb, picked.mask)
        reachable = grasp_reachability(robot, T, ep_cfg)
        sampler = GraspSampler(cfg.sampler, reachability=reachable)
        merge = cfg.resolved_merge
        merger = VoteMerger(dis_target_flow() if merge == "dis" else None)
        base_rng = np.random.default_rng([cfg.seed, 0xBA5E])
        method = cfg.resolved_method
        params = cfg.segmentation if method == "segmentation" else cfg.correlation
        if method == "ablation":
            from cablesim.perception.correlation import AblationParams

            params = AblationParams()
        segment, source = picked.mask, "start"
        prev_snap = camera.snapshot() if merge == "oracle" else None
        previous_centres: list[np.ndarray] = []
        depth, K = start.depth, start.intrinsics  # the image the current segment lies in
        while len(result.successes) < cfg.grasps and len(result.interactions) < cfg.max_attempts:
            k = len(result.interactions)
            labels_now = camera.render_labels()
            grade = grade_proposal(segment, labels_now, hose, True)
            if source != "start":
                result.grade(grade)
            say(f"interaction {k} ({source}, {grade}): {cfg.kind} on {int(segment.sum())} px")
            t0 = time.perf_counter()
            ep = run_episode(pw, robot, camera, segment, ep_cfg)
            inter = Interaction(k, ep.success, ep.reason, source, segment, grade)
            inter.timings["episode"] = time.perf_counter() - t0
            inter.episode = {
                "actions": [a.to_dict() for a in ep.actions],
                "other_hoses_max_displacement_m": ep.other_hose_displacement(),
            }
            inter.grasped_hose = ep.hose
            result.interactions.append(inter)
            centre_cam = None
            if ep.centre is not None:
                centre_cam = world.world_to_camera(ep.centre[None])[0]
            else:  # failed before the runner estimated it: blacklist the segment all the same
                try:
                    centre_cam = segment_pose(segment, depth, K).centre
                except InputError:
                    pass
            if not ep.success or ep.stream is None:
                say(f"interaction {k} failed: {ep.reason}")
                if centre_cam is not None:
                    sampler.add_grasp(centre_cam, segment, blacklist=True)
                # the attempt may have moved things: carry the votes into the current image
                now = camera.capture()
                snap = camera.snapshot() if merge == "oracle" else None
                merger.retarget(now.rgb, _oracle(snap, prev_snap))
                prev_snap = snap or prev_snap
                depth, K = now.depth, now.intrinsics
            else:
                stream = ep.stream
                target = stream.target
                t0 = time.perf_counter()
                seg = segment_stream(
                    stream,
                    method=method,
                    flow=_flow(cfg.flow, flow_kwargs),
                    params=params,
                )
                inter.timings["perception"] = time.perf_counter() - t0
                truth = target.truth.labels == hose if target.truth is not None else None
                inter.seg, inter.target_rgb, inter.target_depth = seg, target.rgb, target.depth
                inter.truth = truth
                snap = camera.snapshot() if merge == "oracle" else None
                merger.add(target.rgb, seg.votes, _oracle(snap, prev_snap))
                prev_snap = snap
                if truth is not None:
                    inter.scores = scores_dict(seg.mask(1), truth)
                    inter.merged = scores_dict(merger.mask(cfg.merged_votes), truth)
                    result.final_truth = truth
                inter.flow_example = _flow_example(stream, cfg.flow, flow_kwargs)
                result.merged_votes = merger.votes
                result.final_rgb = target.rgb
                if centre_cam is not None:
                    sampler.add_grasp(centre_cam, segment, blacklist=True)
                    previous_centres.append(centre_cam)
                if inter.scores:
                    s, m = inter.scores, inter.merged
                    say(
                        f"interaction {k}: P {s['precision']:.3f} R {s['recall']:.3f} "
                        f"F0.4 {s['f0.4']:.3f}; merged P {m['precision']:.3f} "
                        f"R {m['recall']:.3f} F0.4 {m['f0.4']:.3f}"
                    )
                depth, K = target.depth, target.intrinsics
                if writer is not None:
                    writer.interaction(inter, stream, merger.votes)
            if writer is not None and not inter.success:
                writer.failed(inter)
            if len(result.successes) >= cfg.grasps:
                result.stop_reason = f"budget of {cfg.grasps} interactions reached"
                break
            if len(result.interactions) >= cfg.max_attempts:
                result.stop_reason = f"{cfg.max_attempts} attempts tried"
                break
            # next segment on the merged votes
            if merger.votes is None:
                result.stop_reason = "the first interaction failed: no votes to propose from"
                break
            if cfg.strategy == "random":
                nxt = random_segment(
                    merger.votes,
                    depth,
                    K,
                    base_rng,
                    reachable,
                    cfg.random_tries,
                    previous=previous_centres,
                )
                source = "random"
            else:
                sr = sampler.propose(merger.votes, depth, K)
                nxt = None if sr.proposal is None else sr.proposal.mask
                source = "sampler"
                unreachable = [
                    c
                    for c in sr.candidates
                    if (c.rejected or "").startswith("unreachable") and c.mask.any()
                ]
                if unreachable:
                    labels_now = camera.render_labels()  # ground truth, for grading only
                    for c in unreachable:
                        result.grade(grade_proposal(c.mask, labels_now, hose, False))
                if sr.proposal is None:
                    say(f"grasp sampler: no proposal ({sr.rejections()})")
            if nxt is None:
                result.stop_reason = "no further reachable proposal"
                break
            segment = front_segment(nxt, depth) if cfg.front_filter else nxt
        if not result.stop_reason:
            result.stop_reason = "done"
        result.perturbations = list(pw.log)
        result.timings["total"] = time.perf_counter() - t_start
        if writer is not None:
            writer.finish(result)
        return result
    finally:
        camera.close()
        if writer is not None:
            writer.close()


def _flow(name: str, kwargs: dict[str, Any] | None) -> Any:
    from cablesim.perception.flow import make_flow

    return make_flow(name, **(kwargs or {}))


def _oracle(new_snap: Any, prev_snap: Any) -> np.ndarray | None:
    """Ground-truth flow new -> previous target (new(p) = previous(p + f)), or None."""
    if new_snap is None or prev_snap is None:
        return None
    from cablesim.sim.flow_gt import gt_flow

    flow, valid = gt_flow(new_snap, prev_snap)[:2]
    flow = np.where(valid[..., None], flow, 0.0).astype(np.float32)
    return flow


def _flow_example(
    stream: Any, flow: str, kwargs: dict[str, Any] | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Flow of the kept frame farthest from the target (estimated, ground truth)."""
    frames = [f for f in stream.frames if not f.is_target and f.truth is not None]
    if not frames:
        return None
    target = stream.target
    g1 = frames[0].gripper
    f = max(frames, key=lambda fr: float(np.linalg.norm(fr.gripper - g1)))
    est = _flow(flow, kwargs).frame_flow(f, target)
    gt = f.truth.flow_to_target
    if gt is None:
        return None
    gt = np.where(f.truth.flow_valid[..., None], gt, 0.0) if f.truth.flow_valid is not None else gt
    return est, np.asarray(gt, np.float32)


__all__ = [
    "CorrelationParams",
    "ExplorationResult",
    "Interaction",
    "explore",
    "grasp_reachability",
    "random_segment",
    "scores_dict",
]
