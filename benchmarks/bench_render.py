"""Render cost of the arm's look: primitive geoms vs franka_ros meshes (``RobotConfig.visual``).

    taskset -c 0 .venv/bin/python -m benchmarks.bench_render [--repeats 7]

Writes ``benchmarks/results/render.md``.  One core: the process (and the software rasteriser's
threads, ``LP_NUM_THREADS=1``) is pinned to CPU 0; timings are CPU seconds
(``time.process_time``), medians over repeats, so other load on the machine matters less.
Two arm poses in the default scene (seed 0, 640x480): parked (where ``visual="mesh"`` still
shows the shoulder at the image's right edge) and home (the arm in the middle of the view).
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import os
import statistics
import subprocess
import time

import mujoco
import numpy as np

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.frames import LABEL_ROBOT
from cablesim.panda.model import HOME_QPOS, joint_qpos_addresses
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import SceneConfig
from cablesim.sim.world import World

OUT = RESULTS / "render.md"


def cpu_per_call(fn, frames: int, repeats: int) -> float:
    """Median CPU seconds per call over ``repeats`` batches of ``frames`` calls."""
    out = []
    for _ in range(repeats):
        t0 = time.process_time()
        for _ in range(frames):
            fn()
        out.append((time.process_time() - t0) / frames)
    return statistics.median(out)


def measure(visual: str, frames: int, repeats: int) -> dict[str, float]:
    cfg = SceneConfig(seed=0).with_values({"robot.visual": visual})
    builds = []
    for _ in range(3):  # the first build may settle (or load) the state and import modules
        t0 = time.process_time()
        world = World.build(cfg)
        builds.append(time.process_time() - t0)
    build = statistics.median(builds[1:])
    m = world.model
    out: dict[str, float] = {"build_s": build, "ngeom": m.ngeom, "faces": int(m.nmeshface)}
    with SimCamera(world) as cam:
        for pose in ("park", "home"):
            if pose == "home":
                world.data.qpos[joint_qpos_addresses(m, world.panda.joints)] = HOME_QPOS
                mujoco.mj_forward(m, world.data)
            for _ in range(3):
                cam.snapshot()
            out[f"{pose}_robot_px"] = int((cam.render_labels() == LABEL_ROBOT).sum())
            out[f"{pose}_capture"] = cpu_per_call(cam.capture, frames, repeats)
            out[f"{pose}_snapshot"] = cpu_per_call(cam.snapshot, frames, repeats)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--frames", type=int, default=20, help="rendered frames per repeat")
    args = ap.parse_args()
    os.environ.setdefault("LP_NUM_THREADS", "1")  # Mesa llvmpipe: one rasteriser thread
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    res = {}
    for visual in ("primitive", "mesh"):
        print(f"[bench] {visual}: {args.repeats} x {args.frames} frames per pose", flush=True)
        res[visual] = measure(visual, args.frames, args.repeats)
    p, q = res["primitive"], res["mesh"]

    def fps(x: float) -> str:
        return f"{1 / x:.1f}"

    rows = [
        ("mesh faces in the model", f"{p['faces']:,}", f"{q['faces']:,}"),
        ("geoms in the model", f"{p['ngeom']}", f"{q['ngeom']}"),
        ("World.build (settled state cached), CPU s", f"{p['build_s']:.2f}", f"{q['build_s']:.2f}"),
    ]
    for pose in ("park", "home"):
        rows += [
            (f"{pose}: robot pixels", f"{p[pose + '_robot_px']:,}", f"{q[pose + '_robot_px']:,}"),
            (
                f"{pose}: RGB + depth (capture) fps",
                fps(p[pose + "_capture"]),
                fps(q[pose + "_capture"]),
            ),
            (
                f"{pose}: RGB + depth + labels (snapshot) fps",
                fps(p[pose + "_snapshot"]),
                fps(q[pose + "_snapshot"]),
            ),
        ]
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    lines = [
        "# Render cost of the arm's look (RobotConfig.visual)",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}",
        f"- machine: {pv.machine()}; "
        f"pinned to one core, LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS')}",
        f"- load while measuring: {load}",
        f"- mujoco {mujoco.__version__}, MUJOCO_GL={os.environ.get('MUJOCO_GL')}, "
        f"numpy {np.__version__}",
        "- scene: seed 0, 4 hoses, 640x480; park = RobotConfig.park_qpos, home = HOME_QPOS",
        f"- CPU time per frame, medians over {args.repeats} repeats of {args.frames} frames",
        "",
        "| measure | primitive | mesh |",
        "|---|---|---|",
        *[f"| {a} | {b} | {c} |" for a, b, c in rows],
        "",
    ]
    print("\n".join(lines))
    write_results(OUT, "\n".join(lines))


if __name__ == "__main__":
    main()
