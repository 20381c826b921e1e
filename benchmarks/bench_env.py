"""Throughput of the Gymnasium environments: environment steps per CPU second on one core.

    .venv/bin/python -m benchmarks.bench_env [--episodes 3] [--write]

Every step is a full simulated interaction, so the cost depends on what the action does: an
action that reaches the hose runs the whole interaction (grasp or push, periodic action,
release, retreat, settle, target frame, segmentation); one that is refused (no depth at the
point, grasp pose unreachable) costs a depth look-up and a reachability check.  Cases:

- ``dict default, aimed``: ``HoseExploreConfig()`` (4 hoses, 160x120, 2 periods, 2 actions,
  budget 3), every step :func:`cablesim.envs.aim.aim_at_segment` (a grasp on the start
  segment);
- ``dict default, random``: the same with ``action_space.sample()``;
- ``fast, aimed grasp`` / ``fast, aimed push``: :func:`cablesim.envs.box.fast_config`
  (budget 2) through ``AimedBoxAction`` with the zero residual;
- ``fast, residual N(0,1)``: the same with a unit Gaussian residual, clipped (what an untrained
  SB3 PPO policy does);
- ``fast, random Box``: ``BoxAction`` with uniform samples.

Resets are included (the scene is built and cached before timing).  CPU time of this process
(``resource.getrusage``), pinned to one core where the platform allows.  ``--write`` writes
``benchmarks/results/env.md``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys

import numpy as np

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.envs import HoseExploreConfig, HoseExploreEnv, aim_at_segment
from cablesim.envs.box import fast_config, make_box_env

OUT = RESULTS / "env.md"


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def run_case(name: str, env, policy, seeds: list[int]) -> dict:
    env.reset(seed=seeds[0])  # build (and cache) the scene before timing
    step_cpu, rewards, steps, reached = [], [], 0, 0
    t0 = _cpu()
    for s in seeds:
        obs, _ = env.reset(seed=s)
        done = False
        while not done:
            a = policy(obs)
            c = _cpu()
            obs, r, term, trunc, info = env.step(a)
            step_cpu.append(_cpu() - c)
            rewards.append(float(r))
            reached += bool(info["success"])
            steps += 1
            done = term or trunc
    total = _cpu() - t0
    env.close()
    row = {
        "case": name,
        "steps": steps,
        "cpu_s": total,
        "steps_per_cpu_s": steps / total,
        "median_step_s": statistics.median(step_cpu),
        "max_step_s": max(step_cpu),
        "success": reached / steps,
        "mean_reward": float(np.mean(rewards)),
    }
    print(
        f"{name:28s} {steps:3d} steps  {total:7.1f} s CPU  {row['steps_per_cpu_s']:6.3f} steps/s"
        f"  median step {row['median_step_s']:5.2f} s  interactions {row['success']:.0%}"
        f"  mean reward {row['mean_reward']:.3f}",
        flush=True,
    )
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=3, help="episodes per case")
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/env.md")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    ap.add_argument("--only", default="", help="comma-separated case prefixes to run")
    args = ap.parse_args()
    if not args.no_pin and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    rng = np.random.default_rng(0)
    fast = fast_config()
    cases = [
        ("dict default, aimed", lambda: HoseExploreEnv(HoseExploreConfig()), aim_at_segment),
        (
            "dict default, random",
            lambda: HoseExploreEnv(HoseExploreConfig()),
            None,  # action_space.sample, seeded below
        ),
        (
            "fast, aimed grasp",
            lambda: make_box_env(fast, aimed=True),
            lambda o: np.array([-1, 0, 0, 0], np.float32),
        ),
        (
            "fast, aimed push",
            lambda: make_box_env(fast, aimed=True),
            lambda o: np.array([1, 0, 0, 0], np.float32),
        ),
        (
            "fast, residual N(0,1)",
            lambda: make_box_env(fast, aimed=True),
            lambda o: np.clip(rng.normal(size=4), -1, 1).astype(np.float32),
        ),
        (
            "fast, random Box",
            lambda: make_box_env(fast),
            lambda o: rng.uniform(-1, 1, 4).astype(np.float32),
        ),
    ]
    only = tuple(p.strip() for p in args.only.split(",") if p.strip())
    rows = []
    for name, make, policy in cases:
        if only and not name.startswith(only):
            continue
        env = make()
        if policy is None:
            env.action_space.seed(0)
            policy = lambda o, env=env: env.action_space.sample()  # noqa: E731
        rows.append(run_case(name, env, policy, seeds))
    if args.write:
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        lines = [
            "# Environment throughput (`python -m benchmarks.bench_env`)",
            "",
            f"- date: {pv.utc_date()}; commit {pv.git_commit()}",
            f"- machine: {pv.machine()}",
            f"- load average at the end: {load:.1f} (CPU time is reported, pinned to one core)",
            f"- episodes per case: {args.episodes} (seeds {seeds[0]}..{seeds[-1]})",
            "",
            "| case | steps | CPU s | steps per CPU s | median step s | max step s "
            "| interactions | mean reward |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            lines.append(
                f"| {r['case']} | {r['steps']} | {r['cpu_s']:.1f} | {r['steps_per_cpu_s']:.3f} "
                f"| {r['median_step_s']:.2f} | {r['max_step_s']:.2f} | {r['success']:.0%} "
                f"| {r['mean_reward']:.3f} |"
            )
        write_results(OUT, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
