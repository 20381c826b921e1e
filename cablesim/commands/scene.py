"""Build and settle a seeded scene, render it (RGB, depth, labels), pull one hose's middle
vertex about 3 cm for 0.5 s of physics, render again and write the ground-truth optical flow
between the two frames.  The same seed gives the same files bit for bit.

Files: rgb.png, depth.png (colour-mapped), depth.npy (float32 metres, 0 = none), labels.png,
labels.npy (int16: hose index, -2 robot, -1 background), rgb_moved.png, labels_moved.npy,
flow.png (HSV wheel, invalid black), flow.npy (HxWx2 float32, rgb.png pixels -> rgb_moved.png),
flow_valid.npy, scene.json (config, intrinsics, camera pose, what was moved).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import mujoco
import numpy as np

from cablesim.commands._args import (
    add_scene_arguments,
    apply_scene_arguments,
    check_settle_cache,
    output_path,
    prepare_output_dir,
    write_image,
)
from cablesim.config import to_dict
from cablesim.errors import InputError
from cablesim.perception.frames import LABEL_BACKGROUND, LABEL_ROBOT
from cablesim.sim.config import BACKGROUNDS, SceneConfig

PULL_DISTANCE = 0.03  # m
PULL_TIME = 0.5  # s
PULL_STIFFNESS = 300.0  # N/m
PULL_DAMPING = 4.0  # N s/m
PULL_MAX_FORCE = 6.0  # N

LABEL_COLOURS = np.array(  # BGR, per hose index (cycled); robot and background below
    [
        [60, 60, 230],
        [80, 200, 60],
        [230, 120, 40],
        [40, 220, 240],
        [200, 60, 200],
        [230, 230, 60],
        [60, 140, 255],
        [170, 170, 170],
    ],
    np.uint8,
)
ROBOT_COLOUR = np.array([255, 255, 255], np.uint8)
BACKGROUND_COLOUR = np.array([0, 0, 0], np.uint8)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--out", type=output_path, required=True, help="output directory")
    p.add_argument("--background", choices=BACKGROUNDS, default=None, help="board background")
    p.add_argument("--hose", type=int, default=0, help="which hose to pull (default 0)")
    p.add_argument("--no-robot", action="store_true", help="leave the arm out of the scene")
    p.add_argument("--depth-noise", action="store_true", help="RealSense-like depth noise")


def scene_config(args: argparse.Namespace) -> SceneConfig:
    cfg = apply_scene_arguments(SceneConfig(), args)
    if args.background is not None:
        cfg.board.background = args.background
    if args.no_robot:
        cfg.robot.enabled = False
    cfg.camera.depth_noise = bool(args.depth_noise)
    return cfg.validate()


def colour_depth(depth: np.ndarray) -> np.ndarray:
    """BGR uint8 colour map of a depth image (near = warm); 0 (no depth) is black."""
    valid = depth > 0
    out = np.zeros((*depth.shape, 3), np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth[valid], [1, 99])
        scaled = np.clip((depth - lo) / max(hi - lo, 1e-6), 0, 1)
        cmap = cv2.applyColorMap((255 * (1 - scaled)).astype(np.uint8), cv2.COLORMAP_TURBO)
        out[valid] = cmap[valid]
    return out


def colour_labels(labels: np.ndarray) -> np.ndarray:
    out = np.empty((*labels.shape, 3), np.uint8)
    out[:] = BACKGROUND_COLOUR
    out[labels == LABEL_ROBOT] = ROBOT_COLOUR
    hose = labels >= 0
    out[hose] = LABEL_COLOURS[labels[hose] % len(LABEL_COLOURS)]
    out[(labels < 0) & (labels != LABEL_ROBOT) & (labels != LABEL_BACKGROUND)] = 128
    return out


def colour_flow(flow: np.ndarray, valid: np.ndarray, max_mag: float | None = None) -> np.ndarray:
    """BGR uint8 HSV colour wheel: hue = direction, value = magnitude / max; invalid black."""
    mag = np.linalg.norm(flow, axis=-1)
    ang = np.arctan2(flow[..., 1], flow[..., 0])
    if max_mag is None:
        max_mag = float(mag[valid].max()) if valid.any() else 1.0
    hsv = np.zeros((*flow.shape[:2], 3), np.uint8)
    hsv[..., 0] = np.round((ang + np.pi) / (2 * np.pi) * 179).astype(np.uint8)
    hsv[..., 1] = 255
    hsv[..., 2] = np.round(np.clip(mag / max(max_mag, 1e-6), 0, 1) * 255).astype(np.uint8)
    hsv[~valid] = 0
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def pull_hose(world, hose_index: int, distance: float, duration: float) -> dict:
    """Pull the middle vertex of a hose ``distance`` sideways (along the board, +y) with a
    damped spring force for ``duration`` seconds of physics; the pull is still on at the end."""
    m, d = world.model, world.data
    hose = world.hoses[hose_index]
    k = hose.n_vertices // 2
    body = int(hose.vertex_bodies[k])
    start = d.xpos[body].copy()
    target = start + np.array([0.0, distance, 0.0])
    n_steps = int(round(duration / m.opt.timestep))
    for _ in range(n_steps):
        vel = np.zeros(6)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, vel, 0)
        f = PULL_STIFFNESS * (target - d.xpos[body]) - PULL_DAMPING * vel[3:]
        norm = np.linalg.norm(f)
        if norm > PULL_MAX_FORCE:
            f *= PULL_MAX_FORCE / norm
        d.xfrc_applied[body, :3] = f
        world.step(1)
    return {
        "hose": hose_index,
        "vertex": k,
        "start": start.tolist(),
        "target": target.tolist(),
        "end": d.xpos[body].tolist(),
        "duration_s": duration,
    }


def run(args: argparse.Namespace) -> int:
    from cablesim.sim.camera import SimCamera
    from cablesim.sim.flow_gt import gt_flow
    from cablesim.sim.settle import settle_world
    from cablesim.sim.world import World

    cfg = scene_config(args)
    if not 0 <= args.hose < cfg.hoses.count:
        raise InputError(f"--hose {args.hose} is not one of the {cfg.hoses.count} hoses")
    out = prepare_output_dir(args.out)
    check_settle_cache(cfg)
    t0 = time.perf_counter()
    print(
        f"[scene] building seed {cfg.seed}: {cfg.hoses.count} hoses, "
        f"{cfg.board.background} board, robot {'on' if cfg.robot.enabled else 'off'}",
        flush=True,
    )
    world = World.build(cfg, settle=False)
    speed = settle_world(world, progress=True)
    print(
        f"[scene] settled (max hose speed {speed * 1000:.3f} mm/s) "
        f"in {time.perf_counter() - t0:.1f}s",
        flush=True,
    )
    with SimCamera(world) as cam:
        print(f"[scene] rendering {cam.width}x{cam.height}", flush=True)
        before = cam.snapshot()
        _write_frame(out, "", before)
        print(
            f"[scene] pulling hose {args.hose} by {PULL_DISTANCE * 100:.0f} cm "
            f"for {PULL_TIME:.1f}s",
            flush=True,
        )
        pulled = pull_hose(world, args.hose, PULL_DISTANCE, PULL_TIME)
        after = cam.snapshot()
        write_image(out / "rgb_moved.png", cv2.cvtColor(after.rgb, cv2.COLOR_RGB2BGR))
        np.save(out / "labels_moved.npy", after.labels)
        print("[scene] ground-truth flow", flush=True)
        flow, valid, _ = gt_flow(before, after)
        np.save(out / "flow.npy", flow)
        np.save(out / "flow_valid.npy", valid)
        write_image(out / "flow.png", colour_flow(flow, valid))
        mag = np.linalg.norm(flow[valid & (before.labels == args.hose)], axis=-1)
        meta = {
            "seed": cfg.seed,
            "config": to_dict(cfg),
            "intrinsics": cam.intrinsics.to_dict(),
            "T_world_camera": cam.T_world_camera.tolist(),
            "hoses": [
                {
                    "index": i,
                    "name": h.spec.name,
                    "rgb": list(h.spec.rgb),
                    "ends": list(h.spec.ends),
                }
                for i, h in enumerate(world.hoses)
            ],
            "pull": pulled,
            "flow": {
                "convention": "flow.npy[v, u] = (du, dv): rgb.png pixel (u, v) shows the point "
                "that rgb_moved.png shows at (u + du, v + dv); invalid where occluded/out",
                "valid_fraction": float(valid.mean()),
                "pulled_hose_max_px": float(mag.max()) if mag.size else 0.0,
            },
            "labels": {"background": LABEL_BACKGROUND, "robot": LABEL_ROBOT},
        }
        (out / "scene.json").write_text(json.dumps(meta, indent=2) + "\n")
    print(f"[scene] wrote {out} in {time.perf_counter() - t0:.1f}s", flush=True)
    return 0


def _write_frame(out: Path, suffix: str, snap) -> None:
    write_image(out / f"rgb{suffix}.png", cv2.cvtColor(snap.rgb, cv2.COLOR_RGB2BGR))
    write_image(out / f"depth{suffix}.png", colour_depth(snap.image.depth))
    np.save(out / f"depth{suffix}.npy", snap.image.depth)
    write_image(out / f"labels{suffix}.png", colour_labels(snap.labels))
    np.save(out / f"labels{suffix}.npy", snap.labels)
