"""Ground-truth optical flow: exact for rigid hose motion, photometrically consistent after
physics, zero on static pixels, invalid where occluded, and bad input errors."""

from __future__ import annotations

import cv2
import mujoco
import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.errors import InputError
from cablesim.frames import LABEL_BACKGROUND
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import CameraConfig, RobotConfig, SceneConfig
from cablesim.sim.flow_gt import flow_to_target, gt_flow
from cablesim.sim.world import World


def _world(w: int, h: int, seed: int = 0) -> World:
    return World.build(
        SceneConfig(
            seed=seed, camera=CameraConfig(width=w, height=h), robot=RobotConfig(enabled=False)
        )
    )


def _rotation(rotvec: np.ndarray) -> np.ndarray:
    R, _ = cv2.Rodrigues(np.asarray(rotvec, float))
    return R


def _set_hose_vertices(world: World, i: int, target: np.ndarray) -> None:
    """Move every free vertex of hose i to ``target`` through its slide joints."""
    m, d = world.model, world.data
    current = world.hose_vertices(i)
    for k, body in enumerate(world.hoses[i].vertex_bodies):
        if body == 0:
            continue
        jadr = m.body_jntadr[body]
        for j in range(m.body_jntnum[body]):
            d.qpos[m.jnt_qposadr[jadr + j]] += m.jnt_axis[jadr + j] @ (target[k] - current[k])
    mujoco.mj_forward(m, d)


@pytest.fixture(scope="module")
def rigid():
    """Hose 1 moved rigidly (rotation about its centroid + translation), no physics."""
    world = _world(320, 240)
    hi = 1
    with SimCamera(world) as cam:
        s0 = cam.snapshot()
        V = world.hose_vertices(hi)
        Q, c, t = _rotation([0.05, 0.1, 0.15]), V.mean(0), np.array([-0.03, 0.01, 0.02])
        _set_hose_vertices(world, hi, (V - c) @ Q.T + c + t)
        s1 = cam.snapshot()
    return world, hi, s0, s1, Q, c, t, V


def test_rigid_motion_gives_exact_analytic_flow(rigid):
    world, hi, s0, s1, Q, c, t, V = rigid
    g = gt_flow(s0, s1)
    K = s0.intrinsics
    v, u = np.nonzero(s0.labels == hi)
    X = world.camera_to_world(K.backproject(np.stack([u, v], -1), s0.depth[v, u]))
    expected = K.project(world.world_to_camera((X - c) @ Q.T + c + t)) - np.stack([u, v], -1)
    # vertex 0 is pinned to the world, so the first edge is not moved rigidly
    rigid_part = np.linalg.norm(X - V[0], axis=1) > 0.08
    assert rigid_part.sum() > 200
    err = np.linalg.norm(g.flow[v, u] - expected, axis=1)[rigid_part]
    assert err.max() < 1e-3, f"max error {err.max():.2e} px"
    assert np.linalg.norm(expected, axis=1).mean() > 3  # it really moved
    assert g.valid[v, u].mean() > 0.6


def test_static_pixels_zero_and_occlusions_invalid(rigid):
    world, hi, s0, s1, *_ = rigid
    flow, valid, normal_flow = gt_flow(s0, s1)
    static = (s0.labels == LABEL_BACKGROUND) | ((s0.labels >= 0) & (s0.labels != hi))
    assert np.all(flow[static] == 0)
    # background newly covered by the moved hose: occluded in dst
    covered = (s0.labels == LABEL_BACKGROUND) & (s1.labels == hi)
    assert covered.sum() > 50
    assert not valid[covered].any()
    uncovered = (s0.labels == LABEL_BACKGROUND) & (s1.labels == LABEL_BACKGROUND)
    assert valid[uncovered].mean() > 0.99
    # moved-hose pixels whose destination shows something else are invalid
    v, u = np.nonzero(s0.labels == hi)
    q = np.rint(np.stack([u, v], -1) + flow[v, u]).astype(int)
    inside = (q[:, 0] >= 0) & (q[:, 0] < 320) & (q[:, 1] >= 0) & (q[:, 1] < 240)
    other = np.zeros(len(v), bool)
    other[inside] = s1.labels[q[inside, 1], q[inside, 0]] != hi
    assert other.sum() > 0
    assert not valid[v[other], u[other]].any()
    # normal flow: hose pixels only, never longer than the flow
    assert np.all(normal_flow[s0.labels < 0] == 0)
    assert np.all(np.linalg.norm(normal_flow, axis=-1) <= np.linalg.norm(flow, axis=-1) + 1e-4)


def test_identity_and_convention(rigid):
    _, _, s0, s1, *_ = rigid
    g = gt_flow(s0, s0)
    assert np.all(g.flow == 0)
    assert g.valid[s0.depth > 0].all()
    a, b = flow_to_target(s1, s0), gt_flow(s0, s1)
    assert np.array_equal(a.flow, b.flow) and np.array_equal(a.valid, b.valid)


def test_warping_with_gt_flow_after_physics():
    """Pull a hose by physics; warping the moved frame back with the GT flow reproduces the
    first frame on visible hose pixels, much better than no flow does."""
    world = _world(640, 480, seed=2)
    hi = 0
    hose = world.hoses[hi]
    body = int(hose.vertex_bodies[hose.n_vertices // 2])
    with SimCamera(world) as cam:
        s0 = cam.snapshot()
        world.data.xfrc_applied[body, :3] = [-0.1, 0.3, 0.05]
        world.step(int(0.3 / world.model.opt.timestep))
        s1 = cam.snapshot()
    flow, valid, _ = gt_flow(s0, s1)
    h, w = s0.shape
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    warped = cv2.remap(s1.rgb, gx + flow[..., 0], gy + flow[..., 1], cv2.INTER_LINEAR)
    inner = cv2.erode((s0.labels == hi).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    sel = inner & valid
    moved = np.linalg.norm(flow, axis=-1) > 2
    assert (sel & moved).sum() > 300
    sel &= moved
    a = s0.rgb.astype(float)
    err_gt = np.abs(warped.astype(float) - a)[sel].mean()
    err_zero = np.abs(s1.rgb.astype(float) - a)[sel].mean()
    assert err_gt < 10.0, err_gt
    print(f"photometric error: GT flow {err_gt:.1f}, zero flow {err_zero:.1f}")
    assert err_zero > 3 * err_gt, (err_zero, err_gt)


def test_flow_from_one_source_to_many_frames_reuses_only_source_work(rigid):
    """flow_to_target uses the target as the source of every flow: what depends on the source
    alone is computed once per snapshot, and the flows equal those of a fresh source copy."""
    import dataclasses

    world, hi, s0, s1, *_ = rigid
    first = gt_flow(s0, s1)
    assert "_gt_source" in s0.__dict__  # cached on the snapshot (by flow_gt)
    identity = gt_flow(s0, s0)  # the same source, another destination
    assert np.all(identity.flow == 0)
    for dst, ref in ((s1, first), (s0, identity)):
        fresh = dataclasses.replace(s0)  # no cached source work
        assert "_gt_source" not in fresh.__dict__
        again = gt_flow(fresh, dst)
        for a, b in zip(again, ref, strict=True):
            assert np.array_equal(a, b)


def test_bad_input(rigid):
    _, _, s0, _, *_ = rigid
    with pytest.raises(InputError):
        gt_flow(s0, "not a snapshot")  # type: ignore[arg-type]
    small = _world(160, 120)
    with SimCamera(small) as cam:
        other = cam.snapshot()
    with pytest.raises(InputError):
        gt_flow(s0, other)
