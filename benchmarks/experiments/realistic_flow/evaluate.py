"""Perception half of ``python -m benchmarks.experiments.realistic_flow``: variants on the
recorded streams.

A recorded stream is read lean (RGB, arm mask and gripper of every frame; depth and labels of
the target only), optionally given the camera's noise models (:mod:`cablesim.sim.sensor`,
seeded from the scene's ``rgb_noise`` / ``depth_noise`` streams, frames in order), and every
flow back end runs **once** per stream while one set of accumulators per per-sample variant
(arm masks, photometric check, forward-backward) consumes it -- the same accumulators and
filters :func:`cablesim.perception.pipeline.compute_statistics` uses (``check_equivalence``
shows the result is identical).  What threshold tuning needs of the statistics (|c0|, R^2,
std(d_phi), vote fractions) is cached per (scene, noise, flow, variant) as float16 maps, so
the support variants (foreground, contrast: target-frame cues) and the tuning run without
recomputing flow.  Thresholds are tuned by :mod:`cablesim.perception.tuning` and masks scored
by :mod:`cablesim.perception.metrics`, the rules of the thesis protocol (SPEC sections 7-8).
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.experiments.realistic_flow.record import Scene
from cablesim.frames import Frame, FrameTruth, Intrinsics, Stream
from cablesim.perception.actions import action_direction
from cablesim.perception.correlation import (
    CorrelationAccumulator,
    CorrelationParams,
    CorrelationResult,
)
from cablesim.perception.flow import DISFlow, FlowEstimator, OracleFlow, make_flow
from cablesim.perception.flow_region import FlowRegion, RegionFlow
from cablesim.perception.learned import LearnedFlow, weights_path
from cablesim.perception.methods import make_method
from cablesim.perception.metrics import nanmean, score_mask
from cablesim.perception.pipeline import StreamStatistics, plan_jobs
from cablesim.perception.refine import (
    ContrastParams,
    ForegroundParams,
    RefineParams,
    SampleFilter,
    contrast_mask,
    foreground_mask,
)
from cablesim.perception.registry import parse_spec
from cablesim.perception.segmentation import SegmentationAccumulator, SegmentationResult
from cablesim.perception.tuning import TuningResult, TuningRow, tune_thresholds


# --------------------------------------------------------------------------------- streams
def _load_npz(path: Path, keys: Sequence[str]) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in keys if k in z.files}


@dataclass
class LeanStream:
    scene: Scene
    stream: Stream
    hose: int
    truth: np.ndarray  # the grasped hose in the target frame
    labels: np.ndarray  # target labels
    clean_depth: np.ndarray  # target depth without noise
    flow_files: dict[int, Path]  # id(frame) -> its ground-truth flow file
    meta: dict[str, Any] = field(default_factory=dict)


def load_stream(scene: Scene, noisy: bool) -> LeanStream:
    """The recorded stream of ``scene`` (module docstring); ``noisy`` applies the sensor models
    of ``CameraConfig.realistic()`` (RGB of every frame, depth of the target)."""
    from cablesim.seeding import stream as rng_stream
    from cablesim.sim.config import CameraConfig
    from cablesim.sim.sensor import rgb_sensor, stereo_depth

    root = scene.path
    doc = json.loads((root / "meta.json").read_text())
    K = Intrinsics.from_dict(doc["intrinsics"])
    entries = [json.loads(x) for x in (root / "index.jsonl").read_text().splitlines() if x.strip()]
    frames_e = sorted((e for e in entries if e["kind"] == "frame"), key=lambda e: e["i"])
    flows_e = {e["i"]: root / e["file"] for e in entries if e["kind"] == "flow"}
    cam = CameraConfig.realistic()
    rgb_rng = rng_stream(scene.seed, "rgb_noise")
    depth_rng = rng_stream(scene.seed, "depth_noise")
    frames: list[Frame] = []
    files: dict[int, Path] = {}
    n = len(frames_e)
    labels = clean_depth = None
    hose = -1
    for j, e in enumerate(frames_e):
        last = j == n - 1
        keys = ["rgb", "gripper", "action", "sample", "timestamp", "arm_mask"]
        if last:
            keys += ["depth", "labels", "grasped_hose"]
        a = _load_npz(root / e["file"], keys)
        rgb = a["rgb"]
        if noisy:
            rgb = rgb_sensor(rgb, cam.rgb_sensor, rgb_rng)
        depth = None
        truth = None
        if last:
            clean_depth = a["depth"]
            depth = (
                stereo_depth(clean_depth, cam.depth_stereo, K.f, depth_rng)
                if noisy
                else clean_depth
            )
            labels = a["labels"]
            hose = int(a["grasped_hose"])
            truth = FrameTruth(labels=labels, grasped_hose=hose)
        f = Frame(
            rgb=rgb,
            depth=depth,
            intrinsics=K,
            gripper=a["gripper"],
            action=int(a["action"]),
            sample=int(a["sample"]),
            timestamp=float(a["timestamp"]),
            truth=truth,
            arm_mask=a.get("arm_mask"),
        )
        if e["i"] in flows_e:
            files[id(f)] = flows_e[e["i"]]
        frames.append(f)
    meta = doc.get("meta") or {}
    if hose < 0:
        hose = int(meta.get("hose", -1))
    assert labels is not None and clean_depth is not None
    return LeanStream(
        scene, Stream(frames, meta), hose, labels == hose, labels, clean_depth, files, meta
    )


class RecordedOracle(OracleFlow):
    """The recorded ground-truth flow, read frame by frame from the recording."""

    def __init__(self, lean: LeanStream) -> None:
        super().__init__()
        self.files = lean.flow_files

    def frame_flow(self, frame: Frame, target: Frame) -> np.ndarray:
        h, w = target.shape
        if frame is target:
            return np.zeros((h, w, 2), np.float32)
        a = _load_npz(self.files[id(frame)], ["flow_to_target", "flow_valid"])
        flow = np.array(a["flow_to_target"], np.float32)
        flow[~a["flow_valid"]] = 0.0
        flow[~np.isfinite(flow)] = 0.0
        return flow


# --------------------------------------------------------------------------------- variants
def board_crop(scene: Scene, K: Intrinsics, margin: int = 8) -> tuple[int, int, int, int]:
    from cablesim.sim.regions import board_region

    return board_region(scene.config().scene, K, margin)


def _fine(**overrides: int) -> DISFlow:
    """DIS ``fine`` as these results name it (before issue 21's default): OpenCV's medium
    preset with 8 px patches every 4 px at half resolution and the preset's 5 variational
    refinement iterations; ``overrides`` change settings of :class:`DISFlow`."""
    return DISFlow("medium", **{"finest_scale": 1, "patch_size": 8, "patch_stride": 4, **overrides})


FLOWS: dict[str, Callable[[LeanStream], FlowEstimator]] = {
    "oracle": lambda s: RecordedOracle(s),
    "dis-medium": lambda s: DISFlow("medium"),
    "dis-fast": lambda s: DISFlow("fast"),
    "dis-fine": lambda s: _fine(),
    "dis-fine-gd12": lambda s: _fine(gradient_descent_iters=12),
    "dis-fine-vr10": lambda s: _fine(variational_refinement_iters=10),
    # issue 21's cheaper DIS settings, screened on the validation scenes (noisy, arm+normal,
    # fg-c3): fewer variational refinement iterations (5 in the medium preset) and patches
    # every 6 px; "dis-fine-vr1" became the default ``fine`` (cablesim.perception.flow)
    "dis-fine-vr3": lambda s: _fine(variational_refinement_iters=3),
    "dis-fine-vr2": lambda s: _fine(variational_refinement_iters=2),
    "dis-fine-vr1": lambda s: _fine(variational_refinement_iters=1),
    "dis-fine-vr0": lambda s: _fine(variational_refinement_iters=0),
    "dis-fine-s6": lambda s: _fine(patch_stride=6),
    "dis-fine-s6vr2": lambda s: _fine(patch_stride=6, variational_refinement_iters=2),
    # the default flow on the board's (the table's mat's) crop, not scaled: issue 21's lever
    # "perception where hoses can move"
    "dis-fine-board": lambda s: RegionFlow(
        FLOWS["dis-fine"](s), FlowRegion.from_crop(board_crop(s.scene, s.stream.intrinsics))
    ),
    "dis-medium-board1.5": lambda s: RegionFlow(
        DISFlow("medium"), FlowRegion.from_crop(board_crop(s.scene, s.stream.intrinsics), 1.5)
    ),
    "dis-fast-board1.5": lambda s: RegionFlow(
        DISFlow("fast"), FlowRegion.from_crop(board_crop(s.scene, s.stream.intrinsics), 1.5)
    ),
    # the shipped learned flow (issue 23): DIS medium gated by the network's moving probability
    "learned": lambda s: LearnedFlow(),
}


def is_learned(flow: str) -> bool:
    """Whether ``flow`` is a spec of the learned back end (``learned,weights=raft,...``)."""
    return parse_spec(flow, "flow").target == "learned"


def flow_for(flow: str, lean: LeanStream) -> FlowEstimator:
    """The estimator of ``flow``: a name of :data:`FLOWS`, or any spec of the learned back
    end (``learned,weights=raft,gate=null``: the options of
    :class:`cablesim.perception.learned.LearnedFlow`)."""
    if flow in FLOWS:
        return FLOWS[flow](lean)
    if is_learned(flow):
        return make_flow(flow)
    raise KeyError(f"unknown flow {flow!r}: one of {sorted(FLOWS)} or a learned flow spec")


SAMPLES: dict[str, RefineParams] = {
    "raw": RefineParams(arm_masks=False),
    "arm": RefineParams(arm_masks=True),
    "arm+normal": RefineParams(normal_flow=1.5),
    "arm+photo20": RefineParams(photometric=20.0),
    "arm+photo30": RefineParams(photometric=30.0),
    "arm+photo45": RefineParams(photometric=45.0),
    "arm+fb1": RefineParams(forward_backward=1.0),
}

SUPPORTS: dict[str, RefineParams | None] = {
    "none": None,
    "fg": RefineParams(foreground=ForegroundParams()),
    "fg-d1": RefineParams(foreground=ForegroundParams(dilate_px=1)),
    "fg-h8": RefineParams(foreground=ForegroundParams(min_height=0.008)),
    "fg-c2": RefineParams(foreground=ForegroundParams(colour_px=2)),
    "fg-c3": RefineParams(foreground=ForegroundParams(colour_px=3)),
    "fg-c4": RefineParams(foreground=ForegroundParams(colour_px=4)),
    "fg-c3-w5": RefineParams(foreground=ForegroundParams(colour_px=3, window_m=0.05)),
    "fg-c3-w7": RefineParams(foreground=ForegroundParams(colour_px=3, window_m=0.07)),
    "fg-c3-h3": RefineParams(foreground=ForegroundParams(colour_px=3, min_height=0.003)),
    # half a 2 mm thin wire's height: a wire lying on the table never stands the default 5 mm
    "fg-c3-h1": RefineParams(foreground=ForegroundParams(colour_px=3, min_height=0.001)),
    "contrast": RefineParams(contrast=ContrastParams()),
    "fg&contrast": RefineParams(foreground=ForegroundParams(), contrast=ContrastParams()),
}


def support_for(name: str, target: Frame) -> np.ndarray | None:
    p = SUPPORTS[name]
    if p is None:
        return None
    out = None
    if p.foreground is not None:
        out = foreground_mask(target.depth, target.intrinsics, p.foreground, target.rgb)
    if p.contrast is not None:
        c = contrast_mask(target.rgb, target.intrinsics, target.depth, p.contrast)
        out = c if out is None else out & c
    return out


# --------------------------------------------------------------------------------- statistics
@dataclass
class Timing:
    flow_s: float = 0.0
    frames: int = 0
    per_variant_s: dict[str, float] = field(default_factory=dict)


def compute_variants(
    lean: LeanStream, flow: FlowEstimator, samples: Sequence[str], timing: Timing | None = None
) -> dict[str, StreamStatistics]:
    """One flow pass over the stream; one set of accumulators per per-sample variant."""
    stream = lean.stream
    target = stream.target
    shape, focal = target.shape, target.intrinsics.f
    jobs = plan_jobs(stream)
    checks = {s: SampleFilter(SAMPLES[s], target, flow) for s in samples}
    corr: dict[str, dict[int, CorrelationAccumulator]] = {s: {} for s in samples}
    seg: dict[str, dict[int, SegmentationAccumulator]] = {s: {} for s in samples}
    counts: dict[int, int] = {}
    for job in jobs:
        t0 = time.process_time()
        phi = flow.frame_flow(job.frame, target)
        if timing is not None:
            timing.flow_s += time.process_time() - t0
            timing.frames += 1
        a = job.action
        counts[a] = counts.get(a, 0) + 1
        for s in samples:
            t1 = time.process_time()
            ph = checks[s].apply(phi, job.frame) if SAMPLES[s].per_sample else phi
            if a not in corr[s]:
                corr[s][a] = CorrelationAccumulator(shape, focal, CorrelationParams(), target.depth)
                seg[s][a] = SegmentationAccumulator(shape)
            corr[s][a].update(ph, job.d_g, job.z)
            seg[s][a].update(ph)
            if timing is not None:
                timing.per_variant_s[s] = (
                    timing.per_variant_s.get(s, 0.0) + time.process_time() - t1
                )
    actions = sorted(counts)
    out = {}
    for s in samples:
        out[s] = StreamStatistics(
            shape=shape,
            actions=actions,
            n_samples=counts,
            correlation={a: acc.result() for a, acc in corr[s].items()},
            segmentation={a: acc.result() for a, acc in seg[s].items()},
            directions={a: action_direction(stream.action_frames(a)) for a in actions},
            flow=flow.describe(),
            support=~target.arm_mask
            if SAMPLES[s].arm_masks and target.arm_mask is not None
            else None,
        )
    return out


def _stats_path(scene: Scene, noisy: bool, flow: str, sample: str) -> Path:
    if flow == "oracle" and SAMPLES[sample].photometric is None:
        noisy = False  # ground-truth flow and arm masks do not see the sensor noise
    return scene.stats_path / ("noisy" if noisy else "clean") / _flow_dir(flow) / f"{sample}.npz"


@lru_cache(maxsize=8)
def _weights_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:12]


def _flow_dir(flow: str) -> str:
    """The statistics folder of ``flow``: a learned flow's names the weights file it runs
    (``learned`` -> ``learned-<sha12>``; new weights never read the statistics of the ones
    before, whichever file or shipped name the spec gives)."""
    spec = parse_spec(flow, "flow")
    if spec.target != "learned":
        return flow
    return f"{flow}-{_weights_digest(weights_path(spec.params.get('weights')))}"


def save_stats(path: Path, st: StreamStatistics) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"actions": np.array(st.actions), "shape": np.array(st.shape)}
    for a in st.actions:
        c = st.correlation[a]
        arrays[f"c0_{a}"] = np.abs(c.c0).astype(np.float16)
        arrays[f"r2_{a}"] = c.r2.astype(np.float16)
        arrays[f"std_{a}"] = c.std_dphi.astype(np.float32)
        sr = st.segmentation[a]
        arrays[f"votes_{a}"] = sr.votes.astype(np.uint16)
        arrays[f"nseg_{a}"] = np.array(sr.n_samples)
        arrays[f"ncorr_{a}"] = np.array(c.n_samples)
    if st.support is not None:
        arrays["support"] = st.support
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)


def load_stats(path: Path) -> StreamStatistics:
    with np.load(path, allow_pickle=False) as z:
        actions = [int(a) for a in z["actions"]]
        shape = tuple(int(x) for x in z["shape"])
        corr, seg = {}, {}
        zero = np.zeros(shape, np.float32)
        for a in actions:
            c0 = z[f"c0_{a}"].astype(np.float32)
            corr[a] = CorrelationResult(
                n=zero,
                c0=c0,
                c1=zero,
                r2=z[f"r2_{a}"].astype(np.float32),
                psi=np.zeros((*shape, 2), np.float32),
                std_dphi=z[f"std_{a}"],
                n_samples=int(z[f"ncorr_{a}"]),
            )
            seg[a] = SegmentationResult(z[f"votes_{a}"].astype(np.float32), int(z[f"nseg_{a}"]))
        support = z["support"] if "support" in z.files else None
    return StreamStatistics(
        shape=shape,  # type: ignore[arg-type]
        actions=actions,
        n_samples={},
        correlation=corr,
        segmentation=seg,
        support=support,
    )


def ensure_stats(
    scenes: Sequence[Scene],
    noisy: bool,
    plan: dict[str, Sequence[str]],
    log=print,
) -> dict[str, Any]:
    """Compute (or find cached) statistics of every scene for ``plan`` (flow -> per-sample
    variants); returns per-frame timings (CPU ms) of what was computed."""
    timings: dict[str, Any] = {}
    for sc in scenes:
        todo = {
            f: [s for s in samples if not _stats_path(sc, noisy, f, s).exists()]
            for f, samples in plan.items()
        }
        todo = {f: s for f, s in todo.items() if s}
        if not todo:
            continue
        t0 = time.time()
        lean = load_stream(sc, noisy)
        # the target-frame cues need the target: keep it beside the statistics
        tpath = sc.stats_path / ("noisy" if noisy else "clean") / "target.npz"
        if not tpath.exists():
            tpath.parent.mkdir(parents=True, exist_ok=True)
            t = lean.stream.target
            np.savez_compressed(
                tpath,
                rgb=t.rgb,
                depth=t.depth,
                labels=lean.labels,
                hose=np.array(lean.hose),
                clean_depth=lean.clean_depth,
                arm=t.arm_mask if t.arm_mask is not None else np.zeros(t.shape, bool),
                K=np.array(
                    [
                        t.intrinsics.fx,
                        t.intrinsics.fy,
                        t.intrinsics.cx,
                        t.intrinsics.cy,
                        t.intrinsics.width,
                        t.intrinsics.height,
                    ]
                ),
            )
        for f, ss in todo.items():
            tm = Timing()
            est = flow_for(f, lean)
            stats = compute_variants(lean, est, ss, tm)
            for s, st in stats.items():
                save_stats(_stats_path(sc, noisy, f, s), st)
            timings[f"{sc.name}/{f}"] = {
                "flow_ms": 1e3 * tm.flow_s / max(tm.frames, 1),
                **{s: 1e3 * v / max(tm.frames, 1) for s, v in tm.per_variant_s.items()},
            }
        log(
            f"  {sc.name} {'noisy' if noisy else 'clean'}: {sorted(todo)} in {time.time() - t0:.0f} s"
        )
        del lean
    return timings


@dataclass
class Target:
    rgb: np.ndarray
    depth: np.ndarray
    clean_depth: np.ndarray
    labels: np.ndarray
    hose: int
    arm: np.ndarray
    K: Intrinsics

    @property
    def truth(self) -> np.ndarray:
        return self.labels == self.hose

    def frame(self, clean_depth: bool = False) -> Frame:
        return Frame(
            self.rgb,
            self.clean_depth if clean_depth else self.depth,
            self.K,
            np.zeros(3),
            arm_mask=self.arm,
        )


def load_target(scene: Scene, noisy: bool) -> Target:
    p = scene.stats_path / ("noisy" if noisy else "clean") / "target.npz"
    with np.load(p) as z:
        k = z["K"]
        K = Intrinsics(float(k[0]), float(k[1]), float(k[2]), float(k[3]), int(k[4]), int(k[5]))
        return Target(
            z["rgb"], z["depth"], z["clean_depth"], z["labels"], int(z["hose"]), z["arm"], K
        )


def stats_for(scene: Scene, noisy: bool, flow: str, sample: str) -> StreamStatistics:
    return load_stats(_stats_path(scene, noisy, flow, sample))


# --------------------------------------------------------------------------------- tuning
#: the thresholds tried: the methods' own grids (:meth:`~cablesim.perception.methods.
#: SegmentationMethod.grid`), the ablation's std(d_phi) up to 5 cm
GRIDS: dict[str, dict[str, np.ndarray]] = {
    "ablation": {"std_min": np.round(np.arange(0.0, 0.05, 0.0005), 6)},
}
BETAS = (1.0, 0.5, 0.4, 0.3)


def tune(
    stats: Sequence[StreamStatistics], truths: Sequence[np.ndarray], method: str
) -> TuningResult:
    """Thresholds maximising the mean F_beta over the sequences, per beta of :data:`BETAS`;
    union of the actions: :func:`cablesim.perception.tuning.tune_thresholds` (SPEC sections 7
    and 8: an undefined score, e.g. the precision of an empty prediction, is NaN and left out
    of the mean)."""
    return tune_thresholds(stats, truths, method, BETAS, n=1, grid=GRIDS.get(method))


def validation_scores(row: TuningRow) -> dict[str, float]:
    """The validation means at a tuned row's thresholds, as the report names them."""
    return {"precision": row.precision, "recall": row.recall, "f": row.f_beta, "iou": row.iou}


def union_mask(st: StreamStatistics, method: str, pr: dict[str, float]) -> np.ndarray:
    """The union (>= 1 vote) mask at the thresholds ``pr``; with ``st.grow`` each action's
    mask grows along the colour first, as ``masks_from_statistics`` does."""
    if st.grow is not None and st.guide is not None:
        from cablesim.perception.refine import grow_by_colour

        out = np.zeros(st.shape, bool)
        for a in st.actions:
            one = type(st)(**{**st.__dict__, "actions": [a]})
            one.grow = None
            m = union_mask(one, method, pr)
            out |= grow_by_colour(m, st.guide, st.grow, st.support)
        return out
    m = make_method(method)
    outer = None if m.outer_threshold is None else pr[m.outer_threshold]
    return m.score(st, 1, outer) > pr[m.threshold]


def score_row(preds: Sequence[np.ndarray], truths: Sequence[np.ndarray], beta: float = 0.4) -> dict:
    """Mean over sequences of :func:`cablesim.perception.metrics.score_mask` (SPEC sections 7
    and 8: NaN scores, e.g. the precision of an empty prediction, left out of the means);
    ``empty``: the sequences whose prediction was empty."""
    scores = [score_mask(m, t, (beta,)) for m, t in zip(preds, truths, strict=True)]
    P = np.array([s.precision for s in scores], float)

    def real(x: float) -> float | None:
        return None if not np.isfinite(x) else float(x)

    return {
        "precision": nanmean(P),
        "recall": nanmean(s.recall for s in scores),
        "f": nanmean(s.f[beta] for s in scores),
        "iou": nanmean(s.iou for s in scores),
        "empty": int(np.sum(~np.isfinite(P))),
        "n": len(scores),
        "per_scene": [
            {"precision": real(s.precision), "recall": s.recall, "f": s.f[beta], "iou": s.iou}
            for s in scores
        ],
    }


def fp_near_hose(preds: Sequence[np.ndarray], targets: Sequence[Target], px: float = 5.0) -> float:
    """Share of all false positives that lie on a hose or within ``px`` of one."""
    import cv2

    near = far = 0
    for m, tg in zip(preds, targets, strict=True):
        fp = m & ~tg.truth
        hose = (tg.labels >= 0).astype(np.uint8)
        d = cv2.distanceTransform(1 - hose, cv2.DIST_L2, 5)
        near += int((fp & (d <= px)).sum())
        far += int((fp & (d > px)).sum())
    return near / max(near + far, 1)


# --------------------------------------------------------------------------------- proposals
def grade_proposals(scene: Scene, votes: dict[str, np.ndarray], tg: Target) -> dict[str, Any]:
    """The grasp sampler's next proposal from each vote image of ``votes`` (one grasp done),
    as the exploration loop makes it: the robot's reachability callback, the first grasp
    recorded as a previous (blacklisted) grasp, the front-most part of the proposal kept;
    graded against the target labels (SPEC 7), with every candidate the robot could not
    reach graded too (unreachable).  One simulated session (for the robot) per scene."""
    from cablesim.perception.grasp_sampler import GraspSampler
    from cablesim.perception.metrics import grade_proposal
    from cablesim.policies.explore import front_segment, grasp_reachability
    from cablesim.sim.session import SimSession

    meta = json.loads((scene.path / "meta.json").read_text())["meta"]
    T = np.asarray(meta["T_world_camera"], float)
    seg = np.zeros(tg.truth.shape, bool)
    px = np.asarray(meta["segment_px"], int)
    seg[px[:, 1], px[:, 0]] = True
    centre = meta["result"].get("centre")
    c_cam = None if centre is None else ((np.asarray(centre)[None] - T[:3, 3]) @ T[:3, :3])[0]
    session = SimSession.build(scene.config())
    out: dict[str, Any] = {}
    try:
        reach = grasp_reachability(session.robot, T, session.interaction_config(), session.surface)
        for name, v in votes.items():
            sampler = GraspSampler(reachability=reach)
            if c_cam is not None:
                sampler.add_grasp(c_cam, seg, blacklist=True)
            sr = sampler.propose(v.astype(np.int32), tg.depth, tg.K)
            grades: list[str] = []
            for c in sr.candidates:
                if (c.rejected or "").startswith("unreachable") and c.mask.any():
                    grades.append(grade_proposal(c.mask, tg.labels, tg.hose, False))
            first = None
            if sr.proposal is not None:
                chosen = front_segment(sr.proposal.mask, tg.depth)
                first = grade_proposal(chosen, tg.labels, tg.hose, True)
                grades.append(first)
            out[name] = {"proposal": first, "grades": grades, "rejections": sr.rejections()}
    finally:
        session.close()
    return out
