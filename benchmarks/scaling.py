"""How one interaction's cost grows with the number of hoses, the camera's resolution and the
number of action periods, so that a user can size a study before running it.

    .venv/bin/python -m benchmarks.scaling [--seeds 11900 11901] [--axis hoses ...]
        [--explore] [--write] [--json-out FILE]

One factor at a time around the default (4 hoses, 640x480, 3 periods).  For every (setting,
seed), pinned to one core, single-threaded:

- **build**: the scene built without the settle cache (``physics.cache`` off), as a fresh seed
  is built the first time: layout, settling, robot, camera.  Later runs of the
  same seed and physics read the settled state from the cache (under a second).
- **interaction**: the episode benchmark's stages (``bench_episode.py``: physics and control,
  rendering, ground truth, the default CPU perception) of one interaction, with the follow
  gains and the default correlation's union F0.4 against the target frame's ground truth.

``--explore`` also times ``cablesim explore --seed S --quiet`` (the default exploration: a
budget of 3 successful grasps) end to end for the default setting, as a user runs it,
so that the row's "per exploration" estimate (build + grasps x interaction) can be compared
with a measured one.  ``--write`` writes ``benchmarks/results/scaling.md``.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from benchmarks._interaction import pin_to_one_core, run_meta, single_thread_environment, uptime
from benchmarks.episode_variants import check_assignments, scored_interaction
from cablesim.sweep import episode_config

OUT = RESULTS / "scaling.md"
STAGES = ("physics_control", "rendering", "ground_truth", "perception")
EXPLORE_GRASPS = 3  # cablesim explore's default budget of successful grasps

#: axis -> [(label, assignments)], the default setting first
AXES: dict[str, list[tuple[str, tuple[str, ...]]]] = {
    "hoses": [
        (f"{n} hoses", (f"scene.hoses.count={n}",) if n != 4 else ()) for n in (4, 1, 2, 6, 8)
    ],
    "resolution": [
        (
            f"{w}x{h}",
            (f"scene.camera.width={w}", f"scene.camera.height={h}") if w != 640 else (),
        )
        for w, h in ((640, 480), (320, 240), (480, 360), (960, 720))
    ]
    # 16:9 at the same vertical field of view sees the parked arm in the target frame, which
    # the interaction refuses (robot_in_view): timed with that check off
    + [
        (
            "1280x720 (parked arm in view)",
            (
                "scene.camera.width=1280",
                "scene.camera.height=720",
                "interaction.retreat.verify=false",
            ),
        )
    ],
    "periods": [
        (f"{p} periods", (f"interaction.actions.periods={p}",) if p != 3 else ())
        for p in (3, 1, 2, 4)
    ],
}
DEFAULT = "4 hoses, 640x480, 3 periods"


def run_setting(assignments: tuple[str, ...], seed: int) -> dict:
    """Cold build (``physics.cache`` off: the scene settles as a fresh seed's first build
    does) and one interaction of ``seed`` under ``assignments``."""
    from cablesim.sim.session import SimSession

    c0 = time.process_time()
    session = SimSession.build(episode_config((*assignments, "scene.physics.cache=false"), seed))
    build = time.process_time() - c0
    try:
        return scored_interaction(session, seed) | {"build_cpu": build}
    finally:
        session.close()


def time_explore(seed: int, core: int | None) -> dict:
    """``cablesim explore --seed S --quiet`` end to end in a child process on the same core
    (settle cache: an empty temporary one, as on a fresh machine)."""
    with tempfile.TemporaryDirectory(prefix="cablesim-scaling-") as tmp:
        env = dict(os.environ, CABLESIM_CACHE=str(Path(tmp) / "cache"))
        cmd = [sys.executable, "-m", "cablesim.cli", "explore", "--seed", str(seed), "--quiet"]
        cmd += ["--out", str(Path(tmp) / "out")]
        t0 = time.perf_counter()
        before = os.times()
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        after = os.times()
        wall = time.perf_counter() - t0
        metrics = {}
        path = Path(tmp) / "out" / "metrics.json"
        if path.exists():
            metrics = json.loads(path.read_text())
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return {
        "seed": seed,
        "exit": proc.returncode,
        "wall": wall,
        "cpu": cpu,
        "grasps": _grasps(metrics),
        "error": proc.stderr[-500:] if proc.returncode else "",
        "core": core,
    }


def _grasps(metrics: dict) -> str:
    """'successful / attempts' from explore's metrics.json (as far as it says)."""
    attempts = metrics.get("interactions")
    if isinstance(attempts, list):
        return f"{metrics.get('successful_interactions', '?')}/{len(attempts)}"
    return "?"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[11900, 11901])
    ap.add_argument("--axis", choices=list(AXES), nargs="+", default=list(AXES))
    ap.add_argument("--explore", action="store_true", help="also time `cablesim explore`")
    ap.add_argument("--write", action="store_true", help=f"write {OUT}")
    ap.add_argument("--json-out", type=Path, help="save the rows as JSON")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    args = ap.parse_args()
    single_thread_environment()  # before the first rendering (and the child processes)

    settings: dict[str, tuple[str, ...]] = {}
    axis_of: dict[str, list[str]] = {}
    for axis in args.axis:
        for i, (label, assignments) in enumerate(AXES[axis]):
            name = DEFAULT if i == 0 else label
            settings[name] = assignments
            axis_of.setdefault(name, []).append(axis)
    check_assignments(ap, settings, "setting")
    core = None if args.no_pin else pin_to_one_core()
    load_start = uptime()
    rows = []
    for name, assignments in settings.items():
        for seed in args.seeds:
            row = run_setting(assignments, seed) | {"setting": name, "set": list(assignments)}
            rows.append(row)
            total = row["cpu"].get("total", float("nan"))
            print(
                f"{name} / seed {seed}: {'ok' if row['success'] else 'FAILED ' + row['reason']}; "
                f"build {row['build_cpu']:.1f} s, interaction {total:.1f} s CPU",
                flush=True,
            )
    explores = []
    if args.explore:
        for seed in args.seeds:
            e = time_explore(seed, core)
            explores.append(e)
            print(f"explore / seed {seed}: exit {e['exit']}, CPU {e['cpu']:.1f} s", flush=True)
    meta = run_meta(pinned_core=core, load_start=load_start, load_end=uptime(), seeds=args.seeds)
    if args.json_out:
        args.json_out.write_text(
            json.dumps({"meta": meta, "rows": rows, "explore": explores}, indent=1)
        )
    text = report(meta, rows, settings, axis_of, explores)
    print(text)
    if args.write:
        write_results(OUT, text)
    return 0


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def report(
    meta: dict,
    rows: list[dict],
    settings: dict[str, tuple[str, ...]],
    axis_of: dict[str, list[str]],
    explores: list[dict],
) -> str:
    lines = [
        "# Scaling: what an interaction and an exploration cost, by hoses, resolution and periods",
        "",
        "One factor at a time around the default (4 hoses, 640x480, 3 periods), pinned to one "
        "core, single-threaded.  *Build*: the scene built without the settle cache (a fresh seed's "
        "first build; later builds of the same seed and physics read the cache).  "
        "*Interaction*: the episode benchmark's stages (`bench_episode.py`: physics and "
        "control, rendering, ground truth, the default CPU perception).  *Per exploration*: "
        f"build + {EXPLORE_GRASPS} x interaction, the default `cablesim explore` budget of "
        f"{EXPLORE_GRASPS} successful grasps when none fails (a failed attempt costs up to one "
        "interaction more; pictures, video and the sampler add a few seconds).  "
        "`python -m benchmarks.scaling --write`.",
        "",
        f"- date: {meta['date']}; cablesim commit {meta['commit']}",
        f"- machine: {meta['machine']}; run pinned to core {meta['pinned_core']}",
        f"- {meta['versions']}",
        f"- load (shared machine), start: `{meta['load_start']}`; end: `{meta['load_end']}`",
        f"- seeds: {', '.join(str(s) for s in meta['seeds'])} (medians over them)",
        "",
        "| axis | setting | ok | sim s | frames | build (cold) | physics | render | truth "
        "| perception | **per interaction** | **per exploration** | gain min | union F0.4 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in settings:
        sr = [r for r in rows if r["setting"] == name]
        ok = [r for r in sr if "union" in r]
        axes = "<br>".join(axis_of[name]) if name != DEFAULT else "all (default)"
        if not ok:
            lines.append(f"| {axes} | {name} | 0/{len(sr)} |" + " |" * 11)
            continue
        build = _median([r["build_cpu"] for r in ok])
        stages = [_median([r["cpu"][k] for r in ok]) for k in STAGES]
        total = _median([r["cpu"]["total"] for r in ok])
        lines.append(
            f"| {axes} | {name} | {len(ok)}/{len(sr)} | "
            f"{_median([r['sim_time'] for r in ok]):.1f} | "
            f"{_median([r['frames'] for r in ok]):.0f} | {build:.1f} | "
            + " | ".join(f"{s:.1f}" for s in stages)
            + f" | **{total:.1f}** | **{build + EXPLORE_GRASPS * total:.0f}** | "
            f"{min(min(r['gains']) for r in ok):.3f} | "
            f"{_median([r['union']['f0.4'] for r in ok]):.3f} |"
        )
    if explores:
        lines += [
            "",
            "Measured: `cablesim explore --seed S --quiet` end to end (default setting, empty "
            "settle cache, one core), against the default row's per-exploration estimate:",
            "",
            "| seed | exit | successful / attempts | CPU (s) | wall (s) |",
            "|---|---|---|---|---|",
        ]
        for e in explores:
            lines.append(
                f"| {e['seed']} | {e['exit']} | {e['grasps']} | {e['cpu']:.1f} | {e['wall']:.1f} |"
            )
    lines += [
        "",
        "Per seed (CPU seconds):",
        "",
        "| setting | seed | hose | build | interaction | gains | union F0.4 |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "union" not in r:
            lines.append(
                f"| {r['setting']} | {r['seed']} | {r['hose']} | {r['build_cpu']:.1f} | | | "
                f"failed: {r['reason']} |"
            )
            continue
        lines.append(
            f"| {r['setting']} | {r['seed']} | {r['hose']} | {r['build_cpu']:.1f} | "
            f"{r['cpu']['total']:.1f} | {', '.join(f'{g:.3f}' for g in r['gains'])} | "
            f"{r['union']['f0.4']:.3f} |"
        )
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
