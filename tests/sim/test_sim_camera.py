"""SimCamera: intrinsics, labels, metric z-depth, determinism, depth noise, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.camera import Camera, CameraImage
from cablesim.errors import InputError
from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT
from cablesim.sim.camera import SimCamera, intrinsics_from_fovy, robot_body_ids
from cablesim.sim.config import CameraConfig, RobotConfig, SceneConfig
from cablesim.sim.world import World

W, H = 320, 240


def _cfg(seed: int = 0, **camera) -> SceneConfig:
    return SceneConfig(
        seed=seed,
        camera=CameraConfig(width=W, height=H, **camera),
        robot=RobotConfig(enabled=False),
    )


@pytest.fixture(scope="module")
def world() -> World:
    return World.build(_cfg())


@pytest.fixture(scope="module")
def snap(world: World):
    with SimCamera(world) as cam:
        return cam.snapshot()


def test_intrinsics_from_fovy():
    K = intrinsics_from_fovy(640, 480, 58.0)
    assert K.fx == K.fy == pytest.approx(240 / math.tan(math.radians(29)))
    assert (K.cx, K.cy) == (319.5, 239.5)
    with pytest.raises(InputError):
        intrinsics_from_fovy(0, 480, 58)
    with pytest.raises(InputError):
        intrinsics_from_fovy(640, 480, 180)


def test_capture_types(world: World):
    with SimCamera(world) as cam:
        assert isinstance(cam, Camera)
        img = cam.capture()
        assert isinstance(img, CameraImage)
        assert img.rgb.shape == (H, W, 3) and img.rgb.dtype == np.uint8
        assert img.depth.shape == (H, W) and img.depth.dtype == np.float32
        assert img.timestamp == world.time
        assert cam.intrinsics.width == W and cam.intrinsics.height == H
        assert np.allclose(cam.T_world_camera, world.T_world_camera)


def test_labels_per_hose(world: World, snap):
    assert snap.labels.dtype == np.int16
    present = set(np.unique(snap.labels).tolist())
    assert present == {LABEL_BACKGROUND, *range(len(world.hoses))}  # no robot in this scene
    K = snap.intrinsics
    for i in range(len(world.hoses)):
        uv = np.rint(K.project(world.world_to_camera(snap.hose_vertices[i]))).astype(int)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        hit = snap.labels[uv[inside, 1], uv[inside, 0]] == i
        assert hit.mean() > 0.7, f"hose {i}: only {hit.mean():.2f} of its vertices carry its label"
    # hose pixels are labelled exactly where the hose's flex is rendered: body is -1 there
    assert np.all(snap.body[snap.labels >= 0] == -1)


def test_depth_is_metric_z_on_the_board(world: World, snap):
    """The board's front face is the plane x = board.x; depth must be z-depth (not the
    distance along the ray) in metres."""
    b = world.cfg.board
    K, T = snap.intrinsics, snap.T_world_camera
    v, u = np.mgrid[0:H, 0:W]
    rays = K.backproject(np.stack([u, v], -1), np.ones((H, W)))  # z = 1
    rays_w = rays @ T[:3, :3].T
    s = (b.x - T[0, 3]) / rays_w[..., 0]  # camera z at which the ray meets the plane
    hit = T[:3, 3] + s[..., None] * rays_w
    on_board = (np.abs(hit[..., 1]) < b.width / 2 - 0.02) & (hit[..., 2] > 0.05)
    on_board &= (hit[..., 2] < b.height - 0.02) & (snap.labels == LABEL_BACKGROUND)
    assert on_board.sum() > 0.2 * H * W
    err = np.abs(snap.depth[on_board] - s[on_board])
    assert np.mean(err < 0.002) > 0.9  # the rest: connectors and couplings in front
    assert np.median(err) < 5e-4
    # far corners: a ray distance would be >5% larger than z there
    corner = on_board & (np.abs(u - K.cx) > 0.35 * W) & (np.abs(v - K.cy) > 0.3 * H)
    if corner.any():
        assert np.median(np.abs(snap.depth[corner] - s[corner])) < 2e-3


def test_determinism_same_seed_same_bits():
    a, b = World.build(_cfg(seed=3)), World.build(_cfg(seed=3))
    with SimCamera(a) as ca, SimCamera(b) as cb:
        sa, sb = ca.snapshot(), cb.snapshot()
    assert np.array_equal(sa.rgb, sb.rgb)
    assert np.array_equal(sa.depth, sb.depth)
    assert np.array_equal(sa.labels, sb.labels)


def test_depth_noise_seeded_and_realsense_like(world: World):
    clean = SimCamera(world)
    n1, n2 = SimCamera(world, depth_noise=True), SimCamera(world, depth_noise=True)
    try:
        d0 = clean.capture().depth
        d1, d2 = n1.capture().depth, n2.capture().depth
        assert np.array_equal(d1, d2)  # same seed, same noise
        assert not np.array_equal(d1, n1.capture().depth)  # a new draw per frame
    finally:
        for c in (clean, n1, n2):
            c.close()
    both = (d0 > 0) & (d1 > 0)
    k = world.cfg.camera.depth_noise_std_per_m2
    rel = (d1[both] - d0[both]) / (k * d0[both] ** 2)
    assert 0.7 < np.std(rel) < 1.5
    assert np.all(d1 >= 0) and np.mean(d1 == 0) < 0.1 + np.mean(d0 == 0)


def test_bad_input(world: World):
    with pytest.raises(InputError):
        SimCamera(world, width=100000, height=10)
    cam = SimCamera(world)
    cam.close()
    with pytest.raises(InputError):
        cam.capture()


def test_robot_bodies_descend_from_root():
    import mujoco

    spec = mujoco.MjSpec()
    root = spec.worldbody.add_body(name="panda/link0")
    child = root.add_body(name="panda/link1")
    child.add_body(name="panda/hand")
    spec.worldbody.add_body(name="other")
    model = spec.compile()
    names = {model.body(int(b)).name for b in robot_body_ids(model)}
    assert names == {"panda/link0", "panda/link1", "panda/hand"}
    assert robot_body_ids(model, "nope").size == 0


def test_robot_pixels_labelled_robot():
    """The parked arm shows no pixel; moved into view (home), every pixel rendered on a robot
    body is labelled robot and no other pixel is (the zero-robot-pixel checks of the target
    frame rely on this labelling)."""
    import mujoco

    from cablesim.panda.model import HOME_QPOS, joint_qpos_addresses

    world = World.build(
        SceneConfig(seed=0, camera=CameraConfig(width=W, height=H), robot=RobotConfig())
    )
    with SimCamera(world) as cam:
        assert cam.robot_bodies.size > 0
        labels = cam.render_labels()
        assert labels.dtype == np.int16
        assert set(np.unique(labels).tolist()) <= {LABEL_BACKGROUND, 0, 1, 2, 3}  # parked
        world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = HOME_QPOS
        mujoco.mj_forward(world.model, world.data)
        snap = cam.snapshot()
    robot = snap.labels == LABEL_ROBOT
    assert robot.sum() > 500
    assert np.array_equal(robot, np.isin(snap.body, cam.robot_bodies))


def test_label_lookup_on_the_red_byte_is_the_three_byte_sum(monkeypatch):
    """The label pass looks ids up on the red byte alone where every id fits it; forced onto
    the three-byte sum (as a scene of 255 or more geoms takes it), the same labels, body ids
    and depth, bit for bit, with the arm and the hoses in view."""
    import cv2
    import mujoco

    from cablesim.panda.model import HOME_QPOS, joint_qpos_addresses

    world = World.build(
        SceneConfig(seed=1, camera=CameraConfig(width=W, height=H), robot=RobotConfig())
    )
    world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = HOME_QPOS
    mujoco.mj_forward(world.model, world.data)
    with SimCamera(world, layered=False) as cam:
        cam._update_scene()  # noqa: SLF001
        fast = cam._segmentation_pass()  # noqa: SLF001
        assert cam._ctx().scene.ngeom < 255  # noqa: SLF001  (the red byte holds every id)
        with monkeypatch.context() as mp:  # "green or blue seen": the three-byte sum
            mp.setattr(cv2, "countNonZero", lambda _: 1)
            summed = cam._segmentation_pass()  # noqa: SLF001
    for a, b in zip(fast, summed, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    labels = fast[0]
    assert (labels == LABEL_ROBOT).sum() > 500 and {0, 1, 2, 3} <= set(np.unique(labels).tolist())


def test_mesh_look_labels_what_is_drawn():
    """``robot.visual="mesh"``: the labels come from the drawn meshes (the segmentation pass
    sees the very surfaces of the colour pass, so its depth equals the image's depth), not from
    the hidden collision primitives; with the arm parked, every pixel off the arm is the same
    as with the primitive look (same clip planes and lighting), and the parked mesh shoulder
    is the only robot in view."""
    import mujoco

    from cablesim.panda.model import HOME_QPOS, joint_qpos_addresses

    snaps = {}
    for visual in ("primitive", "mesh"):
        # the two looks share one settled state (same physics)
        cfg = SceneConfig(
            seed=0, camera=CameraConfig(width=W, height=H), robot=RobotConfig(visual=visual)
        )
        world = World.build(cfg)
        with SimCamera(world) as cam:
            parked = cam.snapshot()
            world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = HOME_QPOS
            mujoco.mj_forward(world.model, world.data)
            home = cam.snapshot()
            bodies = cam.robot_bodies
        snaps[visual] = parked, home
        for s in (parked, home):
            assert np.array_equal(s.depth, s.image.depth)
            robot = s.labels == LABEL_ROBOT
            assert np.array_equal(robot, np.isin(s.body, bodies))
    (p_park, p_home), (m_park, m_home) = snaps["primitive"], snaps["mesh"]
    off_arm = (m_park.labels != LABEL_ROBOT) & (p_park.labels != LABEL_ROBOT)
    assert np.array_equal(p_park.rgb[off_arm], m_park.rgb[off_arm])
    assert np.array_equal(p_park.image.depth[off_arm], m_park.image.depth[off_arm])
    assert (p_park.labels == LABEL_ROBOT).sum() == 0
    parked_arm = np.flatnonzero((m_park.labels == LABEL_ROBOT).any(axis=0))
    assert parked_arm.size == 0 or parked_arm.min() > 0.9 * W  # the shoulder at the right edge
    p_robot, m_robot = p_home.labels == LABEL_ROBOT, m_home.labels == LABEL_ROBOT
    assert m_robot.sum() > 500 and not np.array_equal(p_robot, m_robot)
    assert (p_robot & m_robot).sum() / (p_robot | m_robot).sum() > 0.6


def test_layered_rendering_gives_the_pixels_of_a_full_render():
    """The background layer (world-welded geoms and sky, rendered once) under the moving layer
    (hoses, robot) is the full render bit for bit: parked arm, arm in view, a pulled hose, and
    after the camera was moved (the cached background must follow it)."""
    import mujoco

    from cablesim.panda.model import HOME_QPOS, joint_qpos_addresses

    world = World.build(
        SceneConfig(seed=0, camera=CameraConfig(width=160, height=120), robot=RobotConfig())
    )
    with SimCamera(world) as layered, SimCamera(world, layered=False) as full:
        assert layered.layered and not full.layered

        def same() -> None:
            a, b = layered.snapshot(), full.snapshot()
            for name in ("rgb", "depth", "labels", "body"):
                assert np.array_equal(getattr(a, name), getattr(b, name)), name
            c, d = layered.capture(), full.capture()
            assert np.array_equal(c.rgb, d.rgb) and np.array_equal(c.depth, d.depth)
            # a snapshot's image without its label pass (capture.truth_every)
            for img in (layered.capture_unlabelled(), full.capture_unlabelled()):
                assert np.array_equal(img.rgb, a.image.rgb)
                assert np.array_equal(img.depth, a.image.depth)

        same()
        world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = HOME_QPOS
        mujoco.mj_forward(world.model, world.data)
        assert (layered.render_labels() == LABEL_ROBOT).sum() > 100
        same()
        world.data.xfrc_applied[int(world.hoses[0].vertex_bodies[8]), :3] = [0.0, 0.4, 0.1]
        world.step(50)
        same()
        world.model.cam_pos[world.camera_id] += [0.0, 0.05, 0.02]
        mujoco.mj_forward(world.model, world.data)
        same()
    # multisampling blends the layers at their edges: such a camera renders in one pass
    with SimCamera(world, antialias_samples=4) as aa:
        assert not aa.layered


def test_coarser_sphere_caps_change_almost_no_pixel(world: World):
    """8 stacks per sphere (the default, for speed) instead of MuJoCo's 16: the hoses' capsule
    caps hide inside the neighbouring edges, so only a few pixels at hose ends change."""

    with SimCamera(world) as cam:
        coarse = cam.snapshot()
    scene = world.cfg
    world.cfg = scene.replace(camera=scene.camera.replace(sphere_stacks=16))
    try:
        with SimCamera(world) as cam:
            fine = cam.snapshot()
    finally:
        world.cfg = scene
    assert world.model.vis.quality.numstacks == 16  # the model's own setting is kept
    labels = coarse.labels != fine.labels
    changed = np.abs(coarse.rgb.astype(int) - fine.rgb.astype(int)).max(-1) > 0
    print(f"{changed.sum()} pixels and {labels.sum()} labels of {changed.size} changed")
    assert changed.any()  # the setting is in effect
    assert changed.mean() < 1e-3 and labels.mean() < 2e-4


def test_unlabelled_capture_is_a_snapshots_image_with_patterns_and_the_arm():
    """Striped cables (pattern geoms added to every pass) with the arm in view: the image of
    ``capture_unlabelled`` is the snapshot's, colour and depth (0 where the sky is), bit for
    bit."""
    import mujoco

    from cablesim.panda.model import HOME_QPOS, joint_qpos_addresses
    from cablesim.sim.config import HoseConfig

    cfg = SceneConfig(
        seed=1,
        camera=CameraConfig(width=160, height=120),
        hoses=HoseConfig(pattern="stripes"),
        robot=RobotConfig(),
    )
    world = World.build(cfg)
    world.data.qpos[joint_qpos_addresses(world.model, world.panda.joints)] = HOME_QPOS
    mujoco.mj_forward(world.model, world.data)
    with SimCamera(world) as cam:
        assert cam.layered
        for _ in range(3):
            world.step(20)
            img, snap = cam.capture_unlabelled(), cam.snapshot()
            assert (snap.labels == LABEL_ROBOT).sum() > 100
            assert np.array_equal(img.rgb, snap.image.rgb)
            assert np.array_equal(img.depth, snap.image.depth)
            assert (img.depth == 0).any()  # the sky: nothing hit
