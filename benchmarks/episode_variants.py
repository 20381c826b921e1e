"""What one interaction costs under other protocol settings, and what each gives up: the
episode benchmark's stages (``bench_episode.py``) for a list of named config variants, with
the follow gains and the default correlation's scores against the ground truth beside the
CPU time.  This is the basis for the protocol decision the 12 s target of issue 9 needs
(``benchmarks/results/episode.md``: the default costs ~22 s on this machine).

    .venv/bin/python -m benchmarks.episode_variants [--seeds 2 8] [--write] [--out FILE]
        [--variant NAME FIELD=VALUE ...] [--json-out FILE] [--baseline FILE]

Each variant is a list of ``--set`` assignments on the episode config (``cablesim explore
--show-config`` lists the fields, without the ``episode.`` prefix here).  Every (variant,
seed) runs once (a run is deterministic: ``bench_episode.py`` checks that), pinned to one
core, single-threaded.  The scores are of one interaction per seed: indicative, not a
benchmark of the method (``realistic_flow.py`` and ``cablesim benchmark thesis`` are).

``--baseline FILE`` adds the rows of an earlier run's ``--json-out`` (e.g. of an older commit,
run with ``PYTHONPATH=<old checkout>`` on the same seeds) as the variant ``before (COMMIT)``:
a before/after table of the same seeds.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from benchmarks._interaction import (
    pin_to_one_core,
    run_interaction,
    run_meta,
    single_thread_environment,
    uptime,
)
from cablesim.errors import ConfigError
from cablesim.sweep import episode_config

OUT = RESULTS / "episode_variants.md"
STAGES = ("physics_control", "rendering", "ground_truth", "perception", "total")

#: name -> assignments on the episode config
VARIANTS: dict[str, tuple[str, ...]] = {
    "default": (),
    "2 periods": ("interaction.actions.periods=2",),
    "480x360": ("scene.camera.width=480", "scene.camera.height=360"),
    "480x360, 2 periods": (
        "scene.camera.width=480",
        "scene.camera.height=360",
        "interaction.actions.periods=2",
    ),
    "320x240": ("scene.camera.width=320", "scene.camera.height=240"),
    "320x240, 2 periods": (
        "scene.camera.width=320",
        "scene.camera.height=240",
        "interaction.actions.periods=2",
    ),
    "2 mm rule": ("interaction.capture.min_gripper_step=0.002",),
    "fast transit": (
        "interaction.retreat.speed_factor=1.0",
        "interaction.grasp.travel_speed=0.5",
    ),
}


def run_variant(assignments: tuple[str, ...], seed: int) -> dict:
    """One interaction of ``seed`` under ``assignments``, timed by stage and scored."""
    from cablesim.sim.session import SimSession

    session = SimSession.build(episode_config(assignments, seed))
    try:
        return scored_interaction(session, seed)
    finally:
        session.close()


def scored_interaction(session: Any, seed: int) -> dict:
    """The row of one interaction of a built ``session`` from its start segment: CPU seconds
    by stage and, when it succeeded, its frames, gains and the default correlation's union
    and intersection scores against the target frame's ground truth."""
    segment = session.pick_start()
    run, res, seg = run_interaction(session, segment.mask)
    row = {
        "seed": seed,
        "hose": session.hose,
        "success": run.success,
        "reason": run.reason,
        "cpu": run.cpu,
    }
    if run.success and seg is not None:
        ev = session.evaluator()
        truth = ev.stream_truth(res.stream)
        row.update(
            sim_time=run.sim_time,
            physics_steps=run.physics_steps,
            ticks=run.ticks,
            frames=run.frames,
            gains=run.gains,
            union=ev.score(seg.mask("union"), truth),
            intersection=ev.score(seg.mask("intersection"), truth),
        )
    return row


def check_assignments(
    ap: argparse.ArgumentParser, named: dict[str, tuple[str, ...]], what: str
) -> None:
    """Stop with ``ap.error`` naming the first of ``named`` (name -> ``--set`` assignments of
    the episode config) whose field or value is bad, before any scene is built."""
    for name, assignments in named.items():
        try:
            episode_config(assignments)
        except ConfigError as e:
            ap.error(f"{what} {name!r}: {e}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[2, 8])
    ap.add_argument(
        "--variant",
        nargs="+",
        action="append",
        metavar=("NAME", "FIELD=VALUE"),
        help="run only this variant (repeatable); a name from the built-in list, or a new "
        "name followed by its assignments",
    )
    ap.add_argument("--write", action="store_true", help=f"write {OUT}")
    ap.add_argument("--json-out", type=Path, help="save the rows as JSON")
    ap.add_argument(
        "--baseline", type=Path, help="an earlier run's --json-out: its rows as 'before'"
    )
    ap.add_argument("--out", type=Path, default=OUT, help=f"the file --write writes ({OUT})")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    args = ap.parse_args()
    single_thread_environment()  # before the first rendering (and the workers)

    variants: dict[str, tuple[str, ...]] = {}
    for name, *assignments in args.variant or [[n] for n in VARIANTS]:
        if not assignments and name not in VARIANTS:
            ap.error(f"--variant {name!r}: not a built-in variant ({', '.join(VARIANTS)})")
        variants[name] = tuple(assignments) if assignments else VARIANTS[name]
    check_assignments(ap, variants, "--variant")
    before: dict | None = None
    if args.baseline is not None:
        try:
            before = json.loads(args.baseline.read_text())
            before_rows, before_meta = before["rows"], before["meta"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            ap.error(f"--baseline {args.baseline}: not a --json-out of this script ({e})")

    core = None if args.no_pin else pin_to_one_core()
    load_start = uptime()
    rows = []
    for name, assignments in variants.items():
        for seed in args.seeds:
            row = run_variant(assignments, seed) | {"variant": name, "set": list(assignments)}
            rows.append(row)
            c = row["cpu"]
            print(
                f"{name} / seed {seed}: {'ok' if row['success'] else 'FAILED ' + row['reason']}; "
                f"CPU {c.get('total', c['interaction']):.1f} s"
                + (
                    f"; frames {row['frames']}; union F0.4 {row['union']['f0.4']:.3f}"
                    if "union" in row
                    else ""
                ),
                flush=True,
            )
    meta = run_meta(pinned_core=core, load_start=load_start, load_end=uptime(), seeds=args.seeds)
    if args.json_out:
        args.json_out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    if before is not None:
        name = f"before ({before_meta['commit']})"
        meta["baseline"] = f"{name}: {before_meta['date']}, {args.baseline.name}"
        variants = {name: tuple(before_rows[0].get("set", ())) if before_rows else (), **variants}
        rows = [{**r, "variant": name} for r in before_rows] + rows
    text = report(meta, rows, variants)
    print(text)
    if args.write:
        write_results(args.out, text)
    return 0


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def report(meta: dict, rows: list[dict], variants: dict[str, tuple[str, ...]]) -> str:
    lines = [
        "# Episode variants: what each protocol setting costs and gives up",
        "",
        "The episode benchmark's stages (`bench_episode.py`: physics + control, rendering, "
        "ground truth, the default CPU perception) for config variants, one interaction per "
        "(variant, seed), pinned to one core.  Scores: the default correlation's union and "
        "intersection masks against the grasped hose in the target frame (one interaction per "
        "seed: indicative only).  `python -m benchmarks.episode_variants --write`.",
        "",
        f"- date: {meta['date']}; cablesim commit {meta['commit']}",
        f"- machine: {meta['machine']}; run pinned to core {meta['pinned_core']}",
        f"- {meta['versions']}",
        f"- load (shared machine), start: `{meta['load_start']}`; end: `{meta['load_end']}`",
        f"- seeds: {', '.join(str(s) for s in meta['seeds'])}",
        *([f"- baseline: {meta['baseline']}"] if meta.get("baseline") else []),
        "",
        "Medians over the seeds (CPU seconds):",
        "",
        "| variant | settings | ok | sim s | frames | physics | render | truth | perception "
        "| **total** | gain min | union P / F0.4 | intersection P / F0.4 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, assignments in variants.items():
        vr = [r for r in rows if r["variant"] == name]
        ok = [r for r in vr if "union" in r]
        if not ok:
            lines.append(
                f"| {name} | {'<br>'.join(assignments) or '-'} | 0/{len(vr)} | | | | | | | | | | |"
            )
            continue

        def med(key: str, rs: list[dict] = ok) -> float:
            return _median([r["cpu"][key] for r in rs])

        u_p = _median([r["union"]["precision"] for r in ok])
        u_f = _median([r["union"]["f0.4"] for r in ok])
        i_p = _median([r["intersection"]["precision"] for r in ok])
        i_f = _median([r["intersection"]["f0.4"] for r in ok])
        lines.append(
            f"| {name} | {'<br>'.join(f'`{a}`' for a in assignments) or '-'} | "
            f"{len(ok)}/{len(vr)} | {_median([r['sim_time'] for r in ok]):.1f} | "
            f"{_median([r['frames'] for r in ok]):.0f} | "
            + " | ".join(f"{med(k):.1f}" for k in STAGES[:-1])
            + f" | **{med('total'):.1f}** | {min(min(r['gains']) for r in ok):.3f} | "
            f"{u_p:.3f} / {u_f:.3f} | {i_p:.3f} / {i_f:.3f} |"
        )
    lines += [
        "",
        "Per seed:",
        "",
        "| variant | seed | hose | frames | total CPU s | gains | union P / R / F0.4 |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "union" not in r:
            lines.append(
                f"| {r['variant']} | {r['seed']} | {r['hose']} | | | | failed: {r['reason']} |"
            )
            continue
        u = r["union"]
        lines.append(
            f"| {r['variant']} | {r['seed']} | {r['hose']} | {r['frames']} | "
            f"{r['cpu']['total']:.1f} | {', '.join(f'{g:.3f}' for g in r['gains'])} | "
            f"{u['precision']:.3f} / {u['recall']:.3f} / {u['f0.4']:.3f} |"
        )
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
