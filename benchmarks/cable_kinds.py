"""The cable kinds side by side: one picture per kind of the same seed's scene, and per kind
what its cables cost and how they bend (settling, vertices, cantilever sag).

    .venv/bin/python -m benchmarks.cable_kinds [--seed 11] [--scene board|table] [--write]

Writes ``docs/img/cable_kinds.png`` (a titled panel, half size: each kind, then a mixed scene;
``docs/img/cable_kinds_table.png`` with ``--scene table``) and, with ``--write``,
``benchmarks/results/cable_kinds.md`` (``cable_kinds_table.md``).  Settling is measured with the settle cache
off, in CPU seconds of this process (``time.process_time``), one build per kind: a rough
figure on a shared machine.  The sag is :func:`cablesim.sim.cantilever.cantilever_sag` of a
level-clamped 0.3 m length at the low, middle (geometric mean) and high end of the kind's
stiffness range.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import dataclasses
import math
import time
from pathlib import Path

import cv2

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.cables import CABLE_KINDS
from cablesim.errors import SceneUnsettledError
from cablesim.sim.camera import SimCamera
from cablesim.sim.cantilever import cantilever_sag
from cablesim.sim.config import HoseConfig, SceneConfig
from cablesim.sim.world import World
from cablesim.viz import panel, write_png

PICTURE = Path(__file__).resolve().parents[1] / "docs" / "img" / "cable_kinds.png"
MIXED = ("garden_hose", "electrical_cable", "thin_wire", "rope")


def _scene(seed: int, hoses: HoseConfig, surface: str = "board") -> tuple[object, dict]:
    cfg = SceneConfig(seed=seed, hoses=hoses, surface=surface)
    cfg = cfg.with_values({"physics.cache": False})
    t0 = time.process_time()
    for draw in range(8):  # as a session does: the next draw where one does not settle
        try:
            world = World.build(cfg.replace(draw=draw))
            break
        except SceneUnsettledError as e:
            print(f"seed {seed} draw {draw} did not settle ({e.speed * 1e3:.1f} mm/s)")
    else:
        raise SystemExit(f"seed {seed}: no draw settled")
    settle = time.process_time() - t0
    camera = SimCamera(world)
    try:
        image = camera.capture().rgb
    finally:
        camera.close()
    image = cv2.resize(image, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)  # docs size
    row = {
        "settle_cpu_s": settle,
        "settle_sim_s": world.time,
        "vertices": sum(h.n_vertices for h in world.hoses),
        "strain": float(world.hose_stretch().max()),
        "draw": world.cfg.draw,
    }
    return image, row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=11, help="the scene of every picture (11)")
    ap.add_argument("--scene", choices=("board", "table"), default="board")
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/cable_kinds.md")
    args = ap.parse_args(argv)
    suffix = "" if args.scene == "board" else f"_{args.scene}"
    picture_path = PICTURE.with_name(f"cable_kinds{suffix}.png")
    results_path = RESULTS / f"cable_kinds{suffix}.md"

    tiles, titles, rows = [], [], {}
    for name, kind in CABLE_KINDS.items():
        image, row = _scene(args.seed, HoseConfig(kind=name), args.scene)
        sags = [cantilever_sag(kind, e) for e in (kind.young[0], None, kind.young[1])]
        rows[name] = {**row, "sag": sags}
        tiles.append(image)
        titles.append(
            f"{name}: {2e3 * kind.radius:.0f} mm, {args.scene}, seed {args.seed}"
            + (f" draw {row['draw']}" if row["draw"] else "")
        )
        print(f"{name}: {row} sag {[round(s, 3) for s in sags]}", flush=True)
    image, row = _scene(args.seed, HoseConfig(kinds=MIXED), args.scene)
    rows["mixed"] = {**row, "sag": []}
    tiles.append(image)
    titles.append(f"one of each kind, {args.scene}, seed {args.seed}")
    picture = panel(tiles, titles)
    write_png(picture_path, picture)
    print(f"wrote {picture_path}")
    if not args.write:
        return 0

    lines = [
        "# Cable kinds (`python -m benchmarks.cable_kinds --write`)",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}; load "
        f"average {pv.load_average(1)} (CPU times are rough: one build each, shared machine)",
        f"- scene: {args.scene}, seed {args.seed}, 4 cables of the kind, settle cache off; sag: a "
        "0.3 m length "
        "clamped level, free end's drop after 4 s at the kind's low / middle / high stiffness",
        "",
        "| kind | diameter | EI (N m^2) | vertices | settle (sim s) | settle (CPU s) | max strain "
        "| sag low / mid / high (mm) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        kind = CABLE_KINDS.get(name)
        if kind is None:
            diameter, ei = "mixed", "-"
        else:
            lo, hi = kind.bending_stiffness()
            diameter, ei = f"{2e3 * kind.radius:.0f} mm", f"{lo:.2g}-{hi:.2g}"
        sag = " / ".join(f"{1e3 * s:.0f}" for s in row["sag"]) or "-"
        lines.append(
            f"| {name} | {diameter} | {ei} | {row['vertices']} | {row['settle_sim_s']:.1f} | "
            f"{row['settle_cpu_s']:.1f} | {row['strain']:.4f} | {sag} |"
        )
    rope, cable = CABLE_KINDS["rope"], CABLE_KINDS["electrical_cable"]
    same = cantilever_sag(dataclasses.replace(cable, radius=rope.radius))
    lines += [
        "",
        f"At the rope's 10 mm, the electrical cable's stiffness sags {1e3 * same:.0f} mm where "
        f"the rope sags {1e3 * rows['rope']['sag'][1]:.0f} mm (the test "
        "`test_a_rope_sags_under_its_own_weight_more_than_a_cable_of_its_diameter`).",
        f"Euler-Bernoulli for the hose at its middle stiffness: "
        f"{1e3 * _beam(CABLE_KINDS['garden_hose']):.0f} mm (small-deflection theory; the rod's "
        "large deflection is less).",
        "",
        f"The picture of the kinds (same seed): `docs/img/{picture_path.name}`.",
    ]
    write_results(results_path, "\n".join(lines) + "\n")
    print(f"wrote {results_path}")
    return 0


def _beam(kind, length: float = 0.3) -> float:
    ei = math.sqrt(kind.young[0] * kind.young[1]) * math.pi * kind.radius**4 / 4
    return kind.mass_per_metre * 9.81 * length**4 / (8 * ei)


if __name__ == "__main__":
    raise SystemExit(main())
