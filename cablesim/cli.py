"""The ``cablesim`` command line: a thin dispatcher over subcommand modules.

Each subcommand lives in ``cablesim.commands.<name>`` with two functions:
``add_arguments(parser)`` and ``run(args) -> int``.  To add one, write the module and list
its name in ``SUBCOMMANDS``.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

import cablesim
from cablesim.errors import CablesimError

# name -> one-line help; implementation in cablesim.commands.<name>
SUBCOMMANDS: dict[str, str] = {
    "scene": "build and settle a scene, render RGB/depth/labels, move a hose, write GT flow",
    "episode": "one interaction: grasp a hose, periodic actions, retreat, target frame, record",
    "explore": "explore a hose: grasps, motion correlation, grasp sampler, merged votes, metrics",
    "calibrate": "eye-to-hand camera calibration with a ChArUco board in the gripper",
    "view": "write a rerun recording (.rrd) of a recording or run folder, or open one",
    "segment": "run perception on a recorded interaction (any layout): votes, masks, scores",
    "benchmark": "the thesis's tables in simulation: tuned on validation scenes, scored on test",
    "dataset": "write simulated sequences in the published layouts (MovingCables, mcor)",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cablesim", description="Simulation-first interactive perception of cables."
    )
    parser.add_argument("--version", action="version", version=f"cablesim {cablesim.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, help_text in SUBCOMMANDS.items():
        module = importlib.import_module(f"cablesim.commands.{name}")
        p = sub.add_parser(name, help=help_text, description=module.__doc__)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except CablesimError as e:
        print(f"cablesim {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
