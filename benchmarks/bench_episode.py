"""Wall time of one full interaction at default settings (640x480, 4 hoses): one grasp, two
actions of 3 periods, release, retreat, settle, target frame and ground-truth flow, split into
physics and control (stepping, IK), rendering (RGB, depth, label passes) and ground truth
(flow from the target frame to every kept frame).

    .venv/bin/python benchmarks/bench_episode.py [--seed 2] [--repeats 3] [--write]

The scene is built (and its settled state cached) before timing; each repeat resets the world
and runs the same seeded episode.  Pinned to one CPU core (``os.sched_setaffinity``) when the
platform allows, as the target is "at most 45 s on one core".  ``--write`` writes
``benchmarks/results/episode.md``.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from _machine import cpu_model  # noqa: E402  (benchmarks/ is on sys.path)

import cablesim  # noqa: F401  (selects the headless GL back end)
from cablesim.sim.session import EpisodeConfig, SimSession

RESULTS = Path(__file__).parent / "results" / "episode.md"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--hose", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/episode.md")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    args = ap.parse_args()

    pinned = False
    if not args.no_pin and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        pinned = True

    cfg = EpisodeConfig(seed=args.seed, hose=args.hose)
    session = SimSession.build(cfg)
    segment = session.pick_start()
    hose = session.hose
    print(
        f"scene built in {session.build_time:.1f} s; hose {hose}, "
        f"segment {int(segment.mask.sum())} px"
    )

    runs = []
    for i in range(args.repeats):
        session = SimSession.build(cfg, world=session.world, camera=session.camera)
        session.hose = hose
        t = time.perf_counter()
        res = session.interact(segment.mask)
        wall = time.perf_counter() - t
        if not res.success:
            print(f"run {i}: FAILED: {res.reason}")
            return 1
        tm = res.timings
        runs.append(
            {
                "total": wall,
                "physics": tm["physics_control"],
                "rendering": tm["rendering"],
                "ground_truth": tm["ground_truth"],
                "frames": len(res.stream),
                "ticks": res.details.get("ticks", 0),
                "sim_time": res.stream.target.timestamp,
                "gains": [a.gain for a in res.actions],
                "others": res.other_hose_displacement(),
            }
        )
        print(
            f"run {i}: {wall:.1f} s (physics+control {tm['physics_control']:.1f}, rendering "
            f"{tm['rendering']:.1f}, ground truth {tm['ground_truth']:.1f}); "
            f"{len(res.stream)} frames kept of {res.details.get('ticks')} camera ticks; "
            f"gains {', '.join(f'{g:.3f}' for g in runs[-1]['gains'])}"
        )
    session.close()

    def med(k: str) -> float:
        return statistics.median(r[k] for r in runs)

    last = runs[-1]
    lines = [
        "# Episode benchmark",
        "",
        "One full interaction at default settings: 640x480 camera, 4 hoses, one grasp, two "
        "actions (along, across) of 3 periods at +-2 cm and 5 cm/s, camera at 15 frames/s of "
        "simulated time with the 1 mm rule, release, retreat, settle, target frame, "
        "ground-truth flow to every kept frame.  `benchmarks/bench_episode.py --write`.",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- machine: {platform.platform()}, {cpu_model()}, {os.cpu_count()} cores"
        f"{' (run pinned to 1 core)' if pinned else ''}, load average at the end "
        f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}",
        f"- python {sys.version.split()[0]}, MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}",
        f"- seed {args.seed}, hose {hose}, {args.repeats} repeats (medians below)",
        f"- simulated time of the interaction: {last['sim_time']:.1f} s; "
        f"{last['ticks']} camera ticks during the actions, {last['frames']} frames kept "
        "(target included)",
        f"- follow gain per action: {', '.join(f'{g:.3f}' for g in last['gains'])}; largest "
        "displacement of the other hoses: "
        f"{', '.join(f'{d * 1000:.1f} mm' for d in last['others'])}",
        "",
        "| part | median wall time (s) |",
        "|---|---|",
        f"| physics + control (stepping, IK, settling) | {med('physics'):.1f} |",
        f"| rendering (RGB+depth and label passes of kept frames) | {med('rendering'):.1f} |",
        f"| ground truth (flow target -> each kept frame) | {med('ground_truth'):.1f} |",
        f"| **total** | **{med('total'):.1f}** |",
        "",
        "Target: at most 45 s on one CPU core.",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if args.write:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(text)
        print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
