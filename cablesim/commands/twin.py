"""Try the real-robot path with no hardware: a digital twin.

Starts the franka-sim server on 127.0.0.1 (from its own environment, see README "Real robot"),
connects FrankyPanda to it with the real protocol, builds a twin of the seed's scene that
follows the robot's measured joints and gripper in real time, feeds the twin's RGB-D frames live
into a librealsense software device read by RealSenseCamera, and runs one interaction with the
real runner (wall-clock StreamClock), then DIS + motion correlation and the grasp sampler's next
proposal; the twin's ground truth scores it.  The same seed in pure simulation is run beside it
unless --no-compare.

Files in --out: metrics.json (frames kept, follow gain, frame/pose skew, twin lag, F0.4,
next-proposal grade; the same for pure simulation), twin_votes.png (target | votes | errors).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cablesim.commands._args import (
    EPISODE_FLAGS,
    add_interaction_arguments,
    add_scene_arguments,
    build_config,
    prepare_output_dir,
    show_config,
)
from cablesim.progress import Progress, quiet
from cablesim.sim.config import EpisodeConfig
from cablesim.twin import FrankaSimServer
from cablesim.twin.episode import sim_episode, twin_episode
from cablesim.viz import errors_tile, overlay_votes, panel, write_png


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p, "scene and episode seed")
    p.add_argument("--out", type=Path, default=None, help="output directory (required)")
    p.add_argument("--hose", type=int, default=None, help="hose of interest (default: drawn)")
    add_interaction_arguments(p)
    p.add_argument("--no-server", action="store_true", help="use a franka-sim already running")
    p.add_argument("--no-compare", action="store_true", help="skip pure simulation of the seed")


def run(args: argparse.Namespace) -> int:

    cfg = build_config(EpisodeConfig, args, EPISODE_FLAGS)
    if args.show_config:
        return show_config(cfg)
    out: Path = prepare_output_dir(args.out)
    say = quiet if args.quiet else Progress("twin")
    if args.no_server:
        ep = twin_episode(cfg, say=say, monitor_every=5.0 if not args.quiet else 0.0)
    else:
        with FrankaSimServer(
            object_width=cfg.scene.hoses.max_diameter(), enforce_motion_limits=False
        ):
            ep = twin_episode(cfg, say=say, monitor_every=5.0 if not args.quiet else 0.0)
    print(ep.summary())
    metrics = {"twin": ep.metrics()}
    stream = ep.result.stream
    if stream is not None and ep.perceived.seg is not None:
        target = stream.target
        truth = target.truth.labels == ep.hose if target.truth is not None else None
        tiles = [target.rgb, overlay_votes(target.rgb, ep.perceived.seg.votes)]
        titles = ["twin target frame", "votes (DIS + correlation)"]
        if truth is not None:
            tiles.append(errors_tile(target.rgb, ep.perceived.seg.mask(1), truth))
            titles.append("union: TP green, FP red, FN blue")
        write_png(out / "twin_votes.png", panel(tiles, titles))
    if not args.no_compare:
        ref, perceived = sim_episode(cfg)
        metrics["simulation"] = {
            "interaction": ref.result.to_dict(),
            "follow_gain": [a.gain for a in ref.result.actions],
            "perception": perceived.to_dict(),
        }
        s = perceived.scores
        f04 = f"F0.4 {s['f0.4']:.3f}" if s else "no scores"
        print(f"pure simulation of seed {cfg.seed}: {ref.result.summary()}\n  perception: {f04}")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    print(f"[twin] wrote {out}")
    return 0 if ep.result.success else 1
