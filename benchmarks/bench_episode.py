"""One default interaction on one CPU core, wall and CPU time by stage: physics and control
(stepping, IK, settling), rendering (RGB + depth of every kept frame and the target frame, and
the label passes of the labelled ones), ground truth (flow from the target frame to every
labelled frame: every 8th kept frame by default since issue 21, ``capture.truth_every``) and
the default CPU perception (``segment_stream(stream, method="correlation", flow="dis")``).

    .venv/bin/python -m benchmarks.bench_episode [--seed 2] [--repeats 3] [--write]
        [--json-out FILE] [--baseline FILE] [--set FIELD=VALUE ...]

Default settings: 640x480, 4 hoses, one grasp, two actions of 3 periods.  The scene is built
(its settled state cached) and the start segment picked before timing; each repeat resets the
world and runs the same seeded interaction, then the perception on its stream.  The process
is pinned to one core and runs single-threaded BLAS/OpenCV/llvmpipe (see
``_interaction.single_thread_environment``).  The machine is shared: CPU time of the process
is the primary measure, wall time is reported beside it with the load average.

``--json-out`` saves the runs; ``--baseline`` adds a before/after table from such a file (e.g.
this script run against an older commit with ``PYTHONPATH=<old checkout>``, or with other
settings: ``--set physics.sleep_tolerance=0.001``).  ``--set`` changes one field of the
episode config (as ``cablesim explore --set``).  ``--write`` writes
``benchmarks/results/episode.md``.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import json
import statistics
import sys
from pathlib import Path

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from benchmarks._interaction import (
    pin_to_one_core,
    run_interaction,
    run_meta,
    single_thread_environment,
    uptime,
)

OUT = RESULTS / "episode.md"
STAGES = (
    ("physics_control", "physics + control (stepping, IK, settling)"),
    ("rendering", "rendering (RGB+depth and label passes)"),
    ("ground_truth", "ground truth (flow target -> each labelled frame)"),
    ("perception", "perception (default: DIS + refine + correlation)"),
    ("total", "**total**"),
)
TARGET_S = 12.0


def _median(runs: list[dict], kind: str, key: str) -> float:
    return statistics.median(r[kind][key] for r in runs)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--hose", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/episode.md")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    ap.add_argument("--json-out", type=Path, help="save the runs as JSON")
    ap.add_argument("--baseline", type=Path, help="JSON of an earlier run for a before/after table")
    ap.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", help="a config field"
    )
    args = ap.parse_args()
    single_thread_environment()  # before the first rendering (and the workers)

    core = None if args.no_pin else pin_to_one_core()
    load_start = uptime()
    from cablesim.config import override
    from cablesim.sim.config import EpisodeConfig
    from cablesim.sim.session import SimSession

    cfg = EpisodeConfig.of(seed=args.seed, hose=args.hose)
    for assignment in args.set:
        cfg = override(cfg, assignment)
    session = SimSession.build(cfg)
    segment = session.pick_start()
    hose = session.hose
    print(f"scene built in {session.build_time:.1f} s; hose {hose}, {int(segment.mask.sum())} px")

    runs = []
    for i in range(args.repeats):
        session = SimSession.build(cfg, world=session.world, camera=session.camera)
        session.hose = hose
        run, res, _ = run_interaction(session, segment.mask)
        if not run.success:
            print(f"run {i}: FAILED: {run.reason}")
            return 1
        runs.append(run.to_dict())
        print(
            f"run {i}: CPU {run.cpu['total']:.1f} s (physics+control "
            f"{run.cpu['physics_control']:.1f}, rendering {run.cpu['rendering']:.1f}, ground "
            f"truth {run.cpu['ground_truth']:.1f}, perception {run.cpu['perception']:.1f}); "
            f"wall {run.wall['total']:.1f} s; {run.frames} frames of {run.ticks} ticks; gains "
            f"{', '.join(f'{g:.3f}' for g in run.gains)}; digest {run.digest[:12]}",
            flush=True,
        )
    session.close()
    load_end = uptime()
    digests = {r["digest"] for r in runs}
    meta = run_meta(
        pinned_core=core,
        load_start=load_start,
        load_end=load_end,
        seed=args.seed,
        hose=hose,
        repeats=args.repeats,
        settings=list(args.set),
        deterministic=len(digests) == 1,
    )
    if args.json_out:
        args.json_out.write_text(json.dumps({"meta": meta, "runs": runs}, indent=1))
    text = report(meta, runs, args.baseline)
    print(text)
    if args.write:
        write_results(OUT, text)
    return 0


def report(meta: dict, runs: list[dict], baseline: Path | None) -> str:
    last = runs[-1]
    lines = [
        "# Episode benchmark",
        "",
        "One default interaction on one CPU core: 640x480 camera, 4 hoses, one grasp, two actions "
        "(along, across) of 3 periods at +-2 cm and 5 cm/s, camera at 15 frames/s of simulated "
        "time with the 1 mm rule, release, retreat, settle, target frame, labels and "
        "ground-truth flow on the labelled frames (every kept frame before issue 21, every 8th "
        "since: `capture.truth_every`), then the default CPU perception "
        "(`segment_stream(stream, method='correlation', flow='dis')`: DIS preset fine (5 "
        "refinement iterations before issue 21, 1 since), normal flow, arm masks and depth "
        "foreground where present; DIS medium and no refine before issue 10). "
        "`python -m benchmarks.bench_episode --write`.",
        "",
        f"- date: {meta['date']}; cablesim commit {meta['commit']}",
        f"- machine: {meta['machine']}; run pinned to core {meta['pinned_core']}",
        f"- {meta['versions']}",
        f"- load (shared machine), start: `{meta['load_start']}`",
        f"- load, end: `{meta['load_end']}`",
        f"- seed {meta['seed']}, hose {meta['hose']}, {meta['repeats']} repeats (medians below); "
        f"same frames, labels, flow and votes in every repeat: {meta['deterministic']}",
        f"- simulated time {last['sim_time']:.1f} s, {last['physics_steps']} physics steps; "
        f"{last['ticks']} camera ticks during the actions, {last['frames']} frames kept (target "
        "included)",
        f"- follow gain per action: {', '.join(f'{g:.3f}' for g in last['gains'])}; largest "
        f"displacement of the other hoses: {', '.join(f'{d:.1f} mm' for d in last['others_mm'])}; "
        f"target frame: {last['still']}",
        "",
        "| stage | median CPU time (s) | median wall time (s) |",
        "|---|---|---|",
    ]
    for key, label in STAGES:
        cpu, wall = _median(runs, "cpu", key), _median(runs, "wall", key)
        if key == "total":
            lines.append(f"| {label} | **{cpu:.1f}** | **{wall:.1f}** |")
        else:
            lines.append(f"| {label} | {cpu:.1f} | {wall:.1f} |")
    lines += [
        "",
        f"Target (issue 9): at most {TARGET_S:.0f} s on one core for the whole interaction "
        "including perception.  CPU time counts every thread of the process; wall time "
        "includes waiting for the core while other jobs run on the shared machine.",
        "",
    ]
    if baseline is not None:
        base = json.loads(Path(baseline).read_text())
        bm, br = base["meta"], base["runs"]
        b0 = br[-1]
        lines += [
            f"## Before and after (CPU time, median of {len(br)} and {len(runs)} repeats)",
            "",
            f"Before: commit {bm['commit']} ({bm['date']}; load at start `{bm['load_start']}`).  "
            f"Simulated time {b0['sim_time']:.1f} s, {b0['physics_steps']} physics steps, "
            f"{b0['frames']} frames; follow gain "
            f"{', '.join(f'{g:.3f}' for g in b0['gains'])}; target frame: {b0['still']}.",
            "",
            "| stage | before (s) | after (s) | speed-up |",
            "|---|---|---|---|",
        ]
        for key, label in STAGES:
            b, a = _median(br, "cpu", key), _median(runs, "cpu", key)
            lines.append(f"| {label} | {b:.1f} | {a:.1f} | {b / a:.1f}x |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
