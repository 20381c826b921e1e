"""How much of the cables the table's camera sees while the hand works, for candidate views.

    .venv/bin/python -m benchmarks.table_views [--seeds 11,12,13] [--write]

For each view and seed the table scene is built and settled once; the arm is then put, by
inverse kinematics and without stepping the physics (the cables stay where they settled), at
16 points of the mat with the TCP 2.5 cm above the table and the hand pointing down (the
height of the actions: the grasp plus the 1 cm lift), and the labels are rendered.  Per pose:
the share of the cable pixels within 8 cm of the TCP's point on the table (projected) that stay
visible against the parked arm's image (what motion correlation can see of the grasped cable
near the hand), the share of all cable pixels that stay visible, and the share of the image
the robot covers.  Also the robot's pixels with the arm parked: the interaction refuses a
target frame in which the robot shows (``robot_in_view``).

``--write`` writes ``benchmarks/results/table_views.md``.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import statistics

import mujoco
import numpy as np

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.config import override
from cablesim.frames import LABEL_ROBOT
from cablesim.panda.model import joint_qpos_addresses
from cablesim.pose import Pose
from cablesim.sim.config import SURFACE_VIEWS, EpisodeConfig
from cablesim.sim.session import SimSession

OUT = RESULTS / "table_views.md"
#: (name, (position, look_at)); None: the table's default view
VIEWS: list[tuple[str, tuple[tuple[float, ...], tuple[float, ...]] | None]] = [
    ("default (over the robot's shoulder)", None),
    ("across the mat, 53 deg", ((0.42, 0.32, 0.62), (0.36, -0.14, 0.0))),
    ("across the mat, 48 deg", ((0.35, 0.30, 0.70), (0.35, -0.14, 0.0))),
    ("across the mat, steep", ((0.36, 0.20, 0.80), (0.36, -0.10, 0.0))),
    ("nearly overhead", ((0.36, -0.03, 1.00), (0.36, -0.13, 0.0))),
    ("behind the robot, high", ((0.35, -0.30, 1.00), (0.35, -0.10, 0.0))),
    ("beside the robot, +x", ((0.62, -0.45, 0.80), (0.36, -0.10, 0.0))),
]
HAND_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
GRID = [(x, y, 0.025) for x in (0.2, 0.3, 0.4, 0.5) for y in (-0.3, -0.18, -0.06, 0.06)]
NEAR = 0.08  # m around the TCP's point on the table


def measure(view, seed: int) -> dict[str, list[float]]:
    cfg = override(EpisodeConfig.of(seed=seed), "scene.surface=table")
    if view is not None:
        cfg = override(cfg, f"scene.camera.position={list(view[0])}")
        cfg = override(cfg, f"scene.camera.look_at={list(view[1])}")
    s = SimSession.build(cfg)
    try:
        m, d = s.world.model, s.world.data
        K, T = s.camera.intrinsics, s.camera.T_world_camera
        parked = s.camera.render_labels()
        cables = parked >= 0
        q0 = d.qpos.copy()
        arm = joint_qpos_addresses(m, s.robot.names.joints)
        yy, xx = np.mgrid[: parked.shape[0], : parked.shape[1]]
        out: dict[str, list[float]] = {"near": [], "all": [], "robot": [], "park": []}
        out["park"].append(float((parked == LABEL_ROBOT).sum()))
        for p in GRID:
            q = s.robot.solve_ik(Pose.from_rotation(np.array(p), HAND_DOWN))
            if q is None:
                continue
            d.qpos[arm] = q
            mujoco.mj_forward(m, d)
            labels = s.camera.render_labels()
            d.qpos[:] = q0
            mujoco.mj_forward(m, d)
            cam = (np.array(p) - T[:3, 3]) @ T[:3, :3]
            u, v = K.project(cam[None])[0]
            r = K.f * NEAR / cam[2]
            near = cables & ((xx - u) ** 2 + (yy - v) ** 2 < r * r)
            if near.sum() > 20:
                out["near"].append(float(((labels >= 0) & near).sum() / near.sum()))
            out["all"].append(float(((labels >= 0) & cables).sum() / cables.sum()))
            out["robot"].append(float((labels == LABEL_ROBOT).mean()))
        return out
    finally:
        s.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="11,12,13")
    ap.add_argument("--write", action="store_true", help=f"write {OUT.name}")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rows = []
    for name, view in VIEWS:
        acc: dict[str, list[float]] = {"near": [], "all": [], "robot": [], "park": []}
        for seed in seeds:
            for k, v in measure(view, seed).items():
                acc[k] += v
        shown = view or SURFACE_VIEWS["table"]
        row = (
            f"| {name} | {tuple(shown[0])} | {tuple(shown[1])} | {len(acc['all'])} | "
            f"{statistics.median(acc['near']):.2f} | {statistics.median(acc['all']):.2f} | "
            f"{statistics.median(acc['robot']):.2f} | "
            f"{', '.join(str(int(p)) for p in acc['park'])} |"
        )
        print(row, flush=True)
        rows.append(row)
    text = "\n".join(
        [
            "# The table's camera: what it sees of the cables while the hand works",
            "",
            f"`python -m benchmarks.table_views --seeds {args.seeds} --write`: see the module's "
            "docstring for the method. Medians over the poses of every seed. 'near the hand': "
            f"the share of the cable pixels within {NEAR * 100:.0f} cm of the TCP's point on "
            "the table that the arm leaves visible; 'robot at park': robot pixels with the arm "
            "parked, per seed (a target frame with any is refused, `robot_in_view`).",
            "",
            f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}",
            "",
            "| view | position | look_at | poses | cable visible near the hand | all cable "
            "visible | robot share of the image | robot px at park |",
            "|---|---|---|---|---|---|---|---|",
            *rows,
            "",
        ]
    )
    if args.write:
        write_results(OUT, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
