"""Motion correlation vs the motion segmentation baseline with perturbed neighbouring hoses.

For each seed: the default scene, one grasp interaction on a seeded start segment (two actions,
K_p = 3) while the other hoses are pulled by the seeded perturbation of
``cablesim.sim.perturb`` (and, with ``--also-unperturbed``, the same without it); the
stream is segmented with ground-truth (oracle) flow by both methods at the SPEC's beta = 0.4
thresholds, union of the two actions, and scored against the grasped hose's ground-truth mask
in the target frame.  Writes ``benchmarks/results/methods.md``.

    .venv/bin/python -m benchmarks.experiments.compare_methods --seeds 0 1 2 3 4 5
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import cablesim  # noqa: F401  (headless GL before mujoco)
from benchmarks import RESULTS
from cablesim import provenance as pv
from cablesim.errors import outcome_of
from cablesim.perception.metrics import score_mask
from cablesim.perception.pipeline import compute_statistics, masks_from_statistics
from cablesim.perception.votes import vote_image
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.perturb import PerturbConfig
from cablesim.sim.session import SimSession

METHODS = ("correlation", "segmentation")


def score_seed(seed: int, perturb: bool, flow: str) -> dict:
    """One seed's row; a failure of any kind is recorded by its named outcome, not raised, so
    that the run goes on with the next seed."""
    try:
        return _score_seed(seed, perturb, flow)
    except Exception as e:
        return {"seed": seed, "perturb": perturb, "error": f"{outcome_of(e)}: {e}"}


def _score_seed(seed: int, perturb: bool, flow: str) -> dict:
    session = SimSession.build(
        EpisodeConfig.of(seed=seed, perturb=PerturbConfig(enabled=perturb), truth_every=1)
    )
    try:
        seg = session.pick_start()
        hose = session.hose
        res = session.interact(seg.mask)
        if not res.success:
            return {"seed": seed, "perturb": perturb, "error": f"{res.outcome}: {res.reason}"}
        stream = res.stream
        truth = stream.target.truth.labels == hose
        stats = compute_statistics(stream, flow, methods=METHODS)
        row = {
            "seed": seed,
            "perturb": perturb,
            "hose": hose,
            "neighbour_max_mm": 1000 * max(res.other_hose_displacement() or [0.0]),
        }
        for m in METHODS:
            masks = masks_from_statistics(stats, m)
            s = score_mask(vote_image(list(masks.values())) >= 1, truth)
            row[m] = (s.precision, s.recall, s.f[0.4], s.iou)
        return row
    finally:
        session.close()


def table(rows: list[dict], perturb: bool) -> list[str]:
    out = [
        "| seed | hose | neighbours moved (max, mm) | method | P | R | F_0.4 | IoU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    ok = [r for r in rows if r["perturb"] == perturb and "error" not in r]
    for r in ok:
        for m in METHODS:
            p, rc, f, j = r[m]
            out.append(
                f"| {r['seed']} | {r['hose']} | {r['neighbour_max_mm']:.1f} | {m} | "
                f"{p:.3f} | {rc:.3f} | {f:.3f} | {j:.3f} |"
            )
    for m in METHODS:
        if ok:
            mean = np.mean([r[m] for r in ok], axis=0)
            out.append(
                f"| **mean** ({len(ok)}) | | | **{m}** | **{mean[0]:.3f}** | **{mean[1]:.3f}** "
                f"| **{mean[2]:.3f}** | **{mean[3]:.3f}** |"
            )
    for r in rows:
        if r["perturb"] == perturb and "error" in r:
            out.append(f"| {r['seed']} | | | failed: {r['error'][:60]} | | | | |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--flow", default="oracle")
    ap.add_argument("--also-unperturbed", action="store_true")
    ap.add_argument("--out", type=Path, default=RESULTS / "methods.md")
    args = ap.parse_args()
    t0 = time.time()
    load0 = pv.load_average()
    rows = []
    modes = [True, False] if args.also_unperturbed else [True]
    for perturb in modes:
        for seed in args.seeds:
            t = time.time()
            r = score_seed(seed, perturb, args.flow)
            rows.append(r)
            msg = r.get("error") or " ".join(
                f"{m}: P {r[m][0]:.3f} R {r[m][1]:.3f} F0.4 {r[m][2]:.3f}" for m in METHODS
            )
            print(f"seed {seed} perturb {perturb}: {msg} ({time.time() - t:.0f} s)", flush=True)
    lines = [
        "# Motion correlation vs motion segmentation, neighbouring hoses perturbed",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}",
        f"- machine: {pv.machine()}; load average at start / end {load0} / {pv.load_average()}",
        f"- flow: {args.flow}; default scene per seed (4 hoses, 640x480), one grasp, two actions "
        "(along, across), K_p = 3, |D| = 2 cm; thresholds of SPEC beta = 0.4 "
        "(tau_v 0.47; c0_min 0.18, R2_min 0.86); union of the two actions",
        f"- perturbation: `{PerturbConfig(enabled=True)!r}`: every other hose pulled at "
        "`points` vertices by a capped spring towards rest + A sin(2 pi t / P + phase) e, e in "
        "the board plane, seeded, during the actions only",
        "- generated by `python -m benchmarks.experiments.compare_methods --seeds "
        f"{' '.join(map(str, args.seeds))}"
        f"{' --also-unperturbed' if args.also_unperturbed else ''}` "
        f"in {time.time() - t0:.0f} s",
        "",
        "## Neighbours perturbed",
        "",
        *table(rows, True),
    ]
    if args.also_unperturbed:
        lines += ["", "## Not perturbed (contacts only)", "", *table(rows, False)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
