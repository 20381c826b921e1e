"""The digital twin next to pure simulation: the whole real path (franky -> franka-sim, twin,
live RealSense software device, StreamClock, run_interaction, DIS + motion correlation, grasp
sampler) and the same seeds simulated, with the same perception.

    .venv/bin/python -m benchmarks.bench_twin [--seeds 0 1 2] [--write]

Per seed: the interaction's outcome, frames kept per action, the follow gain in the twin, the
frame/pose skew of the StreamClock, the twin's lag and tracking, F_0.4 (votes >= 1 against the
target frame's labels of the hose of interest) in the twin and in pure simulation, and the
grade of the grasp sampler's next proposal.  The scene is small (3 hoses, 320x240, one period
per action), as in ``tests/robot/test_twin.py``.  Needs the franka-sim environment (README
"Real robot").  Real time: the load average of the machine is recorded, since the twin and
the server share the CPU with everything else.  ``--write`` writes
``benchmarks/results/twin.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import cablesim  # noqa: F401  (selects the headless GL back end)
from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.episode.config import ActionConfig, InteractionConfig
from cablesim.progress import Progress
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig
from cablesim.twin import FrankaSimServer
from cablesim.twin.episode import sim_episode, twin_episode

OUT = RESULTS / "twin.md"


def config(seed: int) -> EpisodeConfig:
    return EpisodeConfig(
        scene=SceneConfig(seed=seed, hoses=HoseConfig(count=3), camera=CameraConfig(320, 240)),
        interaction=InteractionConfig(actions=ActionConfig(periods=1)),
    )


def _f(x: float | None, fmt: str = ".3f") -> str:
    return "-" if x is None or x != x else format(x, fmt)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/twin.md")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    say = Progress("twin", not args.quiet)
    rows, records = [], []
    for seed in args.seeds:
        cfg = config(seed)
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        with FrankaSimServer(
            object_width=cfg.scene.hoses.max_diameter(), enforce_motion_limits=False
        ):
            ep = twin_episode(cfg, say=say, monitor_every=5.0)
        twin_s = time.perf_counter() - t0
        say(ep.summary())
        t0 = time.perf_counter()
        sim, sim_p = sim_episode(cfg)
        sim_s = time.perf_counter() - t0
        load1 = os.getloadavg()[0]
        r = ep.result
        c, tw, tr = ep.clock, ep.twin, ep.truth
        rows.append(
            f"| {seed} | {ep.hose} | {'ok' if r.success else 'FAILED: ' + r.reason[:40]} | "
            f"{', '.join(str(k) for k in ep.frames_kept) or '-'} | "
            f"{', '.join(_f(g) for g in ep.gains) or '-'} | "
            f"{_f(1000 * c.get('skew_median_s', float('nan')), '.1f')} / "
            f"{_f(1000 * c.get('skew_max_s', float('nan')), '.1f')} | "
            f"{_f(tr.get('pairing_error_mm', {}).get('median'), '.1f')} | "
            f"{_f(tw['lag_ms_median'], '.0f')} / {_f(tw['lag_ms_max'], '.0f')} | "
            f"{_f(tw['tracking_mm_median'], '.1f')} | "
            f"{_f(ep.perceived.scores.get('f0.4'))} ({ep.perceived.proposal_grade or '-'}) | "
            f"{_f(sim_p.scores.get('f0.4'))} ({sim_p.proposal_grade or '-'}) | "
            f"{twin_s:.0f} / {sim_s:.0f} | {load0:.1f}-{load1:.1f} |"
        )
        records.append(
            {
                "seed": seed,
                "twin": ep.metrics(),
                "sim": {
                    "success": sim.result.success,
                    "reason": sim.result.reason,
                    "hose": sim.session.hose,
                    "frames_kept": [a.frames_kept for a in sim.result.actions],
                    "gains": [a.gain for a in sim.result.actions],
                    "perception": sim_p.to_dict(),
                },
            }
        )
    lines = [
        "# Digital twin next to pure simulation",
        "",
        "The whole real path with no hardware (`cablesim.twin`): FrankyPanda -> franka-sim on "
        "127.0.0.1, a real-time twin world following the measured joints and gripper, its "
        "RGB-D frames through a live librealsense software device into RealSenseCamera, "
        "StreamClock, run_interaction, DIS + motion correlation, the grasp sampler; and the "
        "same seeds in pure simulation (`simulate_episode`) with the same perception.  "
        "3 hoses, 320x240, one period per action.  `python -m benchmarks.bench_twin --write`.",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}",
        f"- machine: {pv.machine()}, shared (load average per seed in the table: before-after)",
        f"- python {sys.version.split()[0]}, MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}",
        "",
        "| seed | hose | twin interaction | frames kept | follow gain (twin) | skew median / "
        "max (ms) | pairing error (mm) | twin lag median / max (ms) | tracking (mm) | F0.4 "
        "twin (next proposal) | F0.4 sim (next proposal) | wall s twin / sim | load |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "Skew: |pose sample time - the time the frame was taken| (StreamClock with "
        "frame_time=twin.frame_time: the twin time the frame shows).  Pairing error: distance "
        "between the gripper position paired with a frame and the twin TCP the frame shows.  "
        "Lag: wall time minus the twin time a frame shows, when rendered.  Tracking: twin TCP "
        "vs the replayed robot joints' TCP.",
        "",
        "```json",
        json.dumps(records, indent=1, default=str)[:20000],
        "```",
        "",
    ]
    text = "\n".join(lines)
    print("\n".join(lines[: 12 + len(rows)]))
    if args.write:
        write_results(OUT, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
