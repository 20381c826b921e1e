"""Explore one hose: a start segment, then grasp, two periodic actions, motion correlation on
the stream, and the grasp sampler's next reachable grasp on the same hose, up to a budget of
grasps; the votes of all grasps are merged in the latest target frame.

In simulation (``--robot sim``, the default) the start segment is the seeded stand-in for a
person's click and everything is scored against ground truth.  On the real robot
(``--robot franky --robot-host H --camera realsense[:SERIAL] --calibration calib.json
--start mask.png``, or ``--start-point U,V --start-angle DEG`` instead of a mask) the same
policy, perception and sampler run on the camera's stream; every interaction is recorded as it
happens to ``--out/recordings``; ``--dry-run`` plans every motion and reachability check of the
first interaction and shows it (``plan.png``, ``plan.json``) without moving; Ctrl-C stops the
robot and keeps everything recorded.  The workspace box and speed caps come from
``--workspace`` and ``--max-speed``.

Files in --out: start.png, interaction{k}_votes.png (target | votes in green | ground truth |
aimed segment), interaction{k}_flow.png (estimated | ground-truth flow), interaction{k}_maps.png
(|c0| and R^2 per action), merged.png, episode.mp4 (or episode.gif), metrics.json (precision,
recall, F_0.4, IoU per interaction and merged where ground truth exists; the config).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import cv2
import numpy as np

from cablesim.commands._args import (
    EPISODE_FLAGS,
    add_grow_colour_argument,
    add_interaction_arguments,
    add_scene_arguments,
    below,
    build_config,
    check_settle_cache,
    prepare_output_dir,
    show_config,
    write_config,
)
from cablesim.errors import InputError
from cablesim.perception.flow import FLOW_BACKENDS
from cablesim.perception.geometry import line_segment_mask
from cablesim.perception.methods import CURRENT_METHODS
from cablesim.perception.raft import load_raft
from cablesim.perception.registry import parse_spec
from cablesim.policies.config import MERGES, STRATEGIES, ExploreConfig
from cablesim.policies.explore import Exploration, explore
from cablesim.policies.report import ExplorationWriter, overlay_mask, write_png
from cablesim.progress import Progress
from cablesim.real import RealConfig, RealSession
from cablesim.robot.guard import SafetyConfig


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p, "scene and exploration seed")
    p.add_argument("--out", type=Path, default=None, help="output directory (required)")
    p.add_argument("--hose", type=int, default=None, help="hose of interest (default: drawn)")
    p.add_argument("--grasps", type=int, default=None, help="budget of successful grasps (3)")
    p.add_argument(
        "--strategy", choices=STRATEGIES, default=None, help="next-grasp policy (sampler)"
    )
    p.add_argument(
        "--method",
        default=None,
        metavar="METHOD",
        help=f"segmentation method: {', '.join(CURRENT_METHODS)}, an installed plug-in or "
        "MODULE:CLASS[,KEY=VALUE...] (default: correlation; segmentation for --strategy push)",
    )
    p.add_argument(
        "--flow",
        default=None,
        metavar="FLOW",
        help=f"optical flow back end: {', '.join(FLOW_BACKENDS.builtins())}, an installed "
        "plug-in or MODULE:CLASS[,KEY=VALUE...] (default dis)",
    )
    p.add_argument("--raft-checkpoint", type=Path, default=None, help="weights for --flow raft")
    p.add_argument(
        "--merge",
        choices=MERGES,
        default=None,
        help="vote carrying between targets: dis (default), oracle (ground truth), none",
    )
    add_grow_colour_argument(p)
    p.add_argument("--perturb", action="store_true", help="disturb neighbouring hoses in actions")
    p.add_argument("--record", action="store_true", help="record every interaction (sim)")
    add_interaction_arguments(p)
    real = p.add_argument_group("real robot")
    real.add_argument("--robot", choices=("sim", "franky"), default="sim", help="sim (default)")
    real.add_argument("--robot-host", default=None, help="the robot's FCI address")
    real.add_argument(
        "--camera", default="realsense", help="realsense | realsense:SERIAL | realsense:FILE.db3"
    )
    real.add_argument("--calibration", type=Path, default=None, help="cablesim calibrate's file")
    real.add_argument("--start", type=Path, default=None, help="start segment mask (PNG, >0)")
    real.add_argument("--start-point", default=None, help="start segment centre U,V (pixels)")
    real.add_argument(
        "--start-angle", type=float, default=0.0, help="hose direction at --start-point (deg)"
    )
    real.add_argument("--dry-run", action="store_true", help="plan and check, move nothing")
    real.add_argument(
        "--workspace", default=None, help="TCP box X0,Y0,Z0,X1,Y1,Z1 (m, world frame)"
    )
    real.add_argument("--max-speed", type=float, default=None, help="TCP speed cap (m/s)")
    real.add_argument(
        "--no-realtime", action="store_true", help="no realtime kernel (simulated robot only)"
    )


#: explore's flags -> the field each writes (the session's under ``episode.``).
EXPLORE_FLAGS = {
    **below("episode", EPISODE_FLAGS),
    **{name: name for name in ("strategy", "method", "flow", "merge", "grow_colour", "grasps")},
}


def config_from_args(args: argparse.Namespace) -> ExploreConfig:
    """``ExploreConfig()`` or ``--config FILE``, then the flags given, then ``--set``."""
    values: dict[str, object] = {"progress": not args.quiet}
    if args.grasps is not None:
        values["max_attempts"] = max(2 * args.grasps, args.grasps + 2)
    if args.strategy is not None:  # the interaction kind of the strategy (ExploreConfig)
        values["episode.interaction.kind"] = "push" if args.strategy == "push" else "grasp"
    if args.perturb:
        values["episode.perturb.enabled"] = True
    return build_config(ExploreConfig, args, EXPLORE_FLAGS, values, section="explore")


def _flow_kwargs(cfg: ExploreConfig, args: argparse.Namespace) -> dict | None:
    spec = parse_spec(cfg.flow, "flow back end")
    if spec.target != "raft" or ("checkpoint" in spec.params and args.raft_checkpoint is None):
        return None
    if args.raft_checkpoint is None:
        raise InputError("--flow raft needs --raft-checkpoint (no weights are downloaded)")

    load_raft(args.raft_checkpoint)  # file, torch and weights checked before anything is built
    return {"checkpoint": args.raft_checkpoint}


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    if args.show_config:
        return show_config(cfg)
    flow_kwargs = _flow_kwargs(cfg, args)
    args.out = prepare_output_dir(args.out)
    if args.robot != "sim":
        return run_real(args, cfg, flow_kwargs)

    cfg = check_settle_cache(cfg, "episode.scene")
    write_config(args.out, cfg)
    record_to = args.out / "recordings" if args.record else None
    res = explore(cfg, out=args.out, flow_kwargs=flow_kwargs, record_to=record_to)
    print(res.summary())
    print(f"[explore] wrote {args.out} (metrics.json, pictures, video)")
    return 0 if res.successes else 1


# ---------------------------------------------------------------------- the real robot
def safety_from_args(args: argparse.Namespace) -> SafetyConfig:
    safety = SafetyConfig()
    if args.workspace is not None:
        box = _floats(args.workspace, 6, "--workspace")
        safety.workspace_min, safety.workspace_max = tuple(box[:3]), tuple(box[3:])
    if args.max_speed is not None:
        safety.max_speed = args.max_speed
    return safety.validate()


def _floats(text: str, n: int, name: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise InputError(f"{name} takes {n} comma-separated numbers, got {text!r}")
    return values


def start_segment(args: argparse.Namespace, image) -> np.ndarray:
    """The start segment in ``image``: a mask file, or a point and an angle."""

    h, w = image.depth.shape
    if args.start is not None:
        mask = cv2.imread(str(args.start), cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise InputError(f"--start {args.start}: not a readable image")
        if mask.shape != (h, w):
            raise InputError(f"--start {args.start}: {mask.shape[::-1]} != the camera's {w}x{h}")
        return mask > 0
    if args.start_point is None:
        raise InputError("the real robot needs --start MASK.png or --start-point U,V")
    u, v = _floats(args.start_point, 2, "--start-point")
    if not (0 <= u < w and 0 <= v < h):
        raise InputError(f"--start-point {u},{v} is outside the {w}x{h} image")
    mask = line_segment_mask(
        image.depth, image.intrinsics, u, v, math.radians(args.start_angle), 0.04
    )
    if mask is None:
        raise InputError(f"--start-point {u},{v}: no valid depth there")
    return mask


def real_config(args: argparse.Namespace, cfg: ExploreConfig):

    if not args.robot_host:
        raise InputError("--robot franky needs --robot-host")
    if args.calibration is None:
        raise InputError("--robot franky needs --calibration FILE (cablesim calibrate)")
    interaction = cfg.episode.interaction
    # the frame stream carries the arm's mask (the arm model through the calibrated camera)
    interaction = interaction.replace(
        capture=dataclasses.replace(interaction.capture, arm_masks=True)
    )
    return RealConfig(
        robot_host=args.robot_host,
        camera=args.camera,
        calibration=str(args.calibration),
        realtime=not args.no_realtime,
        seed=cfg.seed,
        safety=safety_from_args(args),
        interaction=interaction,
    ).validate()


def run_real(args: argparse.Namespace, cfg: ExploreConfig, flow_kwargs: dict | None) -> int:

    real = real_config(args, cfg)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(
        json.dumps({"explore": cfg.to_dict(), "real": real.to_dict()}, indent=2) + "\n"
    )  # --config reads its "explore" part back
    say = Progress("explore", cfg.progress)
    session = RealSession.open(real, dry_run=args.dry_run)
    try:
        start = session.capture()
        mask = start_segment(args, start)
        if args.dry_run:
            return dry_run(session, start, mask, out)
        writer = ExplorationWriter(out, cfg)
        writer.start(start.rgb, mask)
        run_ = Exploration(
            session, cfg, mask, start, None, writer, say, flow_kwargs, record_to=out / "recordings"
        )
        try:
            result = run_.run()
        except KeyboardInterrupt:
            session.stop()
            result = run_.result
            result.stop_reason = "interrupted (Ctrl-C): the robot was stopped"
            writer.finish(result)
            writer.close()
            print(f"[explore] interrupted: the robot was stopped; kept everything in {out}")
            return 130
        writer.finish(result)
        writer.close()
        print(result.summary())
        print(f"[explore] wrote {out} (recordings, metrics.json, pictures, video)")
        return 0 if result.successes else 1
    finally:
        session.close()


def dry_run(session, start, mask: np.ndarray, out: Path) -> int:
    """Plan the first interaction on the virtual robot; write plan.json and plan.png."""

    result = session.interact(mask)
    log = session.robot.log
    refused = [m for m in log if not m.ok]
    doc = {
        "feasible": result.success,
        "reason": result.reason,
        "grasp_world": None if result.grasp is None else result.grasp.position.tolist(),
        "motions": [
            {"kind": m.kind, "ok": m.ok, "reason": m.reason, "target": m.target} for m in log
        ],
    }
    (out / "plan.json").write_text(json.dumps(doc, indent=2) + "\n")
    img = overlay_mask(start.rgb, mask, (255, 0, 255))
    T_camera_world = np.linalg.inv(session.T_world_camera)
    K = start.intrinsics
    for m in log:
        if m.kind != "move_to":
            continue
        p = T_camera_world[:3, :3] @ np.asarray(m.target) + T_camera_world[:3, 3]
        if p[2] <= 0:
            continue
        uv = K.project(p[None])[0]
        colour = (0, 255, 0) if m.ok else (255, 0, 0)
        cv2.circle(img, (int(round(uv[0])), int(round(uv[1]))), 4, colour, 2)
    write_png(out / "plan.png", img)
    for m in log:
        print(f"[dry run] {m}")
    verdict = "feasible" if result.success else f"NOT feasible: {result.reason}"
    print(f"[dry run] {len(log)} motions planned, {len(refused)} refused; {verdict}")
    print(f"[dry run] wrote {out / 'plan.json'} and {out / 'plan.png'}; nothing moved")
    return 0 if result.success else 1
