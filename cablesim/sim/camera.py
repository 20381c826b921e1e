"""The simulated RGB-D camera: offscreen MuJoCo rendering of the world's fixed "rgbd" camera.

    cam = SimCamera(world)                 # one renderer, reused
    img = cam.capture()                    # CameraImage: rgb uint8, metric z-depth float32
    snap = cam.snapshot()                  # + labels and what ground-truth flow needs later
    img = cam.capture_unlabelled()         # snap.image, bit for bit, without the label pass
    cam.close()

Depth is the z-depth along the optical axis in metres (what OpenGL's depth buffer holds,
linearised), 0 where nothing was hit.  Labels come from MuJoCo's segmentation rendering: a
hose is a flex (one label per hose: its index), a robot pixel is any geom whose body descends
from the robot root body (``panda/link0``), everything else is background.  RGB and depth
come from one render pass, labels from a second one.

The camera is fixed, so what is welded to the world (board, table, connectors, the sky) looks
the same in every frame: it is rendered once per camera (the background layers, colour and
segmentation), and each pass draws only what can move (hoses, robot) and takes, per pixel, the
nearer of the two layers by their depth buffers.  Where no geometry affects how other geometry
looks (opaque materials, lights fixed to the world, no shadows, reflections or multisampling)
this gives the very pixels, labels and depths of a full render, bit for bit, for about a third
less work per pass; otherwise every pass is a full render.  A snapshot's label pass draws the
scene its colour pass built.

The optional depth noise (``cfg.camera.depth_noise``) is RealSense-like: with
``depth_model = "gaussian"`` Gaussian with sigma = k z^2, 1 mm quantisation, and dropped
pixels (0) at depth discontinuities; with ``"stereo"`` the block-matching model of
:mod:`cablesim.sim.sensor` (correlated disparity error, edges fattened or eroded).  The
optional RGB sensor model (``cfg.camera.rgb_noise``: shot and read noise, exposure and gain,
:func:`cablesim.sim.sensor.rgb_sensor`) applies to the colour image.  Each is drawn from the
seed's own stream (``depth_noise``, ``rgb_noise``: :mod:`cablesim.seeding`), so a camera
created for the same seed produces the same noise sequence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import cv2
import mujoco
import numpy as np

from cablesim.cables import pattern_color
from cablesim.camera.base import Camera, CameraImage
from cablesim.errors import InputError
from cablesim.frames import LABEL_BACKGROUND, LABEL_ROBOT, Intrinsics
from cablesim.seeding import stream
from cablesim.sim.patterns import (
    add_pattern_geoms,
    fallback_frames,
    pattern_geom_bound,
    pattern_pieces,
)
from cablesim.sim.sensor import rgb_sensor, stereo_depth

if TYPE_CHECKING:
    from cablesim.sim.world import World

ROBOT_ROOT = "panda/link0"
DEPTH_EDGE_JUMP = 0.02  # m: a neighbour this much nearer or farther makes a pixel an edge
DEPTH_EDGE_DROPOUT = 0.5  # probability that a noisy camera returns nothing at an edge
DEPTH_QUANTUM = 0.001  # m


def intrinsics_from_fovy(width: int, height: int, fovy_deg: float) -> Intrinsics:
    """Pinhole intrinsics of a MuJoCo camera (square pixels, principal point at the centre;
    pixel (0, 0) is the centre of the top-left pixel)."""
    if width <= 0 or height <= 0:
        raise InputError(f"image size must be positive, got {width}x{height}")
    if not 0 < fovy_deg < 180:
        raise InputError(f"fovy must be in (0, 180) degrees, got {fovy_deg}")
    f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2)
    return Intrinsics(f, f, (width - 1) / 2, (height - 1) / 2, int(width), int(height))


def _camera_option() -> mujoco.MjvOption:
    """What the camera sees: geoms and flexes of the default groups, no sites or tendons."""
    option = mujoco.MjvOption()
    option.sitegroup[:] = 0  # sites and tendons are not things a camera sees
    option.flags[mujoco.mjtVisFlag.mjVIS_TENDON] = False
    return option


def robot_body_ids(model: mujoco.MjModel, root: str = ROBOT_ROOT) -> np.ndarray:
    """Ids of ``root`` and all its descendant bodies (empty if there is no such body)."""
    rid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, root)
    if rid < 0:
        return np.zeros(0, np.int32)
    inside = np.zeros(model.nbody, bool)
    inside[rid] = True
    for b in range(rid + 1, model.nbody):  # parents always come before their children
        inside[b] = inside[model.body_parentid[b]]
    return np.flatnonzero(inside).astype(np.int32)


@dataclass(eq=False)
class SimSnapshot:
    """Everything ground truth needs about one rendered frame, so that flow between any two
    frames can be computed after the fact (``cablesim.sim.flow_gt.gt_flow``).

    ``depth`` is noise-free; ``image`` is what the camera returned (with noise if enabled).
    ``body`` holds, per pixel, the body id of the geom seen there (-1 for hoses and empty
    pixels); ``body_pos``/``body_mat`` are the world poses of all bodies.
    """

    time: float
    intrinsics: Intrinsics
    T_world_camera: np.ndarray  # 4x4
    image: CameraImage
    depth: np.ndarray  # HxW float32, noise-free metric z-depth, 0 = nothing
    labels: np.ndarray  # HxW int16
    body: np.ndarray  # HxW int32
    hose_vertices: tuple[np.ndarray, ...]  # per hose (V, 3) world
    hose_twist: tuple[np.ndarray, ...]  # per hose (V - 1,) twist hinge angles, radians
    hose_radius: tuple[float, ...]  # per hose, m
    body_pos: np.ndarray  # (nbody, 3)
    body_mat: np.ndarray  # (nbody, 3, 3)
    meta: dict[str, Any] = field(default_factory=dict)
    # per hose (V - 1, 3, 3) material frames of the edges (columns: tangent, m1, m2) from
    # MuJoCo's rod state, or None where it has none (see SimCamera._material_frames)
    hose_frames: tuple[np.ndarray | None, ...] = ()

    @property
    def rgb(self) -> np.ndarray:
        return self.image.rgb

    @property
    def shape(self) -> tuple[int, int]:
        return self.labels.shape  # type: ignore[return-value]


class SimCamera(Camera):
    """Renders ``world``'s fixed camera offscreen.  Size defaults to ``world.cfg.camera``."""

    def __init__(
        self,
        world: World,
        width: int | None = None,
        height: int | None = None,
        depth_noise: bool | None = None,
        robot_root: str = ROBOT_ROOT,
        antialias_samples: int = 0,
        layered: bool = True,
    ):
        c = world.cfg.camera
        self.world = world
        self.width = int(c.width if width is None else width)
        self.height = int(c.height if height is None else height)
        m = world.model
        if not (
            0 < self.width <= m.vis.global_.offwidth and 0 < self.height <= m.vis.global_.offheight
        ):
            raise InputError(
                f"image size {self.width}x{self.height} is outside 1x1 .. "
                f"{m.vis.global_.offwidth}x{m.vis.global_.offheight} (the model's framebuffer)"
            )
        self.depth_noise = bool(c.depth_noise if depth_noise is None else depth_noise)
        self._noise_std_per_m2 = float(c.depth_noise_std_per_m2)
        self._rng = stream(world.cfg.seed, "depth_noise")
        self.rgb_noise = bool(c.rgb_noise)
        self._rgb_rng = stream(world.cfg.seed, "rgb_noise")
        self._camera_cfg = c
        fovy = float(m.cam_fovy[world.camera_id])
        self._intrinsics = intrinsics_from_fovy(self.width, self.height, fovy)
        # multisampling costs 2-3x on software OpenGL and blurs label boundaries: off by
        # default; sphere and capsule-cap tessellation from the camera config (the model's
        # settings are restored once the renderer exists, which keeps the tessellation)
        samples, stacks = m.vis.quality.offsamples, m.vis.quality.numstacks
        m.vis.quality.offsamples = int(antialias_samples)
        m.vis.quality.numstacks = int(c.sphere_stacks)
        try:
            self._renderer: mujoco.Renderer | None = mujoco.Renderer(
                m,
                self.height,
                self.width,
                max_geom=10000 + sum(pattern_geom_bound(h.spec) for h in world.hoses),
            )
        finally:
            m.vis.quality.offsamples, m.vis.quality.numstacks = samples, stacks
        self._option = _camera_option()
        self._antialias = int(antialias_samples)
        self._layers = self._layer_options() if layered else None
        self._background: tuple[bytes, np.ndarray, np.ndarray] | None = None
        self._background_seg: tuple[bytes, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._near = float(m.vis.map.znear * m.stat.extent)
        self._far = float(m.vis.map.zfar * m.stat.extent)
        # label lookup tables: geom id -> label / body; flex id -> hose index
        self.robot_bodies = robot_body_ids(m, robot_root)
        is_robot = np.zeros(m.nbody, bool)
        is_robot[self.robot_bodies] = True
        self._geom_label = np.where(is_robot[m.geom_bodyid], LABEL_ROBOT, LABEL_BACKGROUND)
        self._flex_label = np.full(max(m.nflex, 1), LABEL_BACKGROUND, np.int16)
        for i, h in enumerate(world.hoses):
            self._flex_label[h.flex_id] = i
        self._twist_qpos = [self._twist_addresses(h) for h in world.hoses]
        self._patterned = any(h.spec.cable.pattern != "solid" for h in world.hoses)

    # ------------------------------------------------------------------ interface
    @property
    def layered(self) -> bool:
        """Whether colour passes draw the moving layer over a cached background layer (exactly
        the pixels of a full render; see the module docstring)."""
        return self._layers is not None

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    @property
    def T_world_camera(self) -> np.ndarray:
        return self.world.T_world_camera.copy()

    def capture(self) -> CameraImage:
        rgb, depth = self._render_rgbd()
        assert depth is not None
        return self._image(rgb, depth)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------ sim only
    def render_labels(self) -> np.ndarray:
        """HxW int16 labels of the current state (hose index, LABEL_ROBOT, LABEL_BACKGROUND)."""
        return self._render_segmentation()[0]

    def snapshot(self, **meta: Any) -> SimSnapshot:
        """Render RGB, depth and labels of the current state and record the rod and body
        state, so ground-truth flow to or from any other snapshot can be computed later."""
        rgb, _ = self._render_rgbd(depth=False)  # the label pass's depth is the one kept
        # layered, the colour pass built the moving layer's scene: the label pass draws it too
        labels, body, depth = self._render_segmentation(update=self._layers is None)
        return self._snapshot(self._image(rgb, depth), labels, body, depth, meta)

    def capture_unlabelled(self) -> CameraImage:
        """The image :meth:`snapshot` would give of the current state (its depth: 0 where
        nothing is hit, the sky included, as the label pass leaves it), without the label pass
        where the camera is layered: the colour pass's depth over the background segmentation
        pass's, which is the label pass's depth bit for bit.  Not layered: a snapshot's image.
        It draws the same noise as a snapshot (one image of each stream)."""
        if self._layers is None:
            return self.snapshot().image
        bg_rgb, bg_raw = self._background_layer()
        seg_raw = self._background_segmentation()[2]
        rgb, raw = self._moving_layer()
        cv2.copyTo(bg_rgb, _behind(raw, bg_raw), rgb)
        cv2.copyTo(seg_raw, _behind(raw, seg_raw), raw)
        return self._image(cv2.flip(rgb, 0), self._metric_depth(raw))

    def snapshot_of(self, image: CameraImage, **meta: Any) -> SimSnapshot:
        """The snapshot of the current state for an ``image`` already captured in it (only the
        labels are rendered)."""
        labels, body, depth = self._render_segmentation()
        return self._snapshot(image, labels, body, depth, meta)

    def _snapshot(
        self,
        image: CameraImage,
        labels: np.ndarray,
        body: np.ndarray,
        depth: np.ndarray,
        meta: dict[str, Any],
    ) -> SimSnapshot:
        d = self.world.data
        verts = tuple(self.world.hose_vertices(i) for i in range(len(self.world.hoses)))
        twist = tuple(d.qpos[adr].copy() for adr in self._twist_qpos)
        return SimSnapshot(
            time=float(d.time),
            intrinsics=self._intrinsics,
            T_world_camera=self.world.T_world_camera.copy(),
            image=image,
            depth=depth,
            labels=labels,
            body=body,
            hose_vertices=verts,
            hose_twist=twist,
            hose_radius=tuple(float(h.spec.radius) for h in self.world.hoses),
            body_pos=d.xpos.copy(),
            body_mat=d.xmat.reshape(-1, 3, 3).copy(),
            meta=dict(meta),
            hose_frames=tuple(
                self._material_frames(h, v, t)
                for h, v, t in zip(self.world.hoses, verts, twist, strict=True)
            ),
        )

    def _material_frames(self, hose: Any, verts: np.ndarray, twist: np.ndarray) -> Any:
        """(E, 3, 3) material frames of a hose's edges (columns: tangent, m1, m2): MuJoCo's
        time-parallel reference frame of each edge (``u_old`` in ``data.plastic``) turned by
        the edge's twist angle right-handedly about the tangent (vertex k -> k + 1), the
        convention MuJoCo draws box-section rods with (tests/sim/test_flow_gt_twist.py).  None
        when the rod has no such state or it is stale (vertices moved without a physics step:
        the stored tangents differ from the current ones)."""
        m, d = self.world.model, self.world.data
        n = len(verts) - 1
        adr = int(m.flex_plasticadr[hose.flex_id])
        if adr < 0 or len(twist) != n or adr + 6 * n > d.plastic.shape[0]:
            return None
        ref = d.plastic[adr : adr + 6 * n].reshape(n, 6)
        t = verts[1:] - verts[:-1]
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-18)
        u = ref[:, 3:] - np.einsum("ij,ij->i", ref[:, 3:], t)[:, None] * t
        norm = np.linalg.norm(u, axis=1)
        if np.any(np.abs(np.einsum("ij,ij->i", ref[:, :3], t)) < 1 - 1e-9) or np.any(norm < 0.5):
            return None
        u /= norm[:, None]
        m1 = np.cos(twist)[:, None] * u + np.sin(twist)[:, None] * np.cross(t, u)
        return np.stack([t, m1, np.cross(t, m1)], axis=2)

    # ------------------------------------------------------------------ internals
    def _twist_addresses(self, hose: Any) -> np.ndarray:
        """qpos address of each edge's twist hinge: bodies ``{hose}_twist_{k}`` (MuJoCo names
        the last one ``{hose}_twist``), in body order; empty if the flex has no twist dofs."""
        m = self.world.model
        prefix = f"{hose.spec.name}_twist"
        bodies = [
            b
            for b in range(m.nbody)
            if (name := m.body(b).name) == prefix or name.startswith(prefix + "_")
        ]
        if len(bodies) != hose.n_vertices - 1 or any(m.body_jntnum[b] != 1 for b in bodies):
            return np.zeros(0, np.int64)  # another flex dof type: report zero twist
        return np.array([m.jnt_qposadr[m.body_jntadr[b]] for b in bodies], np.int64)

    def _ctx(self) -> mujoco.Renderer:
        if self._renderer is None:
            raise InputError("the camera was closed")
        return self._renderer

    def _update_scene(self, option: mujoco.MjvOption | None = None) -> None:
        option = self._option if option is None else option
        r = self._ctx()
        r.update_scene(self.world.data, self.world.camera_id, option)
        if self._patterned:
            self._add_patterns(r.scene, option)

    def _add_patterns(self, scene: mujoco.MjvScene, option: mujoco.MjvOption) -> None:
        """Append the pattern geoms of every patterned cable the option draws (its flex's
        group is on), in the edges' material frames (:mod:`cablesim.sim.patterns`)."""
        m, d = self.world.model, self.world.data
        for i, h in enumerate(self.world.hoses):
            c = h.spec.cable
            if c.pattern == "solid" or not option.flexgroup[m.flex_group[h.flex_id]]:
                continue
            verts = self.world.hose_vertices(i)
            twist = d.qpos[self._twist_qpos[i]]
            frames = self._material_frames(h, verts, twist)
            if frames is None:
                frames = fallback_frames(verts, twist)
            rest = h.spec.length / (h.spec.n_vertices - 1)
            pieces = pattern_pieces(c.pattern, verts, frames, c.radius, rest, c.pattern_period)
            if pieces is not None:
                rgb = pattern_color(c.pattern, h.spec.rgb, c.pattern_color)
                add_pattern_geoms(scene, pieces, rgb, h.flex_id)

    def _render_rgbd(self, depth: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """RGB and (unless ``depth`` is False) metric depth of the current state, from one
        full render pass or from the moving layer over the cached background layer."""
        if self._layers is None:
            self._update_scene()
            rgb, raw = self._render_raw()
        else:
            bg_rgb, bg_raw = self._background_layer()
            rgb, raw = self._moving_layer()
            back = _behind(raw, bg_raw)
            cv2.copyTo(bg_rgb, back, rgb)
            if depth:
                cv2.copyTo(bg_raw, back, raw)
        return cv2.flip(rgb, 0), self._metric_depth(raw) if depth else None

    def _moving_layer(self) -> tuple[np.ndarray, np.ndarray]:
        """Colour and raw depth (bottom row first) of the moving layer's colour pass of the
        current state, without the sky (it is background)."""
        assert self._layers is not None
        self._update_scene(self._layers[1])
        scene = self._ctx().scene
        sky = scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX]
        scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
        try:
            return self._render_raw()
        finally:
            scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = sky

    def _render_raw(self) -> tuple[np.ndarray, np.ndarray]:
        """Render the current scene; colour and raw depth buffer of that same pass, bottom
        row first (OpenGL's order)."""
        r = self._ctx()
        # The public Renderer API renders once per output; mujoco is pinned (4.0.0), so read
        # colour and depth of one pass through its context (readDepthMap = ZEROFAR).
        if r._gl_context is not None:  # noqa: SLF001
            r._gl_context.make_current()  # noqa: SLF001
        rect = mujoco.MjrRect(0, 0, self.width, self.height)
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        raw = np.empty((self.height, self.width), np.float32)
        mujoco.mjr_render(rect, r.scene, r._mjr_context)  # noqa: SLF001
        mujoco.mjr_readPixels(rgb, raw, rect, r._mjr_context)  # noqa: SLF001
        return rgb, raw

    def _metric_depth(self, raw: np.ndarray) -> np.ndarray:
        """Raw (bottom-up) depth buffer -> metric z-depth, top row first, 0 = nothing."""
        n, f = self._near, self._far
        raw = raw[::-1]
        # reversed-z depth buffer (1 = near, 0 = far) -> eye-space z: n f / ((f - n) raw + n)
        z = raw.astype(np.float64)
        z *= f - n
        z += n
        np.divide(n * f, z, out=z)
        depth = z.astype(np.float32)
        depth[raw <= 0] = 0.0
        return depth

    def _layer_options(self) -> tuple[mujoco.MjvOption, mujoco.MjvOption] | None:
        """Visual options that draw only the world-welded geoms (the background layer) and
        only everything else (the moving layer), or None where the two layers would not
        composite exactly into a full render (see the module docstring)."""
        m = self.world.model
        if self._antialias > 0 or m.nskin > 0 or (m.mat_reflectance > 0).any():
            return None
        if m.vis.quality.shadowsize > 0 and m.light_castshadow.any():
            return None
        if (m.body_weldid[m.light_bodyid] != 0).any():
            return None  # a light that moves changes how the background looks
        opaque = (m.geom_rgba[:, 3] >= 1).all() and (m.flex_rgba[:, 3] >= 1).all()
        if not opaque or (m.mat_rgba[:, 3] < 1).any():
            return None
        # options select geoms by group: a group with any geom that can move is drawn in
        # every moving layer (with its fixed geoms, e.g. the robot's base); the others once
        static = m.body_weldid[m.geom_bodyid] == 0
        moving_groups = {int(g) for g in m.geom_group[~static]}
        background, moving = _camera_option(), _camera_option()
        for g in range(len(background.geomgroup)):
            if g in moving_groups:
                background.geomgroup[g] = 0
            else:
                moving.geomgroup[g] = 0
        background.flexgroup[:] = 0  # flexes move (their vertices are bodies)
        return background, moving

    def _background_layer(self) -> tuple[np.ndarray, np.ndarray]:
        """Colour and raw depth of the world-welded geoms and the sky, rendered once per
        camera pose (and again if a fixed geom or the camera was moved)."""
        assert self._layers is not None
        key = self._background_key()
        if self._background is None or self._background[0] != key:
            self._update_scene(self._layers[0])
            rgb, raw = self._render_raw()
            self._background = (key, rgb, raw)
        return self._background[1], self._background[2]

    def _background_segmentation(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Labels, body ids and raw depth (bottom row first) of the background layer's
        segmentation pass, rendered once per camera pose like its colour."""
        assert self._layers is not None
        key = self._background_key()
        if self._background_seg is None or self._background_seg[0] != key:
            self._update_scene(self._layers[0])
            self._background_seg = (key, *self._segmentation_pass())
        return self._background_seg[1:]

    def _background_key(self) -> bytes:
        """What the background layers depend on: the camera pose and the fixed geoms' poses
        and colours."""
        d, m = self.world.data, self.world.model
        static = m.body_weldid[m.geom_bodyid] == 0
        cam = self.world.camera_id
        return b"".join(
            np.ascontiguousarray(a).tobytes()
            for a in (
                d.cam_xpos[cam],
                d.cam_xmat[cam],
                d.geom_xpos[static],
                d.geom_xmat[static],
                m.geom_rgba[static],
            )
        )

    def _render_segmentation(
        self, update: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(labels int16, body id int32, depth float32) per pixel of the current state, top
        row first, from one segmentation pass (layered: of the moving layer over the cached
        background layer's); its depth matches the labels pixel for pixel.  ``update=False``
        draws the scene as the last pass left it (the same state and layer)."""
        if update:
            self._update_scene(None if self._layers is None else self._layers[1])
        labels, body, raw = self._segmentation_pass()
        if self._layers is not None:
            bg_labels, bg_body, bg_raw = self._background_segmentation()
            back = _behind(raw, bg_raw)
            cv2.copyTo(bg_labels, back, labels)
            cv2.copyTo(bg_body, back, body)
            cv2.copyTo(bg_raw, back, raw)
        return cv2.flip(labels, 0), cv2.flip(body, 0), self._metric_depth(raw)

    def _segmentation_pass(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(labels, body ids, raw depth), bottom row first, of one segmentation pass of the
        scene as it is."""
        r = self._ctx()
        scene = r.scene
        flags = scene.flags.copy()
        scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        try:
            rgb, raw = self._render_raw()
        finally:
            np.copyto(scene.flags, flags)
        # segid - 1 indexes the scene's geoms (0 = nothing); MuJoCo writes segid + 1 as
        # (red, green, blue) = its bytes, low first
        n = scene.ngeom
        objtype = np.full(n + 1, -1, np.int64)
        objid = np.full(n + 1, -1, np.int64)
        for g in scene.geoms[:n]:
            if g.segid >= 0:
                objtype[g.segid + 1], objid[g.segid + 1] = g.objtype, g.objid
        m = self.world.model
        lut_label = np.full(n + 1, LABEL_BACKGROUND, np.int16)
        lut_body = np.full(n + 1, -1, np.int32)
        geom = objtype == int(mujoco.mjtObj.mjOBJ_GEOM)
        lut_label[geom] = self._geom_label[objid[geom]]
        lut_body[geom] = m.geom_bodyid[objid[geom]]
        flex = objtype == int(mujoco.mjtObj.mjOBJ_FLEX)
        lut_label[flex] = self._flex_label[objid[flex]]
        if (
            n < 255
            and cv2.countNonZero(cv2.extractChannel(rgb, 1)) == 0
            and cv2.countNonZero(cv2.extractChannel(rgb, 2)) == 0
        ):
            # every id fits the red byte (the usual scene: a few dozen geoms): look the red
            # byte up in tables of 256 entries (an id past n reads entry n, as the clip below
            # makes it), the same labels and bodies as the three-byte sum at a fifth of the
            # cost (2 ms of a 640x480 label pass)
            red = cv2.extractChannel(rgb, 0)
            pad = 255 - n
            lut_label = np.concatenate([lut_label, np.full(pad, lut_label[n], np.int16)])
            lut_body = np.concatenate([lut_body, np.full(pad, lut_body[n], np.int32)])
            return cv2.LUT(red, lut_label), cv2.LUT(red, lut_body), raw
        segid = (
            rgb[..., 0].astype(np.int32)
            | (rgb[..., 1].astype(np.int32) << 8)
            | (rgb[..., 2].astype(np.int32) << 16)
        )
        segid = np.clip(segid, 0, n)
        return lut_label[segid], lut_body[segid], raw

    def _image(self, rgb: np.ndarray, depth: np.ndarray) -> CameraImage:
        if self.rgb_noise:
            rgb = rgb_sensor(rgb, self._camera_cfg.rgb_sensor, self._rgb_rng)
        if self.depth_noise and self._camera_cfg.depth_model == "stereo":
            depth = stereo_depth(
                depth, self._camera_cfg.depth_stereo, self._intrinsics.f, self._rng
            )
        elif self.depth_noise:
            depth = self._noisy(depth)
        return CameraImage(rgb, depth, float(self.world.data.time), self._intrinsics)

    def _noisy(self, depth: np.ndarray) -> np.ndarray:
        rng = self._rng
        z = depth.astype(np.float64)
        valid = z > 0
        noisy = z + rng.standard_normal(z.shape) * self._noise_std_per_m2 * z * z
        noisy = np.round(noisy / DEPTH_QUANTUM) * DEPTH_QUANTUM
        pad = np.pad(z, 1, mode="edge")
        h, w = z.shape
        jump = np.zeros(z.shape, bool)
        for dy, dx in ((0, 1), (2, 1), (1, 0), (1, 2)):
            jump |= np.abs(pad[dy : dy + h, dx : dx + w] - z) > DEPTH_EDGE_JUMP
        drop = jump & (rng.random(z.shape) < DEPTH_EDGE_DROPOUT)
        out = np.where(valid & ~drop & (noisy > 0), noisy, 0.0)
        return out.astype(np.float32)


def _behind(raw: np.ndarray, bg_raw: np.ndarray) -> np.ndarray:
    """The pixels (a uint8 mask for ``cv2.copyTo``) where the background layer shows: the
    moving layer is not nearer there.  Reversed z: the larger value is nearer; an empty pixel
    (0) shows the background."""
    return (raw <= bg_raw).view(np.uint8)
