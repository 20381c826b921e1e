"""The ``cablesim`` command line: a thin dispatcher over subcommand modules.

Each subcommand lives in ``cablesim.commands.<name>`` with two functions:
``add_arguments(parser)`` and ``run(args) -> int``.  To add one, write the module and list
its name in ``SUBCOMMANDS``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Iterable, Sequence

import cablesim
from cablesim.commands._args import output_path
from cablesim.errors import CablesimError

# name -> one-line help; implementation in cablesim.commands.<name>
SUBCOMMANDS: dict[str, str] = {
    "scene": "build and settle a scene, render RGB/depth/labels, move a hose, write GT flow",
    "episode": "one interaction: grasp a hose, periodic actions, retreat, target frame, record",
    "explore": "explore a hose: grasps, motion correlation, grasp sampler, merged votes, metrics",
    "calibrate": "eye-to-hand camera calibration with a ChArUco board in the gripper",
    "view": "write a rerun recording (.rrd) of a recording or run folder, or open one",
    "segment": "run perception on a recorded interaction (any layout): votes, masks, scores",
    "twin": "the real-robot path with no hardware: franka-sim + a digital twin + RealSense",
    "benchmark": "the thesis's tables in simulation: tuned on validation scenes, scored on test",
    "dataset": "write simulated sequences in the published layouts (MovingCables, mcor)",
    "train": "train the learned flow back end on simulated clips with exact flow (torch)",
    "cables": "list the cable kinds (garden hose, electrical cable, thin wire, rope) and their parameters",
}


def build_parser(commands: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """The parser with every subcommand; the arguments of those in ``commands`` only (all when
    None): a subcommand's module imports what it runs (the simulator, perception), so that
    ``cablesim --help`` and ``cablesim episode`` load only what they need."""
    wanted = set(SUBCOMMANDS if commands is None else commands)
    parser = argparse.ArgumentParser(
        prog="cablesim", description="Simulation-first interactive perception of cables."
    )
    parser.add_argument("--version", action="version", version=f"cablesim {cablesim.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, help_text in SUBCOMMANDS.items():
        if name not in wanted:
            sub.add_parser(name, help=help_text)
            continue
        module = importlib.import_module(f"cablesim.commands.{name}")
        p = sub.add_parser(name, help=help_text, description=module.__doc__)
        module.add_arguments(p)
        for action in p._actions:  # every --out refuses "" (Path("") is the current directory)
            if action.dest == "out":
                action.type = output_path
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run a subcommand; every expected failure (bad input, a file that cannot be written, an
    interruption) ends in one line on stderr and a non-zero exit status, never a traceback."""
    argv = sys.argv[1:] if argv is None else list(argv)
    # the subcommand is the first word that is no option (the top level has only options)
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser([command] if command in SUBCOMMANDS else [])
    args = parser.parse_args(argv)
    prefix = f"cablesim {args.command}"
    try:
        return int(args._run(args) or 0)
    except CablesimError as e:
        _say(f"{prefix}: error: {_one_line(e)}")
        return 2
    except OSError as e:
        if isinstance(e, BrokenPipeError):  # the reader went away: no more output to stdout
            _silence_stdout()
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        _say(f"{prefix}: error: {where}{e.strerror or _one_line(e)}")
        return 2
    except KeyboardInterrupt:
        _say(f"{prefix}: interrupted")
        return 130


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _say(line: str) -> None:
    try:
        sys.stdout.flush()
    except (OSError, ValueError):  # a closed pipe
        pass
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
