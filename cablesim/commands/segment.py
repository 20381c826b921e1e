"""Run perception on a recorded interaction and write what it labels.

SEQUENCE is any recorded interaction:
  - a cablesim recording (a folder with meta.json, written by `cablesim episode` or
    cablesim.recording);
  - a motion-correlation sequence of the published layout (a folder with
    actions_gripper.json, e.g. from the CMCor dataset; its annotation is found in
    motion_correlation_annotations/{validation,test}/<name> beside the sequences' folder);
  - a RealSense .db3 recording with --gripper-log (JSON lines, see
    cablesim.formats.gripper_log: a header, then {"t", "action", "position"} per sample).
The last image is the target frame; the labels are in it.

Files in --out:
  votes.png, votes.npy          actions voting for each target pixel (png: votes x 255 / actions)
  mask_union.png, mask_intersection.png, mask_action<a>.png   0/255
  overlay.png                   titled panels: target | votes | ground truth (when known)
                                | union against the truth (green right, red wrong, blue missed)
  maps.png                      |c0| and R^2 per action (correlation methods)
  scores.json                   precision, recall, IoU, F_beta (beta 1 ... 0.1) of the union and
                                intersection, when a ground-truth mask exists (in the sequence's
                                flow crop for the published layout, as published)
  summary.json                  input, layout, method, flow, thresholds, frames, timings
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.commands._args import add_grow_colour_argument
from cablesim.errors import InputError, RecordingError
from cablesim.formats import detect_layout
from cablesim.formats.gripper_log import read_realsense
from cablesim.formats.mcor import read_annotation, read_mcor
from cablesim.frames import Stream
from cablesim.jsonutil import json_default
from cablesim.perception.flow import FLOW_BACKENDS, check_flow, make_flow
from cablesim.perception.flow_region import FlowRegion
from cablesim.perception.methods import METHODS, check_method, make_method
from cablesim.perception.metrics import BETAS, score_mask
from cablesim.perception.pipeline import params_for_beta, segment_stream
from cablesim.perception.published import PUBLISHED_THRESHOLDS
from cablesim.perception.refine import DEFAULT_REFINE, GrowParams, RefineParams
from cablesim.perception.registry import parse_spec
from cablesim.recording import read_stream
from cablesim.viz import colour_map, hstack, label, overlay_votes, write_png


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", type=Path, help="recording folder or RealSense .db3 file")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument(
        "--flow",
        default="dis",
        metavar="FLOW",
        help=f"flow back end: {', '.join(FLOW_BACKENDS.builtins())}, an installed plug-in or "
        "MODULE:CLASS[,KEY=VALUE...] (default dis)",
    )
    p.add_argument(
        "--method",
        default="correlation",
        metavar="METHOD",
        help=f"perception method: {', '.join(METHODS)}, an installed plug-in or "
        "MODULE:CLASS[,KEY=VALUE...] (default correlation; 'published' = the published code)",
    )
    p.add_argument(
        "--beta",
        type=float,
        default=0.4,
        choices=sorted(PUBLISHED_THRESHOLDS, reverse=True),
        help="thresholds tuned for this F_beta (SPEC sections 7-8; default 0.4)",
    )
    p.add_argument("--checkpoint", type=Path, help="RAFT weights (needed by --flow raft)")
    p.add_argument("--gripper-log", type=Path, help="gripper log of a .db3 recording")
    p.add_argument(
        "--time-offset", type=float, default=0.0, help="seconds added to the gripper log's times"
    )
    p.add_argument(
        "--annotations",
        default="auto",
        help="annotations root of a published-layout sequence ('none' for none; default: found)",
    )
    p.add_argument("--truth", type=Path, help="ground-truth mask of the target frame (> 0)")
    p.add_argument(
        "--crop",
        type=int,
        nargs=4,
        metavar=("X", "Y", "W", "H"),
        help="compute flow on this crop (default: the sequence's own, if any)",
    )
    p.add_argument("--scale", type=float, help="scale the crop by this factor for the flow")
    add_grow_colour_argument(p, "correlation, segmentation, ablation; ")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def _read(args: argparse.Namespace) -> tuple[Stream, str, np.ndarray | None]:
    """(stream, layout, given start segment or None)."""

    layout = detect_layout(args.sequence)
    segment = None
    if layout == "mcor":
        ann = None if args.annotations == "none" else args.annotations
        seq = read_mcor(args.sequence, ann)
        stream, segment = seq.stream, seq.segment
    elif layout == "cablesim-recording":
        stream = read_stream(args.sequence)
        px = stream.meta.get("segment_px")
        if px:
            segment = np.zeros(stream.frames[0].shape, bool)
            uv = np.asarray(px, int).reshape(-1, 2)
            segment[uv[:, 1], uv[:, 0]] = True
    elif layout == "realsense":
        if args.gripper_log is None:
            raise InputError("a RealSense .db3 recording needs --gripper-log")

        stream = read_realsense(args.sequence, args.gripper_log, args.time_offset)
    else:
        raise RecordingError(
            f"{args.sequence}: a MovingCables folder has no gripper; "
            "use cablesim.formats.movingcables.evaluate_clip for its flow evaluation"
        )
    return stream, layout, segment


def _truth(args: argparse.Namespace, stream: Stream) -> np.ndarray | None:
    if args.truth is not None:
        m = read_annotation(args.truth)
        if m.shape != stream.target.shape:
            raise InputError(f"{args.truth}: size {m.shape}, the target is {stream.target.shape}")
        return m
    t = stream.target.truth
    if t is None or t.grasped_hose is None:
        return None
    return t.labels == t.grasped_hose


def _flow(args: argparse.Namespace, stream: Stream) -> Any:
    spec = parse_spec(args.flow, "flow back end")
    if spec.target == "raft" and "checkpoint" not in spec.params:
        if args.checkpoint is None:
            raise InputError("--flow raft needs --checkpoint (RAFT weights; nothing is downloaded)")
        return make_flow(args.flow, checkpoint=str(args.checkpoint))
    if spec.target == "oracle":
        lacking = [
            i
            for i, f in enumerate(stream.frames[:-1])
            if f.action >= 0 and (f.truth is None or f.truth.flow_to_target is None)
        ]
        if lacking:
            raise InputError(
                f"--flow oracle needs ground-truth flow, which frame {lacking[0]} (and "
                f"{len(lacking) - 1} more) lacks: only simulated recordings have it, on every "
                "frame where recorded with --set interaction.capture.truth_every=1 (the default "
                "labels every 8th)"
            )
    return args.flow


def _region(args: argparse.Namespace) -> Any:
    if args.crop is None and args.scale is None:
        return "auto"

    crop = args.crop
    return FlowRegion(
        None if crop is None else tuple(crop[:2]),
        None if crop is None else tuple(crop[2:]),
        args.scale,
    )


def _refine(args: argparse.Namespace) -> RefineParams | None:
    """The default remedies, with the colour growth of ``--grow-colour``."""
    if args.grow_colour is None:
        return None
    if not make_method(args.method).refine_by_default:
        raise InputError(
            f"--grow-colour applies to correlation, segmentation and ablation, not {args.method!r}"
        )
    return dataclasses.replace(DEFAULT_REFINE, grow=GrowParams(colour=args.grow_colour))


def _pictures(out: Path, stream: Stream, seg: Any, truth: np.ndarray | None, title: str) -> None:
    rgb = stream.target.rgb
    n = max(len(seg.masks), 1)
    tiles = [label(rgb, "target frame"), label(overlay_votes(rgb, seg.votes, n), title)]
    if truth is not None:
        tiles.append(label(np.where(truth[..., None], 255, rgb // 3).astype(np.uint8), "truth"))
        union = seg.mask(1)
        cmp = (rgb // 3).astype(np.uint8)
        cmp[union & truth] = (0, 255, 0)
        cmp[union & ~truth] = (255, 0, 0)
        cmp[~union & truth] = (0, 0, 255)
        tiles.append(label(cmp, "union: green right, red wrong, blue missed"))
    write_png(out / "overlay.png", hstack(tiles))
    if seg.c0:
        rows = []
        for a in sorted(seg.c0):
            c0 = label(colour_map(np.abs(seg.c0[a]), 0.0, 1.0), f"action {a}: |c0| (0..1)")
            r2 = label(colour_map(seg.r2[a], 0.0, 1.0), f"action {a}: R^2 (0..1)")
            rows.append(hstack([c0, r2]))
        write_png(out / "maps.png", np.concatenate(rows, axis=0))


def _params_dict(params: Any) -> Any:
    """A method's thresholds for summary.json (a dataclass's fields)."""
    if params is None or not dataclasses.is_dataclass(params):
        return None if params is None else repr(params)
    return vars(params)


def run(args: argparse.Namespace) -> int:
    t0 = time.time()
    out: Path = args.out
    check_flow(args.flow)  # a bad name fails before the sequence is read
    check_method(args.method)
    stream, layout, segment = _read(args)
    truth = _truth(args, stream)
    flow = _flow(args, stream)
    params = params_for_beta(args.method, args.beta)
    refine = _refine(args)
    if not args.quiet:
        print(f"[segment] {layout} {args.sequence}: {len(stream)} frames, actions {stream.actions}")
    t1 = time.time()
    seg = segment_stream(stream, args.method, flow, params, region=_region(args), refine=refine)
    t2 = time.time()
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "votes.npy", seg.votes)
    n = max(len(seg.masks), 1)
    cv2.imwrite(str(out / "votes.png"), (seg.votes.astype(np.int32) * 255 // n).astype(np.uint8))
    for name, m in [("union", seg.mask(1)), ("intersection", seg.mask("intersection"))]:
        cv2.imwrite(str(out / f"mask_{name}.png"), m.astype(np.uint8) * 255)
    for a, m in seg.masks.items():
        cv2.imwrite(str(out / f"mask_action{a}.png"), m.astype(np.uint8) * 255)
    title = f"votes: {args.method}, {args.flow} flow, beta {args.beta:g}"
    _pictures(out, stream, seg, truth, title)
    crop = None
    if stream.meta.get("crop_origin") is not None and stream.meta.get("crop_size") is not None:
        crop = [*stream.meta["crop_origin"], *stream.meta["crop_size"]]
    scores = None
    if truth is not None:
        scores = {
            "counted_in": "crop" if crop else "image",
            "crop": crop,
            "union": score_mask(seg.mask(1), truth, BETAS, crop).to_dict(),
            "intersection": score_mask(seg.mask("intersection"), truth, BETAS, crop).to_dict(),
        }
        (out / "scores.json").write_text(json.dumps(scores, indent=2, default=json_default))
    summary = {
        "sequence": str(args.sequence),
        "layout": layout,
        "frames": len(stream),
        "actions": seg.stats.actions,
        "kept_samples": seg.stats.n_samples,
        "method": args.method,
        "flow": seg.stats.flow,
        "beta": args.beta,
        "params": _params_dict(params),
        "published": seg.stats.published_meta or None,
        "refine": seg.stats.refine,
        "given_segment_px": None if segment is None else int(segment.sum()),
        "voted_px": {"union": int(seg.mask(1).sum()), "intersection": int(seg.mask(n).sum())},
        "truth": truth is not None,
        "timing_s": {"read": t1 - t0, "perception": t2 - t1, "total": time.time() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=json_default))
    if not args.quiet:
        if scores is not None:
            u = scores["union"]
            print(
                f"[segment] union: P {u['precision']:.3f} R {u['recall']:.3f} "
                f"F0.4 {u['f0.4']:.3f} IoU {u['iou']:.3f}"
            )
        print(f"[segment] wrote {out} ({t2 - t1:.1f} s perception)")
    return 0
