"""Benchmarks in simulation.  ``cablesim benchmark thesis`` runs the protocol of thesis chapters
5 and 6: motion segmentation, the no-gripper ablation and motion correlation on disjoint
validation and test scenes (thresholds tuned per beta on validation, reported on test), with
ground-truth and DIS flow, with and without the neighbour perturbation (tables 6.3-6.5); grasp
proposal grades and one against two grasps (tables 6.8, 6.9); one moving hose scored with the
MovingCables protocol (chapter 5).  The thesis's real-robot numbers stand beside ours in every
table.  --flows, --methods and --clip-flows take a user's flow back end or segmentation method
too (an installed plug-in's name, or MODULE:CLASS on the Python path; see docs/plugins.md):
its rows are named after it.

Files in --out: report.md, report.json, pr_curves.png, distributions.png, clip_taus.png,
config.json, results/<job>.json (one per scene; existing ones are skipped, so an interrupted run
resumes), results/timings.jsonl, movingcables/ (the clips).  Defaults are the full protocol
(see docs/cluster_plan.md for its cost); shrink the scene ranges for a quick look:

    cablesim benchmark thesis --validation 1000:1004 --test 2000:2006 --width 320 --height 240
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cablesim.commands._args import (
    add_cable_argument,
    add_config_arguments,
    add_pattern_argument,
    add_surface_argument,
    build_config,
    show_config,
)
from cablesim.jobs import parse_range
from cablesim.thesis import ThesisConfig, run_thesis

#: the flags that write a field of ThesisConfig as they are
FLAGS = {
    "width": "scene.width",
    "height": "scene.height",
    "hoses": "scene.hoses",
    "scene": "scene.surface",
    "cable": "scene.cable",
    "pattern": "scene.pattern",
    "periods": "scene.periods",
    "workers": "workers",
    "ray": "ray",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("which", choices=["thesis"], help="the benchmark to run")
    add_config_arguments(p)
    p.add_argument("--validation", help="validation seeds A:B (default 1000:1050)")
    p.add_argument("--test", help="test seeds A:B (default 2000:2200)")
    p.add_argument(
        "--flows",
        nargs="+",
        metavar="FLOW",
        help="flow back ends (default oracle dis): built-in names, installed plug-ins or "
        "MODULE:CLASS[,KEY=VALUE...]",
    )
    p.add_argument(
        "--methods",
        nargs="+",
        metavar="METHOD",
        help="segmentation methods (default segmentation ablation correlation); add your own "
        "by name or MODULE:CLASS[,KEY=VALUE...]",
    )
    p.add_argument(
        "--clip-flows",
        nargs="+",
        metavar="FLOW",
        help="flow back ends of chapter 5 (default farneback-movingcables farneback dis)",
    )
    p.add_argument(
        "--perturb", nargs="+", choices=["on", "off"], help="neighbour perturbation settings"
    )
    p.add_argument("--width", type=int)
    p.add_argument("--height", type=int)
    p.add_argument("--hoses", type=int)
    add_surface_argument(p)
    add_cable_argument(p)
    add_pattern_argument(p)
    p.add_argument("--periods", type=int, help="periods per action (K_p)")
    p.add_argument("--no-explore", action="store_true", help="skip tables 6.8/6.9")
    p.add_argument("--no-clips", action="store_true", help="skip chapter 5")
    p.add_argument("--clip-validation", help="seeds A:B of the validation clips")
    p.add_argument("--clip-test", help="seeds A:B of the test clips")
    p.add_argument("--workers", type=int, help="worker processes (default 2)")
    p.add_argument("--ray", help="run on Ray: auto, an address, or local")
    p.add_argument("--out", help="output directory (default runs/thesis)")
    p.add_argument(
        "--retry-failed", action="store_true", help="run the scenes that failed before again"
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="run nothing: rebuild the report from the result files in --out (merged runs)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar or lines")


def config_from_args(args: argparse.Namespace):
    """``ThesisConfig()`` or ``--config FILE``, then the flags given, then ``--set``."""

    values: dict[str, object] = {}
    for name in ("validation", "test", "clip_validation", "clip_test"):
        v = getattr(args, name)
        if v is not None:
            values[name] = parse_range(v, "--" + name.replace("_", "-"))
    if args.flows:
        values["flows"] = tuple(args.flows)
    if args.methods:
        values["methods"] = tuple(args.methods)
    if args.clip_flows:
        values["clip_flows"] = tuple(args.clip_flows)
    if args.perturb:
        values["perturb"] = tuple(dict.fromkeys(x == "on" for x in args.perturb))
    if args.no_explore:
        values["explore"] = False
    if args.no_clips:
        values["clips"] = False
    if args.out is not None:
        values["out"] = str(args.out)
    return build_config(ThesisConfig, args, FLAGS, values)


def run(args: argparse.Namespace) -> int:

    cfg = config_from_args(args)
    if args.show_config:
        return show_config(cfg)
    doc = run_thesis(
        cfg,
        progress=not args.quiet,
        retry_failed=args.retry_failed,
        report_only=args.report_only,
    )
    print((Path(cfg.out) / "report.md").read_text())
    # failed scenes are outcomes in the report; only a stage where nothing worked is an error
    return 1 if any(s["total"] and not s["ok"] for s in doc["jobs"].values()) else 0
