"""Simulation benchmarks: physics speed, rendering speed, ground-truth flow cost.

    .venv/bin/python -m benchmarks.bench_sim [--repeats 5]

Writes ``benchmarks/results/sim.md``.  Single-threaded (BLAS/OpenMP threads pinned to 1).
Targets: physics >= 3x real time; RGB + depth + labels >= 15 fps at 640x480; GT flow
<= 20 ms per frame at 640x480.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import os
import statistics
import time

import cv2
import mujoco
import numpy as np

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import SceneConfig
from cablesim.sim.flow_gt import gt_flow
from cablesim.sim.world import World

OUT = RESULTS / "sim.md"


def timed(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=500, help="physics steps per repeat")
    ap.add_argument("--frames", type=int, default=20, help="rendered frames per repeat")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    cfg = SceneConfig(seed=0)
    print("[bench] building the default scene (4 hoses, arm on)", flush=True)
    world = World.build(cfg)
    m, d = world.model, world.data
    dt = m.opt.timestep
    print(f"[bench] nq={m.nq} nv={m.nv} nbody={m.nbody} dt={dt}", flush=True)

    # ---- physics
    print(f"[bench] physics: {args.repeats} x {args.steps} steps", flush=True)
    world.step(50)
    phys = timed(lambda: world.step(args.steps), args.repeats)
    steps_s = args.steps / statistics.median(phys)
    rtf = steps_s * dt

    # ---- rendering
    cam = SimCamera(world)
    for _ in range(3):
        cam.snapshot()
    print(
        f"[bench] rendering: {args.repeats} x {args.frames} frames at {cam.width}x{cam.height}",
        flush=True,
    )
    snap_t = [
        t / args.frames
        for t in timed(lambda: [cam.snapshot() for _ in range(args.frames)], args.repeats)
    ]
    cap_t = [
        t / args.frames
        for t in timed(lambda: [cam.capture() for _ in range(args.frames)], args.repeats)
    ]
    lab_t = [
        t / args.frames
        for t in timed(lambda: [cam.render_labels() for _ in range(args.frames)], args.repeats)
    ]

    # ---- ground-truth flow: hose 0 pulled through physics for 0.3 s
    print("[bench] ground-truth flow after pulling a hose for 0.3 s", flush=True)
    world.reset()
    s0 = cam.snapshot()
    hose = world.hoses[0]
    body = int(hose.vertex_bodies[hose.n_vertices // 2])
    d.xfrc_applied[body, :3] = [-0.1, 0.3, 0.05]
    world.step(int(0.3 / dt))
    d.xfrc_applied[body, :3] = 0
    s1 = cam.snapshot()
    moving = int(((s0.labels == 0) | (s0.labels == -2)).sum())

    def flow_fresh() -> None:  # fresh snapshots: per-snapshot segment data not cached
        s0.__dict__.pop("rod", None)
        s1.__dict__.pop("rod", None)
        gt_flow(s0, s1)

    gt_flow(s0, s1)
    flow_t = timed(flow_fresh, max(args.repeats, 10))
    _, valid, _ = gt_flow(s0, s1)
    cam.close()

    med = statistics.median
    rows = [
        ("physics steps/s (default scene)", f"{steps_s:,.0f}", ""),
        ("physics real-time factor", f"{rtf:.2f}x", ">= 3x"),
        ("RGB + depth + labels (snapshot) fps", f"{1 / med(snap_t):.1f}", ">= 15"),
        ("RGB + depth (capture) fps", f"{1 / med(cap_t):.1f}", ""),
        ("labels only (render_labels) fps", f"{1 / med(lab_t):.1f}", ""),
        ("GT flow ms/frame", f"{1000 * med(flow_t):.1f}", "<= 20"),
    ]
    lines = [
        "# Simulation benchmark",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}",
        f"- machine: {pv.machine()} "
        "(BLAS/OpenMP/OpenCV threads pinned to 1; MuJoCo single-threaded)",
        f"- mujoco {mujoco.__version__}, MUJOCO_GL={os.environ.get('MUJOCO_GL')}, "
        f"numpy {np.__version__}",
        f"- scene: seed 0, 4 hoses, arm on, nq={m.nq}, nv={m.nv}, timestep {dt} s",
        f"- image 640x480 (camera default); medians over {args.repeats} repeats "
        f"({args.steps} physics steps, {args.frames} frames each)",
        f"- GT flow case: hose 0 pulled 0.3 s through physics; {moving} hose/robot pixels in "
        f"the source frame, {valid.mean() * 100:.1f}% of all pixels valid",
        "",
        "| measure | value | target |",
        "|---|---|---|",
        *[f"| {a} | {b} | {c} |" for a, b, c in rows],
        "",
    ]
    print("\n".join(lines))
    write_results(OUT, "\n".join(lines))


if __name__ == "__main__":
    main()
