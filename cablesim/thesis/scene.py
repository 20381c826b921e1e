"""The per-scene jobs of ``cablesim benchmark thesis`` (run in worker processes or on Ray).

- :func:`run_interaction`: one grasp interaction (two actions) of a scene, simulated once (the
  stream is recorded to the cache and replayed when the job runs again), then for every flow
  back end the statistics of every method (the thesis's three unless the job names others:
  any spec of :data:`~cablesim.perception.methods.SEGMENTATION_METHODS`) and their confusion
  counts over the threshold grids, for the union and the intersection of the two actions
  (:class:`~cablesim.perception.tuning.ThresholdCounts`): the tuning on validation and the
  scores on test are computed later from these counts alone.
- :func:`run_exploration`: two grasps (grasp sampler on the merged votes): the grades of every
  grasp proposal (table 6.8) and the scores of one and two grasps at each action threshold
  (table 6.9).
- :func:`run_clip`: a MovingCables clip of one moving hose (written to the dataset folder) and
  the published flow evaluation of each flow back end at each motion threshold (chapter 5).

Undefined scores (the precision of an empty prediction) are stored as null and left out of
the means, as the published evaluation does.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from cablesim.dataset.generate import (
    clip_name,
    failure,
    outcome_of,
    scene_from,
    simulate_clip,
    write_sim_clip,
)
from cablesim.errors import CablesimError
from cablesim.errors import outcome_of as error_outcome
from cablesim.files import waiting_lock, write_text
from cablesim.formats.movingcables import STATIC_THRESHOLD, PublishedFarneback, read_clip
from cablesim.perception.correlation import CorrelationParams
from cablesim.perception.flow import make_flow
from cablesim.perception.metrics import movingcables_frame, score_mask
from cablesim.perception.pipeline import (
    compute_statistics,
    masks_from_statistics,
    params_for_beta,
)
from cablesim.perception.tuning import threshold_counts
from cablesim.perception.votes import merge_votes, vote_image
from cablesim.policies.config import ExploreConfig
from cablesim.policies.explore import explore
from cablesim.recording import read_stream, write_stream
from cablesim.sim.config import EpisodeConfig, PerturbConfig
from cablesim.sim.session import SimSession
from cablesim.thesis.config import METHODS

CODE_DIRS = ("sim", "episode", "panda")  # the code that decides a simulated stream


def _nan_to_none(v: float) -> float | None:
    v = float(v)
    return None if math.isnan(v) else v


def _scores(pred: np.ndarray, truth: np.ndarray) -> dict[str, float | None]:

    s = score_mask(pred, truth)
    out = {k: _nan_to_none(v) for k, v in s.to_dict().items()}
    out["pixels"] = int(np.count_nonzero(pred))
    return out


# --------------------------------------------------------------------------- stream cache
def cache_root() -> Path:
    base = os.environ.get("CABLESIM_CACHE", Path.home() / ".cache" / "cablesim")
    return Path(base) / "thesis-streams"


def _code_digest() -> str:
    pkg = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for d in CODE_DIRS:
        for p in sorted((pkg / d).glob("*.py")):
            h.update(p.name.encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _episode(params: dict[str, Any]) -> Any:

    cfg = EpisodeConfig(
        scene=scene_from(params), perturb=PerturbConfig(enabled=bool(params.get("perturb", False)))
    )
    # every frame labelled: the oracle flow rows read each frame's ground-truth flow
    return cfg.with_values(periods=int(params.get("scene", {}).get("periods", 3)), truth_every=1)


def simulate_stream(params: dict[str, Any], use_cache: bool = True) -> tuple[Any, dict[str, Any]]:
    """(stream, info) of the job's interaction, from the cache when it was simulated before;
    (None, failure record) when the interaction failed (a failure is cached too).

    A cache entry is finished when its ``info.json`` is there (written last, atomically); an
    entry without one (a killed run) is removed and simulated again.  Two processes that need
    the same entry at once take turns (``flock`` on the entry's ``.lock``): the second finds it
    filled."""

    cfg = _episode(params)
    blob = json.dumps([cfg.to_dict(), mujoco.__version__, _code_digest()], sort_keys=True)
    root = Path(params["stream_cache"]) if params.get("stream_cache") else cache_root()
    folder = root / hashlib.sha256(blob.encode()).hexdigest()[:24]
    if not use_cache:
        info, res = _simulate(cfg)
        return (res.stream if info["status"] == "ok" else None), info
    cached = _cached(folder)
    if cached is not None:
        return cached
    with waiting_lock(folder / ".lock"):
        cached = _cached(folder)  # filled by another process meanwhile
        if cached is not None:
            return cached
        info, res = _simulate(cfg)
        _store(folder, info, res)
    return (res.stream if info["status"] == "ok" else None), info


def _cached(folder: Path) -> tuple[Any, dict[str, Any]] | None:
    """A finished cache entry's (stream, info), or None (missing or damaged)."""

    info_path = folder / "info.json"
    if not info_path.is_file():
        return None
    try:
        info = json.loads(info_path.read_text())
        if info.get("status") != "ok":
            return None, info
        return read_stream(folder / "stream"), info
    except (CablesimError, OSError, json.JSONDecodeError):
        return None  # a damaged entry: simulate again


def _simulate(cfg: Any) -> tuple[dict[str, Any], Any]:
    """(info, interaction result or None) of one simulated interaction."""

    session = None
    res = None
    try:
        session = SimSession.build(cfg)
        try:
            seg = session.pick_start()
        except CablesimError as e:
            info = failure(str(e), "no_start_segment")
        else:
            res = session.interact(seg.mask)
            if not res.success or res.stream is None:
                info = failure(res.reason, getattr(res, "outcome", None), hose=session.hose)
            else:
                others = res.other_hose_displacement()
                info = {
                    "status": "ok",
                    "outcome": "ok",
                    "hose": int(session.hose),
                    "segment_pixels": int(seg.mask.sum()),
                    "neighbours_moved_mm": 1000 * max(others) if others else 0.0,
                    "follow_gain": [a.gain for a in res.actions],
                }
    except CablesimError as e:  # the scene itself (did not settle, diverged, ...)
        info = failure(str(e), error_outcome(e))
        res = None
    finally:
        if session is not None:
            session.close()
    return info, res


def _store(folder: Path, info: dict[str, Any], res: Any) -> None:
    """Write a cache entry: the stream (what an unfinished one left removed first), then
    ``info.json``."""

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "info.json").unlink(missing_ok=True)
    for p in (folder / "stream", *folder.glob(".stream.*")):
        shutil.rmtree(p, ignore_errors=True)
    if info["status"] == "ok":
        write_stream(res.stream, folder / "stream")
    write_text(folder / "info.json", json.dumps(info))


# --------------------------------------------------------------------------- tables 6.4 / 6.5
def run_interaction(params: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Job: one scene and perturbation setting (module docstring)."""

    t0 = time.perf_counter()
    stream, info = simulate_stream(params, bool(params.get("cache_streams", True)))
    t_sim = time.perf_counter() - t0
    if stream is None:
        return info
    truth = stream.target.truth.labels == info["hose"]
    out: dict[str, Any] = {
        "hose": info["hose"],
        "frames": len(stream),
        "truth_pixels": int(truth.sum()),
        "segment_pixels": info["segment_pixels"],
        "neighbours_moved_mm": info["neighbours_moved_mm"],
        "follow_gain": info["follow_gain"],
        "flows": {},
    }
    timings = {"simulate_s": t_sim}
    methods = tuple(params.get("methods", METHODS))
    for flow in params["flows"]:
        t1 = time.perf_counter()
        stats = compute_statistics(stream, flow, methods=methods)
        per: dict[str, Any] = {"counts": {}, "thesis_thresholds": {}, "samples": stats.n_samples}
        for method in methods:
            per["counts"][method] = {
                str(n): threshold_counts(stats, truth, method, n).to_dict() for n in (1, 2)
            }
        # the thesis's table 6.3 / SPEC 8: its own thresholds, for the methods it has them for
        for method in (m for m in ("segmentation", "correlation") if m in methods):
            rows = {}
            for beta in (1.0, 0.5, 0.4, 0.3, 0.2, 0.1):
                masks = masks_from_statistics(stats, method, params_for_beta(method, beta))
                votes = vote_image(list(masks.values()))
                rows[f"{beta:g}"] = {
                    str(n): _scores(merge_votes(votes, n, len(masks)), truth) for n in (1, 2)
                }
            per["thesis_thresholds"][method] = rows
        out["flows"][flow] = per
        timings[f"perception_{flow}_s"] = time.perf_counter() - t1
    return {"status": "ok", "outcome": "ok", "result": out, "timings": timings}


# --------------------------------------------------------------------------- tables 6.8 / 6.9
def run_exploration(params: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Job: an exploration of ``grasps`` grasps on a test scene (module docstring)."""

    t0 = time.perf_counter()
    size = params.get("scene", {})
    shortcuts = {name: int(size[name]) for name in ("width", "height", "hoses") if name in size}
    cfg = ExploreConfig.of(
        seed=int(params["seed"]),
        grasps=int(params.get("grasps", 2)),
        flow=params.get("flow", "dis"),
        perturb=PerturbConfig(enabled=bool(params.get("perturb", False))),
        correlation=CorrelationParams(c0_min=params["c0_min"], r2_min=params["r2_min"]),
        progress=False,
        periods=int(size.get("periods", 3)),
        **shortcuts,
    )
    try:
        res = explore(cfg)
    except CablesimError as e:
        return failure(str(e), error_outcome(e))
    ok = res.successes
    out: dict[str, Any] = {
        "hose": res.hose,
        "proposal_grades": dict(res.proposal_grades),
        "interactions": [
            {"success": i.success, "reason": i.reason, "source": i.source, "grade": i.grade}
            for i in res.interactions
        ],
        "successful": len(ok),
        "stop_reason": res.stop_reason,
    }
    if not ok:
        first = res.interactions[0].reason if res.interactions else res.stop_reason
        return failure(first, None, **out)
    first = ok[0]
    assert first.seg is not None and first.truth is not None
    out["one_grasp"] = {str(n): _scores(first.seg.votes >= n, first.truth) for n in (1, 2)}
    if len(ok) >= 2 and res.merged_votes is not None and res.final_truth is not None:
        top = 2 * len(ok)
        out["two_grasps"] = {
            str(n): _scores(res.merged_votes >= n, res.final_truth) for n in range(1, top + 1)
        }
    return {
        "status": "ok",
        "outcome": "ok",
        "result": out,
        "timings": {"total_s": time.perf_counter() - t0},
    }


# --------------------------------------------------------------------------- chapter 5
def clip_flow(name: str) -> Any:
    """The published code's Farneback, or any flow back end's spec."""

    return PublishedFarneback() if name == "farneback-movingcables" else make_flow(name)


def run_clip(params: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Job: a MovingCables clip (written to ``params["dataset"]/<split>``, numbered by seed
    within its split) and the published evaluation of each flow back end at every motion
    threshold, read back from the written files."""

    t0 = time.perf_counter()
    seed = int(params["seed"])
    p = dict(params, randomize=True)
    clip = simulate_clip(seed, scene_from(p), int(params.get("periods", 1)))
    if isinstance(clip, dict):
        return clip
    split_dir = Path(params["dataset"]) / params["split"]
    name = clip_name(seed % 9999 + 1)
    nbytes = write_sim_clip(split_dir, name, clip)
    t_sim = time.perf_counter() - t0
    frames = list(read_clip(split_dir, name))
    taus = [float(t) for t in params["taus"]]
    out: dict[str, Any] = {
        "clip": name,
        "hose": clip.hose,
        "images": len(frames),
        "bytes": nbytes,
        "background": clip.scene.board.background,
        "hoses": clip.scene.hoses.count,
        "flows": {},
    }
    timings = {"simulate_write_s": t_sim}
    for fname in params["flows"]:
        t1 = time.perf_counter()
        est = clip_flow(fname)
        first = frames[0].rgb
        per = {f"{t:g}": {"recall": [], "precision": [], "iou": []} for t in taus}
        epe = []
        for fr in frames:
            pred = est.compute(fr.rgb, first)
            for t in taus:
                st = movingcables_frame(fr.normal_flow, pred, t, STATIC_THRESHOLD, fr.stick_mask)
                row = per[f"{t:g}"]
                row["recall"].append(_nan_to_none(st.recall))
                row["precision"].append(_nan_to_none(st.precision))
                row["iou"].append(_nan_to_none(st.iou))
            epe.append(float(st.epe))
        out["flows"][fname] = {"taus": per, "epe": epe}
        timings[f"flow_{fname}_s"] = time.perf_counter() - t1
    return {"status": "ok", "outcome": "ok", "result": out, "timings": timings}


__all__ = ["outcome_of", "run_clip", "run_exploration", "run_interaction", "simulate_stream"]
