"""Write ``docs/panda_mesh.png``: the Panda drawn with franka_ros's meshes and with primitives.

    .venv/bin/python scripts/panda_mesh_picture.py [--out docs/panda_mesh.png]

Top row: the default scene (seed 0) through its RGB-D camera with the arm moved into view
(``FORWARD_QPOS``, hand towards the board), once with ``RobotConfig.visual="mesh"`` and once
with ``"primitive"``, and the robot's segmentation labels of the meshed arm.  Bottom row: a
close-up of the meshed arm at ``HOME_QPOS`` and of its hand, with the collision primitives
drawn translucent orange over the meshes (the two share the link frames: the meshes sit on the
DH frames the primitives were built on).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cablesim.gl

cablesim.gl.configure()  # the headless GL back end, before MuJoCo is imported

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from cablesim.frames import LABEL_ROBOT  # noqa: E402
from cablesim.panda.description import FORWARD_QPOS, HOME_QPOS  # noqa: E402
from cablesim.panda.model import joint_qpos_addresses  # noqa: E402
from cablesim.panda.visuals import HIDDEN_COLLISION_GROUP  # noqa: E402
from cablesim.sim.camera import SimCamera  # noqa: E402
from cablesim.sim.config import SceneConfig  # noqa: E402
from cablesim.sim.world import World  # noqa: E402
from cablesim.viz import colour_labels, panel, vstack, write_png  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "panda_mesh.png"
W, H = 640, 480


def scene_view(visual: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cfg = SceneConfig(seed=0).with_values({"robot.visual": visual})
    world = World.build(cfg)
    world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = q
    mujoco.mj_forward(world.model, world.data)
    with SimCamera(world, width=W, height=H) as cam:
        snap = cam.snapshot()
    return snap.rgb, snap.labels


def close_up(
    q: np.ndarray, lookat: tuple[float, float, float], distance: float, azimuth: float
) -> np.ndarray:
    """The meshed arm (scene without hoses) from a free camera, collision geoms overlaid."""
    cfg = SceneConfig(seed=0).with_values({"robot.visual": "mesh", "hoses.count": 1})
    world = World.build(cfg, settle=False)
    m, d = world.model, world.data
    d.qpos[joint_qpos_addresses(m, world.panda.joints)] = q
    mujoco.mj_forward(m, d)
    hidden = m.geom_group == HIDDEN_COLLISION_GROUP
    m.geom_rgba[hidden] = (1.0, 0.45, 0.0, 0.45)
    opt = mujoco.MjvOption()
    opt.geomgroup[HIDDEN_COLLISION_GROUP] = 1
    opt.flags[mujoco.mjtVisFlag.mjVIS_TENDON] = False
    opt.flags[mujoco.mjtVisFlag.mjVIS_FLEXVERT] = False
    opt.flags[mujoco.mjtVisFlag.mjVIS_FLEXSKIN] = False
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = lookat
    cam.distance, cam.azimuth, cam.elevation = distance, azimuth, -15.0
    with mujoco.Renderer(m, H, W) as r:
        r.update_scene(d, cam, opt)
        return r.render().copy()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    q_view = np.asarray(FORWARD_QPOS, float)
    mesh_rgb, mesh_labels = scene_view("mesh", q_view)
    prim_rgb, _ = scene_view("primitive", q_view)
    robot_px = int((mesh_labels == LABEL_ROBOT).sum())
    world = World.build(SceneConfig(seed=0), settle=False)  # where the hand is at HOME_QPOS
    world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = HOME_QPOS
    mujoco.mj_kinematics(world.model, world.data)
    hand = world.data.body("panda/hand").xpos.copy()
    base = world.data.body("panda/link0").xpos.copy()
    middle = tuple((base + hand) / 2 + [0.0, 0.0, 0.15])
    arm = close_up(np.asarray(HOME_QPOS, float), middle, 1.25, 25.0)
    hand_img = close_up(np.asarray(HOME_QPOS, float), tuple(hand + [0, 0, -0.06]), 0.42, 40.0)
    top = panel(
        [mesh_rgb, prim_rgb, colour_labels(mesh_labels)],
        [
            'visual="mesh": franka_ros meshes (scene camera)',
            'visual="primitive": the collision geoms',
            f"labels of the meshed arm ({robot_px} robot px, white)",
        ],
    )
    bottom = panel(
        [arm, hand_img],
        [
            "meshes with the collision primitives (orange) at HOME_QPOS",
            "hand and fingers: meshes and collision boxes",
        ],
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, vstack([top, bottom], sep=10))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
