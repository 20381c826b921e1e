"""``cablesim train``: train the learned flow back end from simulated clips (the clips are made
on demand, resumable; a killed run continues from its last checkpoint when the same command
runs again).  ``--config configs/learned_flow.json`` is the config of the shipped default
model (:mod:`cablesim.learn.train` describes the run folder)."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from cablesim.commands._args import add_config_arguments, build_config, show_config
from cablesim.errors import InputError
from cablesim.learn.train import TrainConfig, train
from cablesim.perception.learned import read_weights

FLAGS = {
    "steps": "steps",
    "seed": "seed",
    "data_root": "data.root",
    "threads": "threads",
    "device": "device",
    "init": "init",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, default=None, help="run folder (required; resumed)")
    p.add_argument("--steps", type=int, default=None, help="training steps (3000)")
    p.add_argument("--seed", type=int, default=None, help="seed of the network and the pairs (0)")
    p.add_argument("--data-root", default=None, help="where the simulated clips are made and found")
    p.add_argument("--threads", type=int, default=None, help="torch threads (2)")
    p.add_argument("--device", default=None, help="cpu (default, bit for bit) or cuda (a GPU)")
    p.add_argument(
        "--init",
        default=None,
        help="fine-tune these weights (a shipped name such as raft, or a file)",
    )
    p.add_argument("--workers", type=int, default=2, help="processes making clips (2)")
    p.add_argument("--ray", help="make the clips on Ray: auto, an address, or local")
    p.add_argument("--export", type=Path, default=None, help="copy the final weights here as well")
    p.add_argument("--quiet", action="store_true")
    add_config_arguments(p)


def run(args: argparse.Namespace) -> int:
    cfg = build_config(TrainConfig, args, FLAGS)
    if args.show_config:
        return show_config(cfg)
    if args.out is None:
        raise InputError("--out: the run folder is required")
    if args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    weights = train(cfg, args.out, args.workers, args.ray, not args.quiet)
    if args.export is not None:
        args.export.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(weights, args.export)
        read_weights(args.export)  # what was copied loads
        print(f"exported {args.export}")
    print(f"weights: {weights}  (use: --flow learned,weights={weights})")
    return 0
