"""Simulated sequences in the published layouts (SPEC section 8), one scene per job.

- :func:`simulate_clip` / :func:`run_movingcables`: a MovingCables clip: one hose of a
  randomised scene moved by the gripper while every other hose stays exactly still
  (:class:`~cablesim.sim.freeze.HoseFreeze`); every frame at the camera's 15 frames/s (odd
  image numbers from 00000001), flow of each image back to the first one with instance ids,
  normal flow, and the arm as the "stick" (robot pixels dilated by 2 px, as the thesis dilates
  the poking stick).  Flow is given on hose pixels and zero elsewhere, as in the published
  ground truth.
- :func:`run_mcor`: a motion-correlation robot sequence (grasp, two actions, target frame) in
  the published layout, with its ground-truth mask under ``motion_correlation_annotations``.

Everything a sequence holds follows from its seed (scene, hose, start segment), so a sequence
is the same bytes whatever the number of workers that wrote the dataset.  A sequence is written
into a hidden staging folder (``.partial/`` beside its place) and moved into place when every
file of it is written (:func:`cablesim.files.staged`); it counts as finished when its job's
result file exists (:mod:`cablesim.jobs`), so a killed run leaves at most an unfinished
sequence, which the next run removes and writes again.  A full disk stops the run with
``DiskFullError`` naming the file; the finished sequences stay as they are.
"""

from __future__ import annotations

import datetime as dt
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cablesim.dataset.randomize import Randomization, randomize_scene
from cablesim.errors import CablesimError, InputError
from cablesim.files import commit, staged
from cablesim.formats.mcor import sequence_name, write_annotation, write_mcor
from cablesim.formats.movingcables import ClipFrame, arm_share, labels_to_instances, write_clip
from cablesim.seeding import stream
from cablesim.sim.config import EpisodeConfig, SceneConfig
from cablesim.sim.flow_gt import gt_flow
from cablesim.sim.freeze import HoseFreeze
from cablesim.sim.session import SimSession
from cablesim.video import h264_roundtrip

STICK_DILATION = 2  # px, as the thesis dilates the poking stick's mask
SEQUENCE_EPOCH = dt.datetime(2030, 1, 1)  # sequence names: epoch + seed minutes


def outcome_of(reason: str) -> str:
    """A short named outcome from an interaction's failure reason (``"grasp: ..."`` ->
    ``"grasp"``); a result's own ``outcome`` is used when it has one."""
    head = reason.split(":")[0].split("(")[0].strip().lower()
    slug = "".join(c if c.isalnum() else "_" for c in head).strip("_")
    return (slug or "failed")[:40]


def scene_from(params: dict[str, Any]) -> SceneConfig:
    """The scene of a job: randomised from the seed (datasets) or the default scene, at the
    job's image size and hose count."""

    size = params.get("scene", {})
    values: dict[str, Any] = {"seed": int(params["seed"])}
    for name, path in (("width", "camera.width"), ("height", "camera.height")):
        if name in size:
            values[path] = int(size[name])
    if "hoses" in size:
        values["hoses.count"] = int(size["hoses"])
    if "cable" in size:
        values["hoses.kind"] = str(size["cable"])
    if "pattern" in size:
        values["hoses.pattern"] = str(size["pattern"])
    if "surface" in size:
        values["surface"] = str(size["surface"])
    base = SceneConfig().with_values(values)
    if params.get("randomize", False):
        r = dict(params["randomize"]) if isinstance(params["randomize"], dict) else {}
        if "cable" in size:  # one kind asked for: the randomiser draws no kinds
            r["cable_kinds"] = (str(size["cable"]),)
        if "pattern" in size:  # one pattern asked for: the randomiser draws none
            r["cable_patterns"] = (str(size["pattern"]),)
        for name in ("cable_kinds", "cable_patterns", "hoses"):
            if name in r:
                r[name] = tuple(r[name])
        return randomize_scene(base.seed, base, Randomization(**r))
    return base


def failure(reason: str, outcome: str | None = None, **extra: Any) -> dict[str, Any]:
    return {
        "status": "failed",
        "outcome": outcome or outcome_of(reason),
        "result": {"reason": reason, **extra},
    }


# --------------------------------------------------------------------------- MovingCables
@dataclass
class SimClip:
    """One simulated single-moving-hose clip (see the module docstring)."""

    seed: int
    hose: int
    rgb: list[np.ndarray]
    flow: list[np.ndarray]  # each image back to the first, hose pixels only
    normal_flow: list[np.ndarray]
    instances: list[np.ndarray]  # uint16, hose index + 1 on hose pixels
    stick: list[np.ndarray]  # bool
    scene: SceneConfig


def simulate_clip(
    seed: int,
    scene: SceneConfig,
    periods: int = 1,
    directions: tuple[str, ...] = ("along",),
    amplitude: float = 0.02,
) -> SimClip | dict[str, Any]:
    """A :class:`SimClip` of ``scene``, or a failure record (named outcome): the hand moves
    the grasped hose ``periods`` times by +-``amplitude`` metres in ``directions``."""

    cfg = EpisodeConfig(scene=scene.replace(seed=seed)).with_values(
        {
            "interaction.actions.periods": int(periods),
            "interaction.actions.directions": tuple(directions),
            "interaction.actions.amplitude": float(amplitude),
            "interaction.capture.min_gripper_step": 0.0,  # every frame: a video clip
            "interaction.capture.truth_every": 1,  # and its exact flow
            "interaction.retreat.verify": False,  # the clip ends with the action: no target
        }
    )
    session = SimSession.build(cfg)
    try:
        hose = session.draw_hose()
        freeze = HoseFreeze(session.world, hose)
        session.world.after_step.append(freeze)
        session.truth.keep_snapshots = True
        try:
            seg = session.pick_start()
        except CablesimError as e:
            return failure(str(e), "no_start_segment")
        res = session.interact(seg.mask)
        freeze.release()
        if not res.success or res.stream is None:
            return failure(res.reason, getattr(res, "outcome", None), hose=hose)
        snaps = session.truth.kept
        frames = res.stream.frames
        if len(snaps) != len(frames):
            return failure("ground truth snapshots do not match the frames", "no_truth")
        idx = [i for i, f in enumerate(frames) if f.action == 0]
        if len(idx) < 2:
            return failure(f"only {len(idx)} frames in the action", "too_few_frames")
        first = snaps[idx[0]]
        kernel = np.ones((2 * STICK_DILATION + 1,) * 2, np.uint8)
        clip = SimClip(seed, hose, [], [], [], [], [], scene)
        for i in idx:
            s = snaps[i]
            g = gt_flow(s, first)
            on_hose = (s.labels >= 0)[..., None]
            clip.rgb.append(frames[i].rgb)
            clip.flow.append(np.where(on_hose, g.flow, 0.0).astype(np.float32))
            clip.normal_flow.append(np.where(on_hose, g.normal_flow, 0.0).astype(np.float32))
            clip.instances.append(labels_to_instances(s.labels))
            robot = (s.labels == -2).astype(np.uint8)
            clip.stick.append(cv2.dilate(robot, kernel) > 0)
        return clip
    finally:
        session.close()


CLIP_FOLDERS = ("rgb_clips", "flow_first_back", "normal_flow_first_back", "stick_masks")


def write_sim_clip(split_dir: str | Path, name: str, clip: SimClip) -> int:
    """Write a clip in the published layout (staged, then moved into place, replacing an
    unfinished earlier one: module docstring); returns the bytes written."""

    frames = [
        ClipFrame(2 * k + 1, rgb, flow, nflow, inst, stick)
        for k, (rgb, flow, nflow, inst, stick) in enumerate(
            zip(clip.rgb, clip.flow, clip.normal_flow, clip.instances, clip.stick, strict=True)
        )
    ]
    split_dir = Path(split_dir)
    with staged(split_dir, name) as tmp:
        write_clip(tmp, name, frames)
        total = 0
        for folder in CLIP_FOLDERS:
            total += sum(p.stat().st_size for p in (tmp / folder / name).glob("*.png"))
        for folder in CLIP_FOLDERS:
            if (tmp / folder / name).is_dir():
                commit(tmp / folder / name, split_dir / folder / name)
    return total


def clip_name(index: int) -> str:
    if not 1 <= index <= 9999:
        raise InputError(f"clip numbers run from 0001 to 9999, got {index}")
    return f"{index:04d}"


def clip_motion(seed: int, motion: dict[str, Any] | None) -> tuple[str, float]:
    """The action direction and amplitude (m) of clip ``seed``: one direction drawn from
    ``motion["directions"]`` and an amplitude uniform in ``motion["amplitude"]`` (lo, hi),
    from the seed's ``dataset_motion`` stream; without ``motion`` (jobs written before the
    draw existed) the hand pulls along the hose by 2 cm."""
    if not motion:
        return "along", 0.02
    names = tuple(motion["directions"])
    lo, hi = (float(v) for v in motion["amplitude"])
    rng = stream(seed, "dataset_motion")
    direction = names[int(rng.integers(len(names)))]
    return direction, float(lo + (hi - lo) * rng.random())


def clip_h264(seed: int, compress: dict[str, Any] | None) -> int | None:
    """The CRF at which clip ``seed`` is seen through H.264, or None (not compressed): with
    probability ``compress["h264"]``, a CRF uniform in ``compress["crf"]`` (lo, hi), from the
    seed's ``dataset_h264`` stream."""
    if not compress or not float(compress.get("h264", 0)):
        return None
    rng = stream(seed, "dataset_h264")
    if rng.random() >= float(compress["h264"]):
        return None
    lo, hi = (int(v) for v in compress["crf"])
    return int(rng.integers(lo, hi + 1))


def run_movingcables(params: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Job: one MovingCables clip (params: seed, clip number, split, root, scene, periods,
    motion: see :func:`clip_motion`, compress: see :func:`clip_h264`)."""
    t0 = time.perf_counter()
    seed = int(params["seed"])
    scene = scene_from(params)
    direction, amplitude = clip_motion(seed, params.get("motion"))
    clip = simulate_clip(seed, scene, int(params.get("periods", 1)), (direction,), amplitude)
    if isinstance(clip, dict):
        return {**clip, "result": {**clip["result"], "direction": direction}}
    crf = clip_h264(seed, params.get("compress"))
    if crf is not None:  # the images as a published video shows them; the flow stays exact
        clip.rgb = h264_roundtrip(clip.rgb, crf)
    t_sim = time.perf_counter() - t0
    name = clip_name(int(params["clip"]))
    nbytes = write_sim_clip(Path(params["root"]) / params["split"], name, clip)
    return {
        "status": "ok",
        "outcome": "ok",
        "result": {
            "clip": name,
            "split": params["split"],
            "seed": seed,
            "hose": clip.hose,
            "direction": direction,
            "amplitude": round(amplitude, 4),
            **({"h264_crf": crf} if crf is not None else {}),
            "images": len(clip.rgb),
            "bytes": nbytes,
            "hoses": scene.hoses.count,
            "background": scene.board.background,
            "moving_pixels_last": int(
                np.count_nonzero(np.linalg.norm(clip.normal_flow[-1], axis=2) > 1.0)
            ),
            # the largest share of an image the arm (the stick) covers: on the table the arm
            # can come between the camera and the hoses (up to 0.95 of the view)
            "arm_share_max": round(arm_share(clip.stick), 4),
        },
        "timings": {"simulate_s": t_sim, "write_s": time.perf_counter() - t0 - t_sim},
    }


# --------------------------------------------------------------------------- motion correlation
def sequence_name_of(seed: int) -> str:
    """The published-style folder name of seed ``seed``'s sequence (a fixed epoch plus
    ``seed`` minutes, so names sort by seed and never depend on when they were made)."""

    return sequence_name(SEQUENCE_EPOCH + dt.timedelta(minutes=int(seed)))


def run_mcor(params: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Job: one motion-correlation sequence (params: seed, split, root, scene, periods,
    arm_masks)."""

    t0 = time.perf_counter()
    seed = int(params["seed"])
    scene = scene_from(params)
    cfg = EpisodeConfig(scene=scene).with_values(
        {
            "interaction.actions.periods": int(params.get("periods", 3)),
            "interaction.capture.arm_masks": bool(params.get("arm_masks", True)),
            "interaction.capture.truth_every": 1,  # every frame's flow and labels
        }
    )
    session = SimSession.build(cfg)
    try:
        try:
            seg = session.pick_start()
        except CablesimError as e:
            return failure(str(e), "no_start_segment")
        res = session.interact(seg.mask)
        if not res.success or res.stream is None:
            return failure(res.reason, getattr(res, "outcome", None), hose=session.hose)
        stream = res.stream
        root = Path(params["root"])
        name = sequence_name_of(seed)
        buffers = Path("motion_correlation_buffers") / name
        annotations = Path("motion_correlation_annotations") / params["split"] / name
        masks = [f.arm_mask for f in stream.frames]
        truth = stream.target.truth.labels == session.hose
        with staged(root, name) as tmp:  # both folders complete before either is in place
            write_mcor(
                tmp / buffers,
                stream,
                segment=seg.mask,
                arm_masks=dict(enumerate(masks)) if all(m is not None for m in masks) else None,
                base_to_camera=np.linalg.inv(session.T_world_camera) @ session.T_world_base,
                overwrite=True,
            )
            ann = write_annotation(
                tmp / annotations.parent.parent,
                params["split"],
                name,
                len(stream.frames) - 1,
                truth,
            )
            nbytes = sum(p.stat().st_size for p in (tmp / buffers).iterdir()) + ann.stat().st_size
            commit(tmp / buffers, root / buffers)
            commit(tmp / annotations, root / annotations)
        return {
            "status": "ok",
            "outcome": "ok",
            "result": {
                "sequence": name,
                "split": params["split"],
                "seed": seed,
                "hose": session.hose,
                "images": len(stream.frames),
                "bytes": nbytes,
                "hoses": scene.hoses.count,
                "background": scene.board.background,
                "truth_pixels": int(truth.sum()),
            },
            "timings": {"total_s": time.perf_counter() - t0},
        }
    finally:
        session.close()
