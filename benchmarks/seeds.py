"""Does every seed give an interaction?  One default interaction per seed of a range, as
``cablesim episode --seed S`` runs it (default config: 4 hoses, 640x480, hose of interest and
start segment drawn from the seed), with the outcome of each seed recorded by name.

    nice -n 10 .venv/bin/python -m benchmarks.seeds --first 1000 --count 100 --workers 2 --write

The runner is :mod:`cablesim.sweep` (what a row holds, resuming, what differs between a
resumed and an uninterrupted run: :data:`cablesim.sweep.VOLATILE`).  Seeds run in independent
``spawn`` worker processes (``--workers``; ``0`` runs them in this process); a seed's result
does not depend on the number of workers or on the order.  ``--cache-dir`` points the settle
cache (``$CABLESIM_CACHE``) somewhere else, e.g. an empty directory so that the times include
settling as a new user's first run does.  ``--write`` writes ``benchmarks/results/seeds.md``
and ``seeds.json``; results are also written after every seed (``--json``, atomically), so an
interrupted run keeps what it had, and the same command again resumes: the seeds already in
the ``--json`` file, run at the same commit with the same ``--set``, are kept and not run again
(``--fresh`` runs them all).  A second run writing the same file meanwhile is refused
(``.<name>.lock`` beside it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from benchmarks import RESULTS
from cablesim import sweep


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=1000, help="first seed (1000)")
    ap.add_argument("--count", type=int, default=100, help="number of consecutive seeds (100)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="explicit seeds instead")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (2)")
    ap.add_argument("--cache-dir", type=Path, default=None, help="settle cache to use")
    ap.add_argument("--json", type=Path, default=None, help="write the rows here as they come")
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/seeds.md/json")
    ap.add_argument("--md", type=Path, default=None, help="write the markdown table here")
    ap.add_argument(
        "--fresh", action="store_true", help="run every seed, even those already in --json"
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="change a field of the episode config (repeatable), e.g. --set "
        "scene.camera.width=320; `cablesim explore --show-config` lists the fields (without "
        "their `episode.` prefix here)",
    )
    args = ap.parse_args(argv)
    config = None
    if args.set:  # a bad field or value stops here, before any worker starts
        from cablesim.errors import ConfigError

        try:
            config = sweep.episode_config(args.set).to_dict()
        except ConfigError as e:
            ap.error(f"--set: {e}")
    seeds = (
        args.seeds if args.seeds is not None else list(range(args.first, args.first + args.count))
    )
    json_path = args.json or (RESULTS / "seeds.json" if args.write else None)
    md_path = args.md or (RESULTS / "seeds.md" if args.write else None)
    if args.workers < 0:
        ap.error(f"--workers must be 0 (this process) or more, got {args.workers}")
    from cablesim.errors import CablesimError
    from cablesim.files import OutputLock

    locks = [
        OutputLock(p.parent, name=f".{p.name}.lock") for p in (json_path, md_path) if p is not None
    ]
    try:
        for lock in locks:  # refused at once while another run writes the same file
            lock.acquire()
    except CablesimError as e:
        for lock in locks:
            lock.release()
        print(f"benchmarks.seeds: error: {e}", file=sys.stderr)
        return 2
    try:
        summary = sweep.run_sweep(
            seeds,
            config=config,
            config_changes=args.set,
            workers=args.workers,
            cache_dir=args.cache_dir,
            json_path=json_path,
            md_path=md_path,
            fresh=args.fresh,
            command="python -m benchmarks.seeds "
            + " ".join(argv if argv is not None else sys.argv[1:]),
        )
    finally:
        for lock in locks:
            lock.release()
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
