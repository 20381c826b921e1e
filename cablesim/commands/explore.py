"""Explore one hose of a seeded scene: a start segment (the stand-in for a person clicking),
then grasp, two periodic actions, motion correlation on the stream, and the grasp sampler's
next reachable grasp on the same hose, up to a budget of grasps; the votes of all grasps are
merged in the latest target frame and scored against ground truth.

Files in --out: start.png, interaction{k}_votes.png (target | votes in green | ground truth |
aimed segment), interaction{k}_flow.png (estimated | ground-truth flow), interaction{k}_maps.png
(|c0| and R^2 per action), merged.png, episode.mp4 (or episode.gif), metrics.json (precision,
recall, F_0.4, IoU per interaction and merged; the config).  The metrics are also printed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cablesim.commands._args import (
    add_interaction_arguments,
    add_scene_arguments,
    apply_interaction_arguments,
    apply_scene_arguments,
    check_settle_cache,
    prepare_output_dir,
)
from cablesim.policies.config import FLOWS, MERGES, STRATEGIES, ExploreConfig
from cablesim.sim.perturb import PerturbConfig


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p, "scene and exploration seed")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--hose", type=int, default=None, help="hose of interest (default: drawn)")
    p.add_argument("--grasps", type=int, default=3, help="budget of successful grasps (3)")
    p.add_argument("--strategy", choices=STRATEGIES, default="sampler", help="next-grasp policy")
    p.add_argument(
        "--method",
        choices=("correlation", "segmentation", "ablation"),
        default=None,
        help="segmentation method (default: correlation; segmentation for --strategy push)",
    )
    p.add_argument("--flow", choices=FLOWS, default="dis", help="optical flow back end (dis)")
    p.add_argument("--raft-checkpoint", type=Path, default=None, help="weights for --flow raft")
    p.add_argument(
        "--merge",
        choices=MERGES,
        default="dis",
        help="vote carrying between targets: dis (default), oracle (ground truth), none",
    )
    p.add_argument("--perturb", action="store_true", help="disturb neighbouring hoses in actions")
    add_interaction_arguments(p)


def config_from_args(args: argparse.Namespace) -> ExploreConfig:
    cfg = ExploreConfig(
        seed=args.seed,
        hose=args.hose,
        grasps=args.grasps,
        max_attempts=max(2 * args.grasps, args.grasps + 2),
        strategy=args.strategy,
        method=args.method,
        flow=args.flow,
        merge=args.merge,
        perturb=PerturbConfig(enabled=bool(args.perturb)),
        progress=not args.quiet,
    )
    apply_scene_arguments(cfg.episode.scene, args)
    apply_interaction_arguments(cfg.episode.interaction, args)
    return cfg.validate()


def run(args: argparse.Namespace) -> int:
    from cablesim.policies.explore import explore

    cfg = config_from_args(args)
    flow_kwargs = None
    if cfg.flow == "raft":
        from cablesim.errors import InputError
        from cablesim.perception.raft import load_raft

        if args.raft_checkpoint is None:
            raise InputError("--flow raft needs --raft-checkpoint (no weights are downloaded)")
        load_raft(args.raft_checkpoint)  # file, torch and weights checked before the scene
        flow_kwargs = {"checkpoint": args.raft_checkpoint}
    args.out = prepare_output_dir(args.out)
    check_settle_cache(cfg.episode.scene)
    if cfg.progress:
        print(f"[explore] config:\n{cfg}", flush=True)
    res = explore(cfg, out=args.out, flow_kwargs=flow_kwargs)
    print(res.summary())
    print(f"[explore] wrote {args.out} (metrics.json, pictures, video)")
    return 0 if res.successes else 1
