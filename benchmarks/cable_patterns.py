"""The cable surface patterns side by side, and what drawing them costs per render pass.

    .venv/bin/python -m benchmarks.cable_patterns [--seed 11] [--reps 15] [--write]

Writes ``docs/img/cable_patterns.png`` (titled tiles, the cables cropped at full resolution
and scaled by 0.75: the same scene of a garden hose, an
electrical cable and a rope, each pattern worn by every cable, seen from a camera half as far
from the board as the default one) and, with ``--write``, ``benchmarks/results/
cable_patterns.md``: per pattern, the pattern geoms in the scene and the median wall time of a
colour pass and of a label pass at 640x480 (software OpenGL), each pattern's passes interleaved
with the solid scene's in the same process, so the ratio to solid is the figure to read on a
shared machine.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.cables import PATTERNS
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import CameraConfig, HoseConfig, SceneConfig
from cablesim.sim.world import World
from cablesim.viz import panel, write_png

PICTURE = Path(__file__).resolve().parents[1] / "docs" / "img" / "cable_patterns.png"
KINDS = ("garden_hose", "electrical_cable", "rope")


def _config(seed: int, pattern: str) -> SceneConfig:
    default = CameraConfig()
    look = np.array(default.look_at)
    pos = look + 0.5 * (np.array(default.position) - look)
    return SceneConfig(
        seed=seed, hoses=HoseConfig(count=3, kinds=KINDS, pattern=pattern)
    ).with_values(
        {
            "camera.position": tuple(float(x) for x in pos),
            "camera.look_at": tuple(float(x) for x in look),
        }
    )


def _pass_times(camera: SimCamera, reps: int) -> tuple[list[float], list[float]]:
    colour, labels = [], []
    for _ in range(reps):
        t0 = time.perf_counter()
        camera.capture()
        t1 = time.perf_counter()
        camera.render_labels()
        colour.append(t1 - t0)
        labels.append(time.perf_counter() - t1)
    return colour, labels


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--reps", type=int, default=15, help="render passes per pattern and round")
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/")
    args = ap.parse_args(argv)

    # one settled world; the pattern is a look only, so each pattern's world is the same
    # physics (same seed, same kinds) and is built once from the settle cache
    cameras, worlds, tiles, titles = {}, {}, [], []
    for name in PATTERNS:
        worlds[name] = World.build(_config(args.seed, name))
        cameras[name] = SimCamera(worlds[name])
        image = cameras[name].capture().rgb[60:420, 120:560]  # the cables, full resolution
        tiles.append(cv2.resize(image, None, fx=0.75, fy=0.75, interpolation=cv2.INTER_AREA))
        titles.append(f"{name}: hose, electrical cable, rope (seed {args.seed})")
    rows = [panel(tiles[:3], titles[:3]), panel(tiles[3:], titles[3:])]
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 6), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    write_png(PICTURE, np.vstack(rows))
    print(f"wrote {PICTURE}")

    times: dict[str, dict[str, list[float]]] = {n: {"colour": [], "labels": []} for n in PATTERNS}
    for _round in range(2):  # interleaved: each pattern, then solid again
        for name in PATTERNS:
            for n in (name, "solid"):
                c, lab = _pass_times(cameras[n], args.reps)
                times[n]["colour"] += c
                times[n]["labels"] += lab
    geoms = {}
    for name, cam in cameras.items():
        cam.render_labels()
        geoms[name] = cam._ctx().scene.ngeom  # noqa: SLF001
    solid = {k: statistics.median(v) for k, v in times["solid"].items()}
    lines = [
        "# Cable patterns: render cost",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}; load "
        f"average {pv.load_average(1)}",
        f"- command: `python -m benchmarks.cable_patterns --seed {args.seed} --reps {args.reps} "
        "--write`",
        "- scene: a garden hose, an electrical cable and a rope, 640x480, the camera half as "
        "far from the board as the default; picture: `docs/img/cable_patterns.png`",
        f"- medians of {2 * args.reps} passes per pattern (wall time, software OpenGL, one "
        "thread), interleaved with the solid scene's; the ratio is to solid in the same run",
        "",
        "| pattern | scene geoms | pattern geoms | colour pass (ms) | ratio | label pass (ms) "
        "| ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in PATTERNS:
        med = {k: statistics.median(v) for k, v in times[name].items()}
        lines.append(
            f"| {name} | {geoms[name]} | {geoms[name] - geoms['solid']} | "
            f"{1e3 * med['colour']:.1f} | {med['colour'] / solid['colour']:.2f} | "
            f"{1e3 * med['labels']:.1f} | {med['labels'] / solid['labels']:.2f} |"
        )
    for cam in cameras.values():
        cam.close()
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        write_results(RESULTS / "cable_patterns.md", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
