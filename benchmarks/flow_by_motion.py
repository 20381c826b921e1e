"""Where each flow back end fails: the error on moving hose pixels by how far they moved.

    .venv/bin/python -m benchmarks.flow_by_motion --data SPLIT [SPLIT ...] [--flow SPEC ...]
        [--every N] [--truth normal_flow|flow] [--write]

``SPLIT`` is a MovingCables split folder of simulated clips (``benchmarks.learned_flow``'s
held-out test clips).  The MovingCables protocol's flow (from each image to the first, the
arm -- the clip's "stick" -- left out) is scored on the pixels whose true flow exceeds 1 px,
binned by the true flow's magnitude.  Per bin and back end: the mean end-point error (EPE),
the mean predicted magnitude as a share of the true one (``found``: 0 where the back end sees
no motion at all) and the share of pixels ``tracked`` (error under half the true magnitude).

It answers one question the pooled table in ``learned_flow.md`` cannot: whether a back end's
error on moving pixels comes from imprecise flow (small errors on every pixel) or from motion
it misses altogether (``found`` near 0, EPE near the motion itself), which no local refinement
of DIS can recover.  Every ``--every``-th image of each clip is scored (the first is its own
reference and left out).  Writes ``benchmarks/results/flow_by_motion.md`` (or ``--out``) with
``--write``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.formats.movingcables import list_clips, read_clip
from cablesim.perception.flow import make_flow

BINS = (1.0, 2.0, 4.0, 8.0, 16.0, float("inf"))
DEFAULT_FLOWS = ("dis", "dis-medium", "farneback", "learned,base=network,gate=null")


def bin_label(i: int) -> str:
    lo, hi = BINS[i], BINS[i + 1]
    return f"> {lo:g} px" if hi == float("inf") else f"{lo:g}-{hi:g} px"


class Tally:
    """Sums per magnitude bin: pixels, error, predicted magnitude, true magnitude, tracked."""

    def __init__(self) -> None:
        n = len(BINS) - 1
        self.count = np.zeros(n)
        self.err = np.zeros(n)
        self.pred = np.zeros(n)
        self.true = np.zeros(n)
        self.tracked = np.zeros(n)

    def add(self, gt: np.ndarray, pred: np.ndarray, known: np.ndarray) -> None:
        mag = np.linalg.norm(gt, axis=2)
        err = np.linalg.norm(pred - gt, axis=2)
        pmag = np.linalg.norm(pred, axis=2)
        for i in range(len(BINS) - 1):
            m = known & (mag > BINS[i]) & (mag <= BINS[i + 1])
            self.count[i] += m.sum()
            self.err[i] += err[m].sum()
            self.pred[i] += pmag[m].sum()
            self.true[i] += mag[m].sum()
            self.tracked[i] += (err[m] < 0.5 * mag[m]).sum()

    def rows(self) -> list[dict[str, float]]:
        """One row per bin, then the row of all moving pixels."""
        sums = (self.count, self.true, self.err, self.pred, self.tracked)
        per_bin = [(bin_label(i), *(a[i] for a in sums)) for i in range(len(BINS) - 1)]
        return [_row(*r) for r in [*per_bin, ("all > 1 px", *(a.sum() for a in sums))]]


def _row(label: str, count: float, true: float, err: float, pred: float, tracked: float) -> dict:
    c = max(count, 1.0)
    return {
        "bin": label,
        "pixels": int(count),
        "mean_true": true / c,
        "epe": err / c,
        "found": pred / max(true, 1e-9),
        "tracked": tracked / c,
    }


def measure(splits: list[Path], flows: list[str], every: int, truth: str) -> dict[str, Tally]:
    """One pass over the clips; every back end sees the same images."""
    ests = {f: make_flow(f) for f in flows}
    tallies = {f: Tally() for f in flows}
    for split in splits:
        for clip in list_clips(split):
            first = None
            for k, fr in enumerate(read_clip(split, clip)):
                if first is None:
                    first = fr.rgb
                    continue
                if k % every:
                    continue
                gt = fr.normal_flow if truth == "normal_flow" else fr.flow
                known = np.ones(gt.shape[:2], bool)
                if fr.stick_mask is not None:
                    known &= ~fr.stick_mask
                for f, est in ests.items():
                    tallies[f].add(gt, est.compute(fr.rgb, first), known)
            print(f"{split.parent.name}/{clip} done", flush=True)
    return tallies


def report(tallies: dict[str, Tally], splits: list[Path], every: int, truth: str) -> str:
    lines = [
        "# Flow error on moving pixels by how far they moved (`python -m benchmarks.flow_by_motion`)",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}",
        "- clips: "
        + ", ".join(f"`{s.parent.name}/{s.name}` ({len(list_clips(s))} clips)" for s in splits)
        + f"; every {every}th image, flow to the first image (the MovingCables protocol)",
        f"- truth: the exact {truth.replace('_', ' ')}; pixels whose true flow exceeds 1 px, "
        "the arm left out; `found` = mean predicted magnitude / mean true magnitude, "
        "`tracked` = share of pixels with error under half their true motion",
        "",
        "## Error by true motion",
        "",
        "| true motion | pixels | mean motion (zero flow's EPE) | "
        + " | ".join(f"{f} EPE / found / tracked" for f in tallies)
        + " |",
        "|---|---|---|" + "---|" * len(tallies),
    ]
    rows = {f: t.rows() for f, t in tallies.items()}
    first = next(iter(rows.values()))
    for i, r in enumerate(first):
        cells = [
            f"{rows[f][i]['epe']:.2f} / {rows[f][i]['found']:.2f} / {rows[f][i]['tracked']:.2f}"
            for f in tallies
        ]
        lines.append(
            f"| {r['bin']} | {r['pixels']} | {r['mean_true']:.2f} | " + " | ".join(cells) + " |"
        )
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, nargs="+", required=True, help="split folders")
    ap.add_argument("--flow", nargs="+", default=list(DEFAULT_FLOWS), help="flow back ends")
    ap.add_argument("--every", type=int, default=4, help="score every N-th image (default 4)")
    ap.add_argument("--truth", default="normal_flow", choices=["normal_flow", "flow"])
    ap.add_argument("--write", action="store_true", help="write results/flow_by_motion.md")
    ap.add_argument("--out", type=Path, default=RESULTS / "flow_by_motion.md", help="with --write")
    args = ap.parse_args(argv)
    if args.every < 1:
        ap.error(f"--every must be at least 1, got {args.every}")
    for s in args.data:
        list_clips(s)  # a bad folder stops here
    tallies = measure(args.data, args.flow, args.every, args.truth)
    text = report(tallies, args.data, args.every, args.truth)
    if args.write:
        write_results(args.out, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
