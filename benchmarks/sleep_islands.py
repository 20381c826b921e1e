"""MuJoCo's sleeping islands (``physics.sleep_tolerance``) against every body awake: one default
interaction per seed and setting on one core, CPU time by stage and what was measured (follow
gains, the other hoses' displacement, the stillness at the target frame, segmentation scores
of the default CPU perception against the target frame's ground truth).

    .venv/bin/python -m benchmarks.sleep_islands [--seeds 8102:8104] [--tolerances 0,0.001]
        [--write]

Each seed's scene is built anew per setting (its settled state is cached per config); the
interaction and the perception are those of ``bench_episode``.  ``--write`` writes
``benchmarks/results/sleep_islands.md``.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import statistics
import sys

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from benchmarks._interaction import (
    pin_to_one_core,
    run_interaction,
    run_meta,
    single_thread_environment,
    uptime,
)

OUT = RESULTS / "sleep_islands.md"
STAGES = ("physics_control", "rendering", "ground_truth", "perception", "total")


def _seeds(text: str) -> list[int]:
    a, sep, b = text.partition(":")
    return list(range(int(a), int(b))) if sep else [int(s) for s in text.split(",")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="8102:8104", help="A:B (B excluded) or a,b,c")
    ap.add_argument("--tolerances", default="0,0.001", help="sleep tolerances; 0 = off")
    ap.add_argument("--write", action="store_true", help=f"write {OUT.name}")
    args = ap.parse_args()
    single_thread_environment()
    core = pin_to_one_core()
    load_start = uptime()
    from cablesim.config import override
    from cablesim.evaluation import scores_dict
    from cablesim.sim.config import EpisodeConfig
    from cablesim.sim.session import SimSession

    tolerances = [float(t) for t in args.tolerances.split(",")]
    rows = []
    for seed in _seeds(args.seeds):
        for tol in tolerances:
            cfg = override(EpisodeConfig.of(seed=seed), f"scene.physics.sleep_tolerance={tol}")
            session = SimSession.build(cfg)
            try:
                segment = session.pick_start()
                run, res, seg = run_interaction(session, segment.mask)
                row = {"seed": seed, "tol": tol, "run": run, "scores": None}
                if seg is not None:
                    truth = res.stream.target.truth.labels == session.hose
                    row["scores"] = scores_dict(seg.mask(1), truth)
            finally:
                session.close()
            rows.append(row)
            r = row["run"]
            print(
                f"seed {seed} tolerance {tol:g}: "
                + (
                    f"CPU {r.cpu['total']:.1f} s (physics+control {r.cpu['physics_control']:.1f}); "
                    f"gains {', '.join(f'{g:.3f}' for g in r.gains)}"
                    if r.success
                    else f"FAILED: {r.reason}"
                ),
                flush=True,
            )
    meta = run_meta(pinned_core=core, load_start=load_start, load_end=uptime())
    text = report(meta, rows, tolerances)
    print(text)
    if args.write:
        write_results(OUT, text)
    return 0


def report(meta: dict, rows: list[dict], tolerances: list[float]) -> str:
    lines = [
        "# Sleeping islands (`python -m benchmarks.sleep_islands --write`)",
        "",
        "One default interaction (640x480, 4 hoses, two actions of 3 periods) per seed and "
        "`physics.sleep_tolerance` (0: every body awake, the default), pinned to one core; "
        "CPU seconds by stage as in `bench_episode`.  Scores: the default CPU perception's "
        "mask (one vote) against the target frame's ground truth.",
        "",
        f"- date: {meta['date']}; cablesim commit {meta['commit']}",
        f"- machine: {meta['machine']}; pinned to core {meta['pinned_core']}",
        f"- {meta['versions']}",
        f"- load (shared machine), start: `{meta['load_start']}`; end: `{meta['load_end']}`",
        "",
        "| seed | tolerance | physics+control | rendering | ground truth | perception | total | "
        "simulated s | gains | other hoses moved (mm) | target frame | P | R | F0.4 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        r, s = row["run"], row["scores"]
        if not r.success:
            lines.append(f"| {row['seed']} | {row['tol']:g} | failed: {r.reason} |")
            continue
        sc = (
            "| - | - | -"
            if s is None
            else (f"| {s['precision']:.3f} | {s['recall']:.3f} | {s['f0.4']:.3f}")
        )
        lines.append(
            f"| {row['seed']} | {row['tol']:g} | "
            + " | ".join(f"{r.cpu.get(k, float('nan')):.1f}" for k in STAGES)
            + f" | {r.sim_time:.1f} | {', '.join(f'{g:.3f}' for g in r.gains)} | "
            f"{', '.join(f'{x:.1f}' for x in r.others_mm)} | {r.still} {sc} |"
        )
    lines += ["", "| tolerance | median physics+control (s) | median total (s) |", "|---|---|---|"]
    for tol in tolerances:
        ok = [row["run"] for row in rows if row["tol"] == tol and row["run"].success]
        if ok:
            lines.append(
                f"| {tol:g} | {statistics.median(r.cpu['physics_control'] for r in ok):.1f} | "
                f"{statistics.median(r.cpu['total'] for r in ok):.1f} |"
            )
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
