"""Write simulated sequences in the published layouts, so existing tools read them.

  movingcables  MovingCables clips (SPEC section 8): --out DIR/<split>/{rgb_clips,
                flow_first_back,normal_flow_first_back,stick_masks}/NNNN/DDDDDDDD.png; one hose
                moved by the gripper, nothing else moving; flow of each image back to the first
                (16-bit PNG, instance ids in the third channel), normal flow, the arm as the
                stick; clip NNNN = seed - A + 1
  mcor          motion-correlation robot sequences: --out DIR/motion_correlation_buffers/<name>/
                (rgb, depth, arm masks, actions_gripper.json, the given segment) and
                DIR/motion_correlation_annotations/<split>/<name>/cable_mask_DDDDDDDD.png

Each scene of seeds A:B is randomised from its seed (background, hose count and colours,
lighting, camera pose), so a sequence is the same whatever the number of workers.  Finished
sequences are skipped (DIR/jobs/<sequence>.json); failures are listed by outcome at the end.
A run killed at any point and started again gives the same files as one that never stopped
(DIR/jobs/timings.jsonl aside); a second command writing into the same DIR at the same time is
refused (DIR/.lock); a full disk stops the run with an error naming the file.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cablesim.cables import CABLE_KINDS, PATTERNS
from cablesim.commands._args import (
    add_cable_argument,
    add_pattern_argument,
    add_surface_argument,
)
from cablesim.dataset.randomize import Randomization
from cablesim.episode.config import DIRECTION_NAMES
from cablesim.errors import ConfigError
from cablesim.files import OutputLock, write_text
from cablesim.jobs import Job, execute, load_results, parse_range, read_result, result_path
from cablesim.sim.config import MAX_HOSES

LAYOUTS = ("movingcables", "mcor")
#: A MovingCables clip's hand motion: one direction drawn per clip, an amplitude (m) uniform in
#: the range.  Pulling along the hose alone (the first datasets) moves almost no pixel across
#: the hose (the normal flow); pulling across moves the hose as the real clips' stick does.
CLIP_DIRECTIONS: tuple[str, ...] = ("along", "across")
CLIP_AMPLITUDE: tuple[float, float] = (0.02, 0.05)
#: the CRF range of ``--h264`` clips: 20 (hardly visible) to 34 (blocks on the board's grain);
#: libx264's default is 23
CLIP_H264_CRF: tuple[int, int] = (20, 34)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("layout", choices=LAYOUTS)
    p.add_argument("--scenes", required=True, help="seeds A:B (A included, B not)")
    p.add_argument("--out", type=Path, required=True, help="dataset root")
    p.add_argument("--split", choices=["train", "validation", "test"], default="test")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--ray", help="run on Ray: auto, an address, or local")
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    add_surface_argument(p)
    add_cable_argument(p, default="drawn per cable from every kind")
    add_pattern_argument(p, default="drawn per cable from every pattern", kind_choice=True)
    p.add_argument("--periods", type=int, default=None, help="periods per action (1 clip, 3 mcor)")
    p.add_argument(
        "--directions",
        nargs="+",
        default=list(CLIP_DIRECTIONS),
        metavar="DIR",
        help="movingcables: the hand's directions, one drawn per clip (default: along across)",
    )
    p.add_argument(
        "--amplitude",
        nargs=2,
        type=float,
        default=list(CLIP_AMPLITUDE),
        metavar=("LO", "HI"),
        help="movingcables: the hand's amplitude in metres, uniform in [LO, HI] per clip "
        "(default 0.02 0.05)",
    )
    p.add_argument(
        "--same-colour",
        type=float,
        default=0.0,
        metavar="SHARE",
        help="the share of scenes whose cables all wear one colour, a tangle of identical "
        "cables (default 0; each scene draws it from its seed)",
    )
    p.add_argument(
        "--hoses",
        nargs=2,
        type=int,
        default=None,
        metavar=("LO", "HI"),
        help=f"cables per scene, drawn in [LO, HI] (at most {MAX_HOSES}; default: the "
        "randomiser's 2 6)",
    )
    p.add_argument(
        "--h264",
        type=float,
        default=0.0,
        metavar="SHARE",
        help="movingcables: the share of clips whose images are seen through H.264, as the "
        f"published videos are, at a CRF drawn per clip in {CLIP_H264_CRF} (default 0)",
    )
    p.add_argument("--quiet", action="store_true")


def dataset_jobs(
    layout: str,
    first: int,
    stop: int,
    root: Path,
    split: str,
    scene: dict,
    periods: int | None = None,
    cable_kinds: tuple[str, ...] = tuple(CABLE_KINDS),
    cable_patterns: tuple[str, ...] = tuple(PATTERNS),
    directions: tuple[str, ...] = CLIP_DIRECTIONS,
    amplitude: tuple[float, float] = CLIP_AMPLITUDE,
    same_colour: float = 0.0,
    hoses: tuple[int, int] | None = None,
    h264: float = 0.0,
    h264_crf: tuple[int, int] = CLIP_H264_CRF,
) -> list:
    """One job per seed; each scene randomised, its cables' kinds drawn from ``cable_kinds``
    and their patterns from ``cable_patterns`` (empty: each cable its kind's), a share
    ``same_colour`` of the scenes with all cables of one colour, ``hoses`` (lo, hi) cables
    (None: the randomiser's range); a MovingCables clip's hand moves in one of ``directions``
    by an amplitude drawn in ``amplitude`` (m), and a share ``h264`` of the clips is seen
    through H.264 at a CRF drawn in ``h264_crf``."""

    if layout == "mcor" and split == "train":
        raise ConfigError("--split", "the motion-correlation annotations have validation and test")
    motion = check_motion(directions, amplitude) if layout == "movingcables" else None
    check_scenes(same_colour, hoses)
    compress = check_h264(h264, h264_crf) if layout == "movingcables" else None
    jobs = []
    for seed in range(first, stop):
        params = {
            "seed": seed,
            "split": split,
            "root": str(Path(root).resolve()),  # worker processes (Ray) have their own cwd
            "scene": scene,
            "randomize": {
                "cable_kinds": list(cable_kinds),
                "cable_patterns": list(cable_patterns),
                # (the jobs of datasets made without it as before)
                **({"same_colour": float(same_colour)} if same_colour else {}),
                # (the randomiser's own range as before, however it was asked for)
                **(
                    {"hoses": [int(v) for v in hoses]}
                    if hoses is not None and tuple(hoses) != Randomization.hoses
                    else {}
                ),
            },
            "periods": periods if periods is not None else (1 if layout == "movingcables" else 3),
        }
        if motion is not None:
            params["motion"] = motion
            if compress is not None:
                params["compress"] = compress
            params["clip"] = seed - first + 1
            key = f"movingcables-{split}-{seed - first + 1:04d}-s{seed:06d}"
        else:
            key = f"mcor-{split}-s{seed:06d}"
        jobs.append(Job(f"dataset.{layout}", key, params))
    return jobs


def check_scenes(
    same_colour: float,
    hoses: tuple[int, int] | None,
    names: tuple[str, str] = ("--same-colour", "--hoses"),
) -> None:
    """The project's error naming the bad option (``names``: what the same-colour share and the
    cable counts are called where they came from) unless ``same_colour`` is a share and
    ``hoses`` (lo, hi) a range of cable counts (None: the randomiser's)."""
    where_colour, where_hoses = names
    if not 0 <= float(same_colour) <= 1:
        raise ConfigError(where_colour, f"the share must be in [0, 1], got {same_colour}")
    if hoses is not None:
        lo, hi = (int(v) for v in hoses)
        if not 1 <= lo <= hi <= MAX_HOSES:
            raise ConfigError(where_hoses, f"need 1 <= LO <= HI <= {MAX_HOSES}, got {lo} {hi}")


def check_h264(
    share: float, crf: tuple[int, int], where: str = "--h264", where_crf: str | None = None
) -> dict | None:
    """The jobs' ``compress`` parameter (None for no H.264: the jobs of datasets made before
    it as they were), or the project's error naming ``where`` (``where_crf`` for the CRF
    range; default ``"<where> crf"``)."""
    share = float(share)
    if not 0 <= share <= 1:
        raise ConfigError(where, f"the share must be in [0, 1], got {share}")
    lo, hi = (int(v) for v in crf)
    if not 0 <= lo <= hi <= 51:
        raise ConfigError(where_crf or f"{where} crf", f"need 0 <= LO <= HI <= 51, got {lo} {hi}")
    return {"h264": share, "crf": [lo, hi]} if share > 0 else None


def check_motion(
    directions: tuple[str, ...],
    amplitude: tuple[float, float],
    names: tuple[str, str] = ("--directions", "--amplitude"),
) -> dict:
    """The jobs' ``motion`` parameter, or the project's error naming the bad option (``names``:
    what the directions and the amplitude are called where they came from)."""
    where_dirs, where_amp = names
    if not directions:
        raise ConfigError(where_dirs, "give at least one direction")
    for d in directions:
        if d not in DIRECTION_NAMES:
            raise ConfigError(where_dirs, f"unknown {d!r}; use {DIRECTION_NAMES}")
    lo, hi = (float(v) for v in amplitude)
    if not (0 < lo <= hi <= 0.2):
        raise ConfigError(where_amp, f"need 0 < LO <= HI <= 0.2 m, got {lo} {hi}")
    return {"directions": list(directions), "amplitude": [lo, hi]}


def check_finished(jobs: list, jobs_dir: Path) -> None:
    """Refuse to add to a dataset whose finished sequences were made with other settings
    (another hand motion, kinds, patterns, image size...): the folder would mix them silently.
    The dataset root may have moved since (``root`` is not compared)."""
    for job in jobs:
        path = result_path(jobs_dir, job)
        rec = read_result(path)
        if rec is None:
            continue
        old = {k: v for k, v in dict(rec.get("params", {})).items() if k != "root"}
        new = {k: v for k, v in json.loads(json.dumps(job.params)).items() if k != "root"}
        if old != new:
            diff = sorted(k for k in old.keys() | new.keys() if old.get(k) != new.get(k))
            raise ConfigError(
                str(path),
                f"was made with other settings ({', '.join(diff)}: {old.get(diff[0])!r} there, "
                f"{new.get(diff[0])!r} now); write to a new --out or give the same settings",
            )


def run(args: argparse.Namespace) -> int:

    a, b = parse_range(args.scenes)
    if args.layout == "movingcables" and b - a > 9999:
        raise ConfigError("--scenes", "a MovingCables split holds at most 9999 clips")
    scene = {"width": args.width, "height": args.height}
    if args.scene is not None and args.scene != "board":  # (the jobs of board datasets as before)
        scene["surface"] = args.scene
    kinds = (args.cable,) if args.cable is not None else tuple(CABLE_KINDS)
    patterns = {None: tuple(PATTERNS), "kind": ()}.get(args.pattern, (args.pattern,))
    jobs = dataset_jobs(
        args.layout,
        a,
        b,
        args.out,
        args.split,
        scene,
        args.periods,
        kinds,
        patterns,
        tuple(args.directions),
        tuple(args.amplitude),
        args.same_colour,
        tuple(args.hoses) if args.hoses is not None else None,
        args.h264,
    )
    with OutputLock(args.out):  # refused at once while another command writes there
        check_finished(jobs, args.out / "jobs")
        summary = execute(
            jobs,
            args.out / "jobs",
            args.workers,
            args.ray,
            not args.quiet,
            f"{args.layout} {args.split}",
        )
        recs = [r for r in load_results(args.out / "jobs", jobs) if r["status"] == "ok"]
        if recs:
            mb = [r["result"]["bytes"] / 1e6 for r in recs]
            imgs = [r["result"]["images"] for r in recs]
            print(
                f"{len(recs)} sequences: {sum(imgs)} images, {sum(mb):.1f} MB "
                f"({sum(mb) / len(recs):.1f} MB and {sum(imgs) / len(recs):.0f} images per sequence)"
            )
        write_text(
            args.out / "jobs" / "summary.json",
            json.dumps(
                {"ok": summary.ok, "total": summary.total, "failures": summary.failures}, indent=1
            ),
        )
        print(summary.report())
        return 0 if summary.ok == summary.total else 1
