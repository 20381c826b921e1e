"""Soak test of the Gymnasium environment: many seeded episodes in one process, with the
resident memory (RSS), the open file descriptors and the time per episode tracked, to show that
nothing accumulates (leaked renderers, files, arrays) over a long training-like run.

    nice .venv/bin/python -m benchmarks.soak_env [--episodes 100] [--budget 2] [--write]

One environment (160x120, 2 hoses, one period per action) is made once; every episode resets
it with its own seed (the scene is built once and reused, as in training) and spends its budget
on interactions aimed at the start segment: a grasp, then (budget 2) a push.  ``--write``
writes ``benchmarks/results/soak.md``.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.envs import HoseExploreConfig, HoseExploreEnv

OUT = RESULTS / "soak.md"


def rss_mb() -> float:
    """Resident set size now (MiB), from /proc (Linux)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")  # pragma: no cover - not Linux


def open_files() -> int:
    return len(os.listdir("/proc/self/fd"))


def aim(obs: dict, primitive: int) -> dict:
    """An action on the centre of the start segment, along its principal direction."""
    v, u = np.nonzero(obs["segment"])
    h, w = obs["segment"].shape
    if len(u) < 2:
        return {"primitive": primitive, "point": np.array([0.5, 0.5]), "angle": np.array([0.0])}
    pts = np.stack([u, v], 1).astype(float)
    c = pts.mean(0)
    ev = np.linalg.eigh(np.cov((pts - c).T))[1][:, -1]
    a = (math.atan2(ev[1], ev[0]) + math.pi / 2) % math.pi - math.pi / 2
    return {
        "primitive": primitive,
        "point": np.array([c[0] / w, c[1] / h], np.float32),
        "angle": np.array([a / (math.pi / 2)], np.float32),
    }


def slope_per_100(xs: list[float]) -> float:
    """Least-squares growth of ``xs`` per 100 episodes."""
    if len(xs) < 2:
        return float("nan")
    return float(np.polyfit(np.arange(len(xs)), np.asarray(xs), 1)[0] * 100)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--budget", type=int, default=2, help="interactions per episode (1 or 2)")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--scene-seed", type=int, default=2)
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/soak.md")
    args = ap.parse_args()
    if args.episodes < 1 or args.budget not in (1, 2):
        ap.error("need --episodes >= 1 and --budget 1 or 2")

    cfg = HoseExploreConfig.of(
        scene_seed=args.scene_seed,
        hoses=2,
        width=args.width,
        height=args.height,
        budget=args.budget,
        periods=1,
    )
    started = pv.utc_date()
    load_start = pv.load_average()
    t0, c0 = time.perf_counter(), time.process_time()
    rss0, fds0 = rss_mb(), open_files()
    env = HoseExploreEnv(cfg)
    rows = []
    failures: dict[str, int] = {}
    for ep in range(args.episodes):
        te, ce = time.perf_counter(), time.process_time()
        obs, info = env.reset(seed=ep)
        rewards, successes = [], 0
        for k in range(args.budget):
            obs, reward, terminated, truncated, info = env.step(aim(obs, primitive=k))
            rewards.append(reward)
            successes += bool(info["success"])
            if not info["success"]:
                key = str(info["reason"]).split(":")[0][:60]
                failures[key] = failures.get(key, 0) + 1
            if terminated or truncated:
                break
        rows.append(
            {
                "rss": rss_mb(),
                "fds": open_files(),
                "wall": time.perf_counter() - te,
                "cpu": time.process_time() - ce,
                "successes": successes,
                "reward": float(sum(rewards)),
            }
        )
        if ep % 10 == 0 or ep == args.episodes - 1:
            r = rows[-1]
            print(
                f"episode {ep:3d}: {r['wall']:5.1f} s, RSS {r['rss']:7.1f} MiB, "
                f"{r['fds']} open files, {successes}/{args.budget} successful",
                flush=True,
            )
    env.close()
    total_wall, total_cpu = time.perf_counter() - t0, time.process_time() - c0
    rss = [r["rss"] for r in rows]
    fds = [r["fds"] for r in rows]
    half = len(rows) // 2
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    n_steps = sum(r["successes"] for r in rows)

    lines = [
        "# Soak: the Gymnasium environment over many episodes",
        "",
        f"`python -m benchmarks.soak_env --episodes {args.episodes} --budget {args.budget}` "
        "(run with "
        "`nice`): one `HoseExploreEnv` "
        f"({args.width}x{args.height}, 2 hoses, one period per action, scene seed "
        f"{args.scene_seed}); episode k is `reset(seed=k)` and {args.budget} interaction(s) aimed "
        "at the start segment (a grasp, then a push).  Memory is the resident set size (VmRSS) "
        "after each episode; open files are the entries of /proc/self/fd.",
        "",
        f"- date: {started}; commit {pv.git_commit()}",
        f"- machine: {pv.machine()}, shared; load average at start {load_start}, at the end "
        f"{pv.load_average()}",
        f"- python {sys.version.split()[0]}, MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}",
        f"- {args.episodes} episodes, {len(rows) * args.budget} interactions "
        f"({n_steps} successful); total {total_wall / 60:.1f} min wall, {total_cpu / 60:.1f} min "
        f"CPU; per episode median {statistics.median(r['wall'] for r in rows):.1f} s wall, "
        f"{statistics.median(r['cpu'] for r in rows):.1f} s CPU",
        f"- unsuccessful interactions by reason: {failures or 'none'}",
        "",
        "| | value |",
        "|---|---|",
        f"| RSS before making the environment | {rss0:.1f} MiB |",
        f"| RSS after episode 1 / 10 / {half} / {len(rows)} | "
        + " / ".join(f"{rss[min(i, len(rss)) - 1]:.1f}" for i in (1, 10, half, len(rows)))
        + " MiB |",
        f"| RSS growth over the last {len(rows) - half} episodes (least squares) | "
        f"{slope_per_100(rss[half:]):+.1f} MiB per 100 episodes |",
        f"| peak RSS (ru_maxrss) | {peak:.1f} MiB |",
        f"| open files before / after episode 1 / at the end / most | {fds0} / {fds[0]} / "
        f"{fds[-1]} / {max(fds)} |",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if args.write:
        write_results(OUT, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
