"""A seed sweep: one interaction per seed of a range, the outcome of each recorded by name.

The runner behind ``python -m benchmarks.seeds`` ("does every seed give an interaction?") and
the robustness tests: :func:`run_seed` runs one default interaction (``cablesim episode --seed
S``, or a config given as a dict) and never raises; an unexpected error is recorded as
``error:<Type>`` with its message.  Per seed: success, named outcome
(:data:`cablesim.outcomes.OUTCOMES`), grasp retries, scene re-draws (``cablesim.sim.session``),
hose of interest, wall and CPU time of the worker, and digests of the target frame (RGB +
depth) and of the whole result, so that two runs can be compared bit for bit.

:func:`run_sweep` runs the seeds in ``spawn`` worker processes (or in this process with
``workers=0``) and writes the rows after every seed (``json_path``, atomically; ``md_path``:
:func:`markdown`), so an interrupted run keeps what it had; the same call again resumes: the
seeds already in ``json_path``, run at the same commit with the same config changes, are kept
(``fresh`` runs them all).  A resumed run's files equal an uninterrupted run's except what
times the run (:data:`VOLATILE`).
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import resource
import signal
import statistics
import time
import traceback
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np

from cablesim import provenance as pv
from cablesim.config import override
from cablesim.errors import outcome_of
from cablesim.files import write_text
from cablesim.jobs import exit_with_parent
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.session import simulate_episode

#: what differs between two runs of the same seeds (timings, date, load): not compared
VOLATILE = {
    "meta": ("date", "load_start", "load_end", "wall_s"),
    "rows": ("wall_s", "cpu_s"),
    "summary": ("cpu_s_median", "cpu_s_total"),
}


def episode_config(assignments: Sequence[str] = (), seed: int = 0) -> Any:
    """The default ``EpisodeConfig`` of ``seed`` with ``FIELD=VALUE`` assignments applied (the
    fields of ``cablesim explore --show-config`` without their ``episode.`` prefix), checked;
    a bad field or value raises ``cablesim.errors.ConfigError`` naming it."""

    cfg = EpisodeConfig.of(seed=seed)
    for assignment in assignments:
        cfg = override(cfg, assignment)
    return cfg


def _worker_init() -> None:
    """Workers leave Ctrl-C to the parent, which cancels what is queued and stops them, and
    die with it when it is killed."""

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    exit_with_parent()


def comparable(doc: dict[str, Any]) -> dict[str, Any]:
    """A ``--json`` document without its :data:`VOLATILE` fields."""
    out = dict(doc)
    out["meta"] = {k: v for k, v in doc.get("meta", {}).items() if k not in VOLATILE["meta"]}
    out["summary"] = {
        k: v for k, v in doc.get("summary", {}).items() if k not in VOLATILE["summary"]
    }
    out["rows"] = [
        {k: v for k, v in r.items() if k not in VOLATILE["rows"]} for r in doc.get("rows", [])
    ]
    return out


def previous_rows(path: Path | None, meta: dict[str, Any], seeds: list[int]) -> dict[int, Any]:
    """The rows of ``seeds`` in an earlier ``--json`` file made at the same commit with the
    same config changes (an interrupted run, resumed), else none."""
    if path is None or not path.is_file():
        return {}
    try:
        doc = json.loads(path.read_text())
        old = doc["meta"]
        rows = doc["rows"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    same = ("commit", "config_changes")
    if any(old.get(k) != meta.get(k) for k in same):
        return {}
    wanted = set(seeds)
    return {r["seed"]: r for r in rows if isinstance(r, dict) and r.get("seed") in wanted}


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def run_seed(
    seed: int, cache_dir: str | None = None, config: dict[str, Any] | None = None
) -> dict[str, Any]:
    """One interaction for ``seed`` (the default ``EpisodeConfig``, or ``config`` as a dict with
    the seed replaced); never raises: an error is recorded as a named outcome."""
    if cache_dir is not None:
        os.environ["CABLESIM_CACHE"] = cache_dir

    t0, c0 = time.perf_counter(), _cpu()
    row: dict[str, Any] = {"seed": seed}
    try:
        cfg = EpisodeConfig() if config is None else EpisodeConfig.from_dict(config)
        ep = simulate_episode(cfg.replace(seed=seed))
        try:
            r = ep.result
            draws = ep.draws or {}
            row.update(
                success=bool(r.success),
                outcome=r.outcome,
                reason=r.reason,
                hose=r.hose,
                grasp_retries=int(r.grasp_retries),
                draw=draws.get("draw"),
                resamples=int(draws.get("resamples", 0)),
                turned_down=[t.get("outcome") for t in draws.get("turned_down", [])],
                frames=0 if r.stream is None else len(r.stream),
                follow_r2=[float(a.gain_r2) for a in r.actions],
            )
            if ep.session is not None:  # how often the solver needed help (cablesim.sim.world)
                row["rescues"] = int(ep.session.world.solver_rescues)
                row["fallbacks"] = int(ep.session.world.solver_fallbacks)
            if r.stream is not None:
                t = r.stream.target
                h = hashlib.sha256(np.ascontiguousarray(t.rgb).tobytes())
                h.update(np.ascontiguousarray(t.depth).tobytes())
                row["target_sha256"] = h.hexdigest()[:16]
            digest = json.dumps(r.to_dict() | {"timings_s": None}, sort_keys=True, default=str)
            row["result_sha256"] = hashlib.sha256(digest.encode()).hexdigest()[:16]
        finally:
            ep.close()
    except Exception as e:  # recorded by name; the run goes on with the next seed
        row.update(
            success=False,
            outcome=outcome_of(e),
            reason=f"{type(e).__name__}: {e}",
            traceback=traceback.format_exc(limit=6),
            grasp_retries=0,
            resamples=0,
        )
    row["wall_s"] = time.perf_counter() - t0
    row["cpu_s"] = _cpu() - c0
    return row


def _short(text: str, n: int = 90) -> str:
    text = " ".join(str(text).split()).replace("|", "/")
    return text if len(text) <= n else text[: n - 3] + "..."


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rows if r.get("success")]
    cpu = [r["cpu_s"] for r in rows if r["cpu_s"] == r["cpu_s"]]  # not NaN
    return {
        "seeds": len(rows),
        "successes": len(ok),
        "outcomes": dict(Counter(r["outcome"] for r in rows).most_common()),
        "grasp_retries": dict(sorted(Counter(r.get("grasp_retries", 0) for r in rows).items())),
        "seeds_with_retries": sum(1 for r in rows if r.get("grasp_retries", 0) > 0),
        "resamples": dict(sorted(Counter(r.get("resamples", 0) for r in rows).items())),
        "seeds_resampled": sum(1 for r in rows if r.get("resamples", 0) > 0),
        "turned_down_draws": dict(
            Counter(o for r in rows for o in r.get("turned_down", []) if o).most_common()
        ),
        "seeds_with_rescues": sum(1 for r in rows if r.get("rescues", 0) > 0),
        "cpu_s_median": statistics.median(cpu) if cpu else None,
        "cpu_s_total": sum(cpu),
    }


def markdown(rows: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    s = summary(rows)
    first, last = rows[0]["seed"], rows[-1]["seed"]
    outcomes = ", ".join(f"{k} {v}" for k, v in s["outcomes"].items())
    retries = ", ".join(f"{k}: {v} seeds" for k, v in s["grasp_retries"].items())
    resamples = ", ".join(f"{k}: {v} seeds" for k, v in s["resamples"].items())
    turned = ", ".join(f"{k} {v}" for k, v in s["turned_down_draws"].items()) or "none"
    lines = [
        "# Every seed gives an interaction",
        "",
        (
            "One interaction per seed of the default config changed by "
            + ", ".join(f"`{c}`" for c in meta["config_changes"])
            + " (otherwise as `cablesim episode --seed S`: "
            if meta.get("config_changes")
            else "One default interaction per seed (`cablesim episode --seed S`: 4 hoses, 640x480, "
        )
        + "hose of interest and start segment drawn from the seed; scene re-drawn by the session's "
        "documented rule when a draw does not settle or has no qualifying hose; a grasp that "
        "does not hold is retried at neighbouring points; a hose that slips in the gripper during an "
        "action, follow R^2 < `grasp.min_follow_r2`, is `grasp_not_held`).  "
        f"`{meta['command']}`.",
        "",
        f"- date: {meta['date']}; commit {meta['commit']}",
        f"- machine: {meta['machine']}; {meta['workers']} worker processes (spawn); load "
        f"average at start / end {meta['load_start']} / {meta['load_end']}",
        f"- settle cache: {meta['cache']}",
        f"- wall time of the run: {meta['wall_s']:.0f} s; CPU time per seed: median "
        f"{s['cpu_s_median'] or 0:.1f} s, total {s['cpu_s_total'] / 60:.1f} min",
        "",
        "## Summary",
        "",
        f"- seeds {first}-{last}: **{s['successes']} of {s['seeds']} gave a successful "
        "interaction**",
        f"- outcomes: {outcomes}",
        f"- grasp retries: {retries}",
        f"- scene re-draws (resamples): {resamples}; turned-down draws: {turned}",
        "- seeds where a stretched or sunk hose was stepped by the dense Newton (`physics."
        f"rescue_strain`, `physics.rescue_depth`): {s['seeds_with_rescues']}",
        "",
        "## Per seed",
        "",
        "| seed | success | outcome | hose | draw | re-draws | grasp retries | follow R^2 | "
        "rescues | wall s | CPU s | reason |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['seed']} | {'yes' if r.get('success') else 'no'} | {r['outcome']} | "
            f"{r.get('hose', '')} | {'' if r.get('draw') is None else r['draw']} | "
            f"{r.get('resamples', 0)} | {r.get('grasp_retries', 0)} | "
            f"{' / '.join(f'{x:.3f}' for x in r.get('follow_r2', []))} | "
            f"{r.get('rescues', '')} | {r['wall_s']:.1f} | "
            f"{r['cpu_s']:.1f} | {_short(r.get('reason', ''))} |"
        )
    return "\n".join(lines) + "\n"


def run_sweep(
    seeds: Sequence[int],
    *,
    config: dict[str, Any] | None = None,
    config_changes: Sequence[str] = (),
    workers: int = 2,
    cache_dir: str | os.PathLike[str] | None = None,
    json_path: Path | None = None,
    md_path: Path | None = None,
    fresh: bool = False,
    command: str = "",
    runner: Callable[..., dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Run ``runner`` (default :func:`run_seed`) for every seed (module docstring) with the
    episode config ``config`` (as a dict; None: the default), made by ``config_changes``
    (``FIELD=VALUE``, recorded and compared on resume); returns the :func:`summary` of the
    seeds that finished.  Ctrl-C stops the workers and writes what finished."""

    runner = runner or run_seed
    seeds = list(seeds)
    cache = None if cache_dir is None else str(Path(cache_dir).resolve())
    if cache is not None:
        Path(cache).mkdir(parents=True, exist_ok=True)
    meta: dict[str, Any] = {
        "command": command,
        "date": pv.utc_date(),
        "commit": pv.git_commit(),
        "machine": pv.machine(),
        "workers": workers,
        "load_start": pv.load_average(),
        "cache": cache or os.environ.get("CABLESIM_CACHE", "~/.cache/cablesim (default)"),
        "config_changes": list(config_changes),
    }
    t0 = time.perf_counter()
    rows: dict[int, dict[str, Any]] = {}
    if not fresh:
        rows.update(previous_rows(json_path, meta, seeds))
        if rows:
            print(
                f"resuming: {len(rows)} of {len(seeds)} seeds already in {json_path} (same "
                "commit and config changes); --fresh runs them again",
                flush=True,
            )

    def flush() -> None:
        done = [rows[s] for s in seeds if s in rows]
        meta.update(wall_s=time.perf_counter() - t0, load_end=pv.load_average())
        if json_path is not None:
            json_path.parent.mkdir(parents=True, exist_ok=True)
            doc = {"meta": meta, "summary": summary(done) if done else {}, "rows": done}
            write_text(json_path, json.dumps(doc, indent=1, default=str) + "\n")
        if md_path is not None and done:
            md_path.parent.mkdir(parents=True, exist_ok=True)
            write_text(md_path, markdown(done, meta))

    def record(s: int, row: dict[str, Any]) -> None:
        rows[s] = row
        print(
            f"seed {s}: {row['outcome']}"
            f" (retries {row.get('grasp_retries', 0)}, re-draws {row.get('resamples', 0)},"
            f" {row['cpu_s']:.0f} s CPU) [{len(rows)}/{len(seeds)}]"
            + ("" if row.get("success") else f" {_short(row.get('reason', ''), 160)}"),
            flush=True,
        )
        flush()

    todo = [s for s in seeds if s not in rows]
    if workers == 0:  # in this process
        try:
            for s in todo:
                record(s, runner(s, cache, config))
        except KeyboardInterrupt:
            print("interrupted: writing what finished", flush=True)
        return _finish(rows, seeds, flush)

    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
    try:  # the pool is shut down below, also on Ctrl-C
        futures = {pool.submit(runner, s, cache, config): s for s in todo}
        for fut in as_completed(futures):
            s = futures[fut]
            try:
                row = fut.result()
            except Exception as e:  # the worker itself died: record it, go on
                row = {
                    "seed": s,
                    "success": False,
                    "outcome": f"error:{type(e).__name__}",
                    "reason": f"worker failed: {e}",
                    "wall_s": float("nan"),
                    "cpu_s": float("nan"),
                }
            record(s, row)
        pool.shutdown()
    except KeyboardInterrupt:
        print("interrupted: stopping the workers, writing what finished", flush=True)
        procs = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
    return _finish(rows, seeds, flush)


def _finish(rows: dict[int, dict[str, Any]], seeds: list[int], flush: Callable[[], None]) -> dict:
    flush()
    done = [rows[s] for s in seeds if s in rows]
    return summary(done) if done else {}
