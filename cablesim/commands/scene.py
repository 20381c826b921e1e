"""Build and settle a seeded scene, render it (RGB, depth, labels), pull one hose's middle
vertex about 3 cm for 0.5 s of physics, render again and write the ground-truth optical flow
between the two frames.  The same seed gives the same files bit for bit.

Files: rgb.png, depth.png (colour-mapped, with a colour bar in metres), depth.npy (float32
metres, 0 = none), labels.png (with a key), labels.npy (int16: hose index, -2 robot,
-1 background), rgb_moved.png, labels_moved.npy, flow.png (HSV wheel, invalid black, with the
wheel as a key), flow.npy (HxWx2 float32, rgb.png pixels -> rgb_moved.png), flow_valid.npy,
scene.json (config, intrinsics, camera pose, what was moved).  The pictures carry titles;
rgb.png and rgb_moved.png are the camera's images as rendered.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from cablesim.cables import GARDEN_HOSE
from cablesim.commands._args import (
    SCENE_FLAGS,
    add_scene_arguments,
    build_config,
    check_settle_cache,
    output_path,
    prepare_output_dir,
    show_config,
    write_config,
)
from cablesim.config import to_dict
from cablesim.errors import InputError
from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import BACKGROUNDS, SceneConfig
from cablesim.sim.flow_gt import gt_flow
from cablesim.sim.perturb import spring_force, stable_damping
from cablesim.sim.settle import settle_world
from cablesim.sim.world import World
from cablesim.viz import (
    colour_flow,
    colour_labels,
    depth_tile,
    hstack,
    labels_legend,
    panel,
    with_flow_wheel,
    write_png,
)

PULL_DISTANCE = 0.03  # m
PULL_TIME = 0.5  # s
# the spring on the default hose's vertex; a cable of another kind gets it scaled by its
# vertex's mass, the same acceleration (6 N on a rope's 1.3 g vertex tore the rope apart)
PULL_STIFFNESS = 300.0  # N/m
PULL_DAMPING = 4.0  # N s/m
PULL_MAX_FORCE = 6.0  # N
PULL_VERTEX_MASS = GARDEN_HOSE.mass_per_metre * GARDEN_HOSE.segment_length  # kg, nominal


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--out", type=output_path, default=None, help="output directory (required)")
    p.add_argument(
        "--background",
        choices=BACKGROUNDS,
        default=None,
        help="the board's background, or the mat's on the table",
    )
    p.add_argument("--hose", type=int, default=0, help="which hose to pull (default 0)")
    p.add_argument("--no-robot", action="store_true", help="leave the arm out of the scene")
    p.add_argument("--depth-noise", action="store_true", help="RealSense-like depth noise")


def scene_config(args: argparse.Namespace) -> SceneConfig:
    """``SceneConfig()`` or ``--config FILE``, then the flags given, then ``--set``."""
    values: dict[str, object] = {}
    if args.no_robot:
        values["robot.enabled"] = False
    if args.depth_noise:
        values["camera.depth_noise"] = True
    cfg = build_config(SceneConfig, args, SCENE_FLAGS, values, section="config")
    set_paths = {a.partition("=")[0].strip() for a in getattr(args, "set", None) or []}
    path = f"{cfg.surface}.background"  # the board's, or the table mat's
    if args.background is not None and path not in set_paths:  # (--set wins over a flag)
        cfg = cfg.with_values({path: args.background})
    return cfg


def pull_hose(world, hose_index: int, distance: float, duration: float) -> dict:
    """Pull the middle vertex of a hose ``distance`` sideways (+y: along the board, or across
    the table) with a
    damped spring force for ``duration`` seconds of physics; the pull is still on at the end."""
    m, d = world.model, world.data
    hose = world.hoses[hose_index]
    k = hose.n_vertices // 2
    body = int(hose.vertex_bodies[k])
    cable = hose.spec.cable
    scale = cable.mass_per_metre * cable.segment_length / PULL_VERTEX_MASS  # 1 for the hose
    stiffness, max_force = scale * PULL_STIFFNESS, scale * PULL_MAX_FORCE
    # an explicit force: its damping capped for a stable step (as the perturbation's)
    damping = stable_damping(scale * PULL_DAMPING, m.body_mass[body], m.opt.timestep)
    start = d.xpos[body].copy()
    target = start + np.array([0.0, distance, 0.0])
    n_steps = int(round(duration / m.opt.timestep))
    for _ in range(n_steps):
        d.xfrc_applied[body, :3] = spring_force(m, d, body, target, stiffness, damping, max_force)
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

    cfg = scene_config(args)
    if args.show_config:
        return show_config(cfg)
    if not 0 <= args.hose < cfg.hoses.count:
        raise InputError(f"--hose {args.hose} is not one of the {cfg.hoses.count} hoses")
    out = prepare_output_dir(args.out)
    write_config(out, cfg)
    cfg = check_settle_cache(cfg)
    t0 = time.perf_counter()
    print(
        f"[scene] building seed {cfg.seed}: {cfg.hoses.count} hoses, "
        f"{getattr(cfg, cfg.surface).background} {cfg.surface}, "
        f"robot {'on' if cfg.robot.enabled else 'off'}",
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
        write_png(out / "rgb_moved.png", after.rgb)
        np.save(out / "labels_moved.npy", after.labels)
        print("[scene] ground-truth flow", flush=True)
        flow, valid, _ = gt_flow(before, after)
        np.save(out / "flow.npy", flow)
        np.save(out / "flow_valid.npy", valid)
        mag = np.linalg.norm(flow[valid & (before.labels == args.hose)], axis=-1)
        mm = float(max(np.linalg.norm(flow[valid], axis=-1).max(initial=0.0), 1e-6))
        write_png(
            out / "flow.png",
            panel(
                [with_flow_wheel(colour_flow(flow, mm, valid), mm)],
                [f"ground-truth flow rgb.png -> rgb_moved.png (hose {args.hose} pulled)"],
            ),
        )
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
    write_png(out / f"rgb{suffix}.png", snap.rgb)
    write_png(out / f"depth{suffix}.png", panel([depth_tile(snap.image.depth)], ["depth (m)"]))
    np.save(out / f"depth{suffix}.npy", snap.image.depth)
    labels = hstack([colour_labels(snap.labels), labels_legend(snap.labels, snap.labels.shape[0])])
    write_png(out / f"labels{suffix}.png", panel([labels], ["labels"]))
    np.save(out / f"labels{suffix}.npy", snap.labels)
