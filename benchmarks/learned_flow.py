"""The learned flow beside DIS and Farneback on held-out simulated clips, and its speed.

    .venv/bin/python -m benchmarks.learned_flow --data SPLIT [SPLIT ...] [--flow SPEC ...]
        [--weights FILE] [--truth normal_flow flow] [--validation] [--write]

``SPLIT`` is a MovingCables split folder of simulated test clips, made with seeds that neither
training nor validation used, e.g.::

    cablesim dataset movingcables --scenes 102000:102006 --split test --out runs/lf-board
    cablesim dataset movingcables --scenes 102500:102506 --split test --scene table \\
        --out runs/lf-table

``--validation`` scores validation clips (those a training run validated on) to choose a
setting, titled so, and ``--write`` then writes ``learned_flow_validation.md``.

Each back end is scored with the published MovingCables protocol
(:func:`cablesim.formats.movingcables.evaluate_clip`: flow from each image to the first, the
arm -- the clip's "stick" -- never moving, moving where |flow| > 1 px, truth the exact normal
flow as published and the exact flow), pooled per split folder: IoU, precision, recall, EPE
over all pixels and over the pixels whose true flow exceeds 1 px; per clip (with the arm's
largest share of the view) and pooled per kind of the cable that moves (from the clips' job
records, :func:`clip_kinds`).  The speed section times
one flow at 552x408 (the thesis's crop, scaled 1.5x) on one thread: thread CPU time, median of
``--repeats`` after a warm-up.

Writes ``benchmarks/results/learned_flow.md`` with ``--write``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.dataset.generate import scene_from
from cablesim.formats.movingcables import (
    arm_share,
    evaluate_clip,
    list_clips,
    read_stick_masks,
)
from cablesim.jobs import read_result
from cablesim.perception.flow import FlowEstimator, make_flow
from cablesim.perception.metrics import movingcables_summary

DEFAULT_FLOWS = ("dis", "dis-medium", "farneback", "learned")


def with_weights(spec: str, weights: str | None) -> str:
    """``spec`` with ``weights=`` added when it names the learned flow without its own
    (``learned`` and ``learned,gate=null`` alike: each learned back end runs the given file)."""
    name, _, opts = spec.partition(",")
    if weights is None or name != "learned" or "weights=" in opts:
        return spec
    return f"learned,weights={weights}" + (f",{opts}" if opts else "")


def score(
    splits: list[Path],
    flow: str | FlowEstimator,
    truth: str,
    per_clip: dict | None = None,
    kinds: dict[str, str] | None = None,
    per_kind: dict | None = None,
) -> dict[str, dict[str, float]]:
    """Per split folder (and ``all``): the pooled MovingCables summary of ``flow``; each
    clip's own summary goes into ``per_clip`` (keyed ``folder/split/clip``) when given, and
    with ``kinds`` (clip -> the kind of the cable that moves in it, :func:`clip_kinds`) the
    summary pooled over each kind's clips into ``per_kind``."""
    est = make_flow(flow) if isinstance(flow, str) else flow
    out: dict[str, dict[str, float]] = {}
    every = []
    by_kind: dict[str, list] = {}
    for split in splits:
        frames = []
        for clip in list_clips(split):
            stats, _ = evaluate_clip(split, clip, est, 1.0, truth=truth)
            frames.extend(stats[1:])  # the first image is its own reference
            key = f"{_name(split)}/{clip}"
            if per_clip is not None:
                per_clip[key] = movingcables_summary(stats[1:]).to_dict()
            if kinds is not None:
                by_kind.setdefault(kinds[key], []).extend(stats[1:])
        every.extend(frames)
        out[_name(split)] = movingcables_summary(frames).to_dict()
    out["all"] = movingcables_summary(every).to_dict()
    if per_kind is not None:
        per_kind.update({k: movingcables_summary(v).to_dict() for k, v in sorted(by_kind.items())})
    return out


def clip_kinds(splits: list[Path]) -> dict[str, str] | None:
    """Per clip (``folder/split/clip``): the kind of the cable that moves in it, from the
    clip's job record (``folder/jobs/movingcables-SPLIT-CLIP-sSEED.json``, written by
    ``cablesim dataset movingcables``): the scene its seed and randomisation make
    (:func:`cablesim.dataset.generate.scene_from`), cable ``hose``.  None when a clip has no
    single readable record (clips made elsewhere)."""
    out = {}
    for split in splits:
        jobs = split.parent / "jobs"
        for clip in list_clips(split):
            found = sorted(jobs.glob(f"movingcables-{split.name}-{clip}-s*.json"))
            rec = read_result(found[0]) if len(found) == 1 else None
            if rec is None:
                return None
            scene = scene_from(rec["params"])
            out[f"{_name(split)}/{clip}"] = scene.hoses.kind_of(int(rec["result"]["hose"]))
    return out


def arm_shares(splits: list[Path]) -> dict[str, float]:
    """Per clip (``folder/split/clip``): the largest share of an image that the arm, the
    clip's stick, covers (the table's camera can see mostly arm)."""
    return {
        f"{_name(split)}/{clip}": arm_share(read_stick_masks(split, clip))
        for split in splits
        for clip in list_clips(split)
    }


def clip_table(
    per_clip: dict[str, dict[str, dict[str, float]]], shares: dict[str, float]
) -> list[str]:
    """Markdown rows: per clip, the arm's largest share and each back end's EPE > 1 px."""
    flows = list(per_clip)
    lines = [
        "| clip | arm's largest share of the image | "
        + " | ".join(f"{f} EPE > 1 px" for f in flows)
        + " |",
        "|---|---|" + "---|" * len(flows),
    ]
    for clip, share in shares.items():
        cells = [f"{per_clip[f][clip]['epe_gt_gt1']:.2f}" for f in flows]
        lines.append(f"| {clip} | {share:.2f} | " + " | ".join(cells) + " |")
    return lines


def kind_table(
    per_kind: dict[str, dict[str, dict[str, float]]], kinds: dict[str, str]
) -> list[str]:
    """Markdown rows: per kind of the moving cable and back end, the pooled IoU and EPE."""
    clips = Counter(kinds.values())
    lines = [
        "| kind of the moving cable | clips | back end | IoU | P | R | EPE > 1 px | images |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for kind in sorted(clips):
        for flow, by in per_kind.items():
            s = by[kind]
            lines.append(
                f"| {kind} | {clips[kind]} | {flow} | {s['iou']:.3f} | {s['precision']:.3f} | "
                f"{s['recall']:.3f} | {s['epe_gt_gt1']:.2f} | {s['images']} |"
            )
    return lines


def _name(split: Path) -> str:
    return f"{split.parent.name}/{split.name}"


def speed(flow: str | FlowEstimator, repeats: int = 7) -> float:
    """Median thread CPU seconds of one flow at 552x408 on one thread."""
    est = make_flow(flow) if isinstance(flow, str) else flow
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (408, 552, 3)).astype(np.float32), (0, 0), 2)
    a = np.clip((img - 127) * 3 + 127, 0, 255).astype(np.uint8)
    b = np.roll(a, (2, 3), axis=(0, 1))
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    torch_threads = _torch_threads(1)
    try:
        est.compute(a, b)
        times = []
        for _ in range(repeats):
            t0 = time.thread_time()
            est.compute(a, b)
            times.append(time.thread_time() - t0)
    finally:
        cv2.setNumThreads(threads)
        _torch_threads(torch_threads)
    return statistics.median(times)


def _torch_threads(n: int) -> int | None:
    try:
        import torch  # lazy: optional heavy package
    except ImportError:
        return None
    old = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(n)
    return old


def report(
    results: dict[str, dict[str, dict[str, dict[str, float]]]],
    speeds: dict[str, float],
    splits: list[Path],
    weights: str,
    what: str = "held-out simulated clips",
    per_clip: dict[str, dict[str, dict[str, float]]] | None = None,
    per_kind: dict[str, dict[str, dict[str, float]]] | None = None,
    kinds: dict[str, str] | None = None,
) -> str:
    lines = [
        f"# The learned flow on {what} (`python -m benchmarks.learned_flow`)",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}",
        f"- weights: `{weights}`",
        "- clips: " + ", ".join(f"`{_name(s)}` ({len(list_clips(s))} clips)" for s in splits),
        "- MovingCables protocol: flow from each image to the first, the arm never moving, "
        "moving where |flow| > 1 px; IoU, P, R pooled as published (mean over images); "
        "EPE > 1 px: over the pixels whose true flow exceeds 1 px",
        "",
    ]
    for truth, by_flow in results.items():
        lines += [
            f"## Truth: exact {truth.replace('_', ' ')}",
            "",
            "| clips | back end | IoU | P | R | EPE all | EPE > 1 px | images |",
            "|---|---|---|---|---|---|---|---|",
        ]
        names = list(next(iter(by_flow.values())))
        for where in names:
            for flow, res in by_flow.items():
                s = res[where]
                lines.append(
                    f"| {where} | {flow} | {s['iou']:.3f} | {s['precision']:.3f} | "
                    f"{s['recall']:.3f} | {s['epe']:.3f} | {s['epe_gt_gt1']:.2f} | "
                    f"{s['images']} |"
                )
        lines.append("")
    if per_clip:
        lines += [
            "## Per clip: EPE > 1 px against the exact normal flow",
            "",
            "The arm (the clip's stick) is never scored; where it fills most of the view few "
            "hose pixels are left, and they lie beside its large motion.",
            "",
            *clip_table(per_clip, arm_shares(splits)),
            "",
        ]
    if per_kind and kinds:
        lines += [
            "## Per cable kind: the clips pooled by the kind of the cable that moves",
            "",
            "Against the exact normal flow. Each clip moves one cable; the scene draws every "
            "cable's kind (and pattern) from its seed, so the other cables in view are of any "
            "kind.",
            "",
            *kind_table(per_kind, kinds),
            "",
        ]
    if speeds:
        lines += [
            "## Speed: one flow at 552x408, one thread (median thread CPU time)",
            "",
            "| back end | ms |",
            "|---|---|",
        ]
        lines += [f"| {k} | {1000 * v:.1f} |" for k, v in speeds.items()]
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, nargs="+", required=True, help="test split folders")
    ap.add_argument("--flow", nargs="+", default=list(DEFAULT_FLOWS), help="flow back ends")
    ap.add_argument("--weights", default=None, help="weights for 'learned' (default: shipped)")
    ap.add_argument("--speed", nargs="*", default=None, help="back ends to time (default: --flow)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument(
        "--truth",
        nargs="+",
        default=["normal_flow", "flow"],
        choices=["normal_flow", "flow"],
        help="ground truths to score against (default both)",
    )
    ap.add_argument(
        "--validation",
        action="store_true",
        help="the clips are validation clips (choosing a setting): titled so, and --write "
        "writes benchmarks/results/learned_flow_validation.md",
    )
    ap.add_argument("--write", action="store_true", help="write benchmarks/results/learned_flow.md")
    ap.add_argument("--out", type=Path, default=None, help="with --write: write this file instead")
    args = ap.parse_args(argv)
    for s in args.data:
        list_clips(s)  # a bad folder stops here
    # rows are named as given; every learned back end runs --weights
    flows = {f: with_weights(f, args.weights) for f in args.flow}
    results: dict[str, dict[str, dict[str, dict[str, float]]]] = {}
    per_clip: dict[str, dict[str, dict[str, float]]] = {}
    per_kind: dict[str, dict[str, dict[str, float]]] = {}
    kinds = clip_kinds(args.data)
    if kinds is None:
        print("no job records beside the clips: no table per cable kind", flush=True)
    for truth in args.truth:
        results[truth] = {}
        for f, spec in flows.items():
            normal = truth == "normal_flow"
            clips = per_clip.setdefault(f, {}) if normal else None
            by_kind = per_kind.setdefault(f, {}) if normal and kinds else None
            results[truth][f] = score(args.data, spec, truth, clips, kinds, by_kind)
            a = results[truth][f]["all"]
            print(
                f"{truth:11s} {f:40s} IoU {a['iou']:.3f} P {a['precision']:.3f} "
                f"R {a['recall']:.3f} EPE>1 {a['epe_gt_gt1']:.2f}",
                flush=True,
            )
    timed = args.speed if args.speed is not None else list(flows)
    speeds = {f: speed(with_weights(f, args.weights), args.repeats) for f in timed}
    for f, v in speeds.items():
        print(f"speed {f}: {1000 * v:.1f} ms")
    what = "simulated validation clips" if args.validation else "held-out simulated clips"
    text = report(
        results,
        speeds,
        args.data,
        args.weights or "as each row names it; rows without weights= run the shipped default",
        what,
        per_clip,
        per_kind,
        kinds,
    )
    if args.write:
        name = "learned_flow_validation.md" if args.validation else "learned_flow.md"
        write_results(args.out or RESULTS / name, text)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
