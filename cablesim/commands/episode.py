"""Run one seeded interaction: build the scene, pick a random graspable start segment of a hose
(the stand-in for a person clicking on it), grasp, two periodic actions (along and across the
hose), release, retreat out of view, settle, target frame.

Files in --out:
  recording/         the frame stream (see cablesim.recording; replay with
                     cablesim.camera.replay.ReplayCamera); labels and ground-truth flow on
                     every 8th kept frame and the target (every frame with
                     --set interaction.capture.truth_every=1, e.g. to score flows later)
  contact_sheet.png  start image with the segment, a few action frames, the target frame and
                     its ground-truth grasped-hose mask (titled tiles)
  start.png, target.png  the camera's images
  target_labels.png  the target frame's labels with a key
  summary.json       config (with the scene draw that served), named outcome, scene draws,
                     result (gain per action, other hoses' displacement, frames kept, grasp
                     retries, timings); also printed.  A seed no scene draw of which serves
                     (scene_unsettled, no_graspable_segment) writes only this file.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from cablesim.commands._args import (
    EPISODE_FLAGS,
    add_interaction_arguments,
    add_scene_arguments,
    build_config,
    check_settle_cache,
    output_path,
    prepare_output_dir,
    show_config,
    write_config,
)
from cablesim.frames import LABEL_ROBOT, Stream
from cablesim.recording import RecordingWriter
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.session import simulate_episode
from cablesim.viz import (
    SEGMENT_COLOUR,
    colour_labels,
    hstack,
    labels_legend,
    overlay_mask,
    panel,
    write_png,
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p, "episode and scene seed")
    p.add_argument("--hose", type=int, default=None, help="hose to grasp (default: drawn)")
    p.add_argument("--out", type=output_path, default=None, help="output directory (required)")
    add_interaction_arguments(p)
    p.add_argument("--push", action="store_true", help="push (poke) instead of grasping")
    p.add_argument("--overwrite", action="store_true", help="replace an existing recording")


def config_from_args(args: argparse.Namespace) -> EpisodeConfig:
    """``EpisodeConfig()`` or ``--config FILE``, then the flags given, then ``--set``."""
    values = {"interaction.kind": "push"} if args.push else {}
    return build_config(EpisodeConfig, args, EPISODE_FLAGS, values)


def contact_sheet(
    start_rgb: np.ndarray, segment: np.ndarray, stream: Stream, n_action_frames: int = 4
) -> np.ndarray:
    """One titled row: start image (segment in magenta), a few action frames, target, target
    mask (grasped hose white, robot red)."""
    start = overlay_mask(start_rgb, segment, SEGMENT_COLOUR, dim=1.0)
    frames = [f for f in stream.frames if not f.is_target]
    pick = np.linspace(0, len(frames) - 1, min(n_action_frames, len(frames))).round().astype(int)
    tiles = [start] + [frames[i].rgb for i in pick] + [stream.target.rgb]
    titles = ["start, segment (magenta)"]
    titles += [f"action {frames[i].action}, t {frames[i].timestamp:.2f} s" for i in pick]
    titles.append("target frame")
    truth = stream.target.truth
    if truth is not None and truth.grasped_hose is not None:
        mask = np.zeros_like(start)
        mask[truth.labels == truth.grasped_hose] = (255, 255, 255)
        mask[truth.labels == LABEL_ROBOT] = (255, 0, 0)
        tiles.append(mask)
        titles.append(f"target: hose {truth.grasped_hose} (white), robot (red)")
    return panel(tiles, titles)


def run(args: argparse.Namespace) -> int:

    cfg = config_from_args(args)
    if args.show_config:
        return show_config(cfg)
    out = prepare_output_dir(args.out)
    RecordingWriter.check_target(out / "recording", args.overwrite, "--overwrite")
    cfg = check_settle_cache(cfg, "scene")
    write_config(out, cfg)
    if not args.quiet:
        print(f"[episode] seed {cfg.seed}: config in {out / 'config.json'}")
    ep = simulate_episode(
        cfg, record_to=out / "recording", overwrite=args.overwrite, progress=not args.quiet
    )
    try:
        res = ep.result
        summary = {
            "config": (ep.session.cfg if ep.session is not None else cfg).to_dict(),
            "outcome": res.outcome,
            "segment_px": None if ep.segment is None else int(ep.segment.mask.sum()),
            "scene_build_s": None if ep.session is None else ep.build_time,
            "scene_draws": ep.draws,
            "result": res.to_dict(),
        }
        if ep.start_image is not None:
            write_png(out / "start.png", ep.start_image.rgb)
        if res.success and res.stream is not None and ep.start_image is not None:
            start_img = ep.start_image.rgb
            sheet = contact_sheet(start_img, ep.segment.mask, res.stream)
            write_png(out / "contact_sheet.png", sheet)
            write_png(out / "target.png", res.stream.target.rgb)
            t = res.stream.target.truth
            if t is not None:
                h = t.labels.shape[0]
                labels = hstack([colour_labels(t.labels), labels_legend(t.labels, h)])
                write_png(out / "target_labels.png", panel([labels], ["target frame: labels"]))
            kept = len(res.stream) - 1
            summary["frames_kept"] = kept
            summary["gain"] = {a.label: a.gain for a in res.actions}
            summary["other_hoses_max_displacement_m"] = res.other_hose_displacement()
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        print(res.summary())
        print(f"[episode] wrote {out}")
        return 0 if res.success else 1
    finally:
        ep.close()
