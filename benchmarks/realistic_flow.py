"""Realistic flow: motion correlation with the CPU flow on recorded, noisy, perturbed scenes.

    nice -n 10 .venv/bin/python benchmarks/realistic_flow.py record      # simulate (resumable)
    nice -n 10 .venv/bin/python benchmarks/realistic_flow.py evaluate    # perception + table

``record`` simulates one grasp interaction per scene (perturbed neighbours, arm masks, ground
truth) into ``~/.cache/cablesim/streams`` (``$CABLESIM_STREAMS``) and skips scenes already
there; ``evaluate`` runs the perception variants on the recorded streams, tunes thresholds per
beta on the validation scenes and reports on the test scenes in
``benchmarks/results/realistic_flow.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _rf_record import record  # noqa: E402

VAL_SEEDS, VAL_WANT, VAL_SOLID = range(300, 400), 16, 8
TEST_SEEDS, TEST_WANT, TEST_SOLID = range(400, 500), 24, 12


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("--workers", type=int, default=2)
    r.add_argument("--split", choices=("val", "test", "both"), default="both")
    r.add_argument("--geometry", choices=("default", "thesis"), default="default")
    r.add_argument("--scale", type=float, default=1.0, help="fraction of the scene counts")
    args = ap.parse_args()
    if args.cmd == "record":
        splits, solid = {}, {}
        if args.split in ("val", "both"):
            splits["val"] = (VAL_SEEDS, max(1, round(VAL_WANT * args.scale)))
            solid["val"] = round(VAL_SOLID * args.scale)
        if args.split in ("test", "both"):
            splits["test"] = (TEST_SEEDS, max(1, round(TEST_WANT * args.scale)))
            solid["test"] = round(TEST_SOLID * args.scale)
        out = record(splits, solid, args.workers, args.geometry, log=lambda m: print(m, flush=True))
        for k, v in out.items():
            print(f"{k}: {len(v)} scenes, seeds {[s.seed for s in v]}", flush=True)


if __name__ == "__main__":
    main()
