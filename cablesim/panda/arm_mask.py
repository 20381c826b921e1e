"""Arm masks from kinematics: the Panda model rendered at a joint state through a calibrated
camera (issue 8: "the Panda model rendered at the measured joint state through the calibrated
camera gives a per-frame arm mask, by the same code in simulation and on the real robot").

    masker = ArmMasker(intrinsics, T_world_camera, T_world_base, margin=3)
    masker = ArmMasker.for_robot(robot, camera, margin=3)     # SimPanda / FrankyPanda
    mask = masker(q, opening)                 # HxW bool, True where the arm is
    collector = FrameCollector(T, arm_mask=masker.for_tick)   # one mask per kept frame

This is kinematics rendering, not the simulator: a small model holding only the arm
(:func:`cablesim.panda.model.attach_panda` at the base pose, no scene) is put at the joint
angles and finger opening and rendered with MuJoCo's segmentation rendering; every pixel that
shows one of its geoms is arm.  Nothing occludes the arm in that model, so the mask also covers
arm parts hidden behind a hose; what the mask does not know (a real arm's outline differs from
the primitive model's by millimetres, the joint state lags the image by the clock's skew) is what
``margin`` (pixels of dilation) is for.

Camera model.  ``intrinsics`` are OpenCV pinhole intrinsics (pixel (0, 0) is the centre of the
top-left pixel; ``fx != fy`` and an off-centre principal point allowed) and ``T_world_camera``
has OpenCV axes (x right, y down, z forward).  A MuJoCo model camera has one ``fovy`` and a
centred principal point, so the renderer's OpenGL camera is set directly: position, forward =
OpenCV +z, up = OpenCV -y, and an asymmetric frustum whose edges are the image borders
(``u = -0.5`` and ``u = W - 0.5``, ``v = -0.5`` and ``v = H - 0.5``) at the near plane.  MuJoCo's
``frustum_width`` is the frustum's *half* width (measured: the projection of points matches the
pinhole model to 0.05 px with it; see ``tests/robot/test_arm_mask.py``).

Threads.  A masker may be called from any thread (a real camera's frames arrive on a capture
thread): its OpenGL work runs on one private thread, calls are serialised.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import cv2
import mujoco
import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Intrinsics
from cablesim.panda.description import FINGER_RANGE
from cablesim.panda.model import attach_panda, joint_qpos_addresses, robot_body_ids
from cablesim.pose import Pose

PREFIX = "mask/"
NEAR = 0.02  # m, near clipping plane of the mask camera
FAR = 20.0  # m


def _matrix(T: Any, what: str) -> np.ndarray:
    if isinstance(T, Pose):
        return T.matrix()
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise InputError(f"{what} must be a finite 4x4 matrix (or a Pose), got shape {M.shape}")
    R = M[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
        raise InputError(f"{what} has no rotation in its upper-left 3x3 block")
    return M


class ArmMasker:
    """Renders HxW bool masks of the Panda at given joint states (module docstring).

    ``intrinsics``: the camera's; ``T_world_camera``: 4x4, OpenCV axes; ``T_world_base``: the
    robot base in the world (4x4 or a :class:`Pose`; identity when the world is the base frame);
    ``margin``: default dilation in pixels.
    """

    def __init__(
        self,
        intrinsics: Intrinsics,
        T_world_camera: Any,
        T_world_base: Any = None,
        margin: int = 0,
    ) -> None:
        if not isinstance(intrinsics, Intrinsics):
            raise InputError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")
        if margin < 0:
            raise InputError(f"margin must be >= 0 pixels, got {margin}")
        self.intrinsics = intrinsics
        self.margin = int(margin)
        self.T_world_camera = _matrix(T_world_camera, "T_world_camera")
        base = Pose.from_matrix(
            np.eye(4) if T_world_base is None else _matrix(T_world_base, "T_world_base")
        )
        self.T_world_base = base.matrix()
        w, h = int(intrinsics.width), int(intrinsics.height)
        spec = mujoco.MjSpec()
        spec.visual.global_.offwidth = w
        spec.visual.global_.offheight = h
        self.names = attach_panda(spec, base.position, base.quaternion, prefix=PREFIX)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._arm_qadr = joint_qpos_addresses(m, self.names.joints)
        self._finger_qadr = joint_qpos_addresses(m, self.names.finger_joints)
        is_arm = np.zeros(m.ngeom, bool)
        is_arm[np.isin(m.geom_bodyid, robot_body_ids(m, PREFIX))] = True
        self._is_arm_geom = is_arm
        # An OpenGL context is current in one thread at a time (EGL refuses another: a real
        # camera's frames arrive on a capture thread), so one private thread does all the GL
        # work: it creates the renderer, renders every mask and frees it.
        self._gl = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cablesim-arm-mask")
        self._lock = threading.Lock()
        self._renderer: mujoco.Renderer | None = self._gl.submit(self._new_renderer, h, w).result()
        self._option = mujoco.MjvOption()
        self._option.sitegroup[:] = 0
        self._option.flags[mujoco.mjtVisFlag.mjVIS_TENDON] = False
        self._option.geomgroup[:] = 1  # every geom of the arm, whatever its group

    @classmethod
    def for_robot(cls, robot: Any, camera: Any, margin: int = 0) -> ArmMasker:
        """The masker of a robot of the ``Robot`` interface that checks motions on an arm-only
        model (``SimPanda``, ``FrankyPanda``: its ``arm.base`` is the base pose in the world)
        seen by ``camera`` (its ``T_world_camera``, else the robot's)."""
        arm = getattr(robot, "arm", None)
        base = getattr(arm, "base", None)
        if not isinstance(base, Pose):
            raise InputError(f"{type(robot).__name__} has no arm model with a base pose")
        T = camera.T_world_camera
        return cls(camera.intrinsics, robot.T_world_camera if T is None else T, base, margin)

    # ------------------------------------------------------------------ rendering
    def __call__(
        self, joints: Sequence[float], opening: float, margin: int | None = None
    ) -> np.ndarray:
        """HxW bool mask of the arm at arm joints ``joints`` (7,) and finger ``opening`` (m),
        dilated by ``margin`` pixels (default: the masker's)."""
        q = np.asarray(joints, dtype=float).reshape(-1)
        if q.shape != (7,) or not np.isfinite(q).all():
            raise InputError(f"joints must be 7 finite angles, got {np.asarray(joints).shape}")
        if not np.isfinite(opening):
            raise InputError(f"opening must be finite, got {opening!r}")
        margin = self.margin if margin is None else int(margin)
        if margin < 0:
            raise InputError(f"margin must be >= 0 pixels, got {margin}")
        with self._lock:
            if self._renderer is None:
                raise InputError("the arm masker was closed")
            mask = self._gl.submit(self._render, q, float(opening)).result()
        return dilate(mask, margin)

    def _new_renderer(self, height: int, width: int) -> mujoco.Renderer:
        r = mujoco.Renderer(self.model, height, width)
        r.enable_segmentation_rendering()
        return r

    def _render(self, q: np.ndarray, opening: float) -> np.ndarray:
        """The undilated mask (on the GL thread)."""
        r = self._renderer
        assert r is not None
        m, d = self.model, self.data
        d.qpos[self._arm_qadr] = q
        d.qpos[self._finger_qadr] = np.clip(0.5 * opening, *FINGER_RANGE)
        mujoco.mj_kinematics(m, d)
        r.update_scene(d, camera=-1, scene_option=self._option)
        self._set_camera(r.scene)
        seg = r.render()
        objid, objtype = seg[..., 0], seg[..., 1]
        geom = (objtype == int(mujoco.mjtObj.mjOBJ_GEOM)) & (objid >= 0)
        mask = np.zeros(objid.shape, bool)
        mask[geom] = self._is_arm_geom[objid[geom]]
        return mask

    def for_tick(self, tick: Any) -> np.ndarray:
        """The mask of a clock tick (:class:`cablesim.episode.clock.Tick`: ``.joints``,
        ``.opening``): what :class:`~cablesim.episode.capture.FrameCollector` calls."""
        return self(tick.joints, tick.opening)

    def _set_camera(self, scene: mujoco.MjvScene) -> None:
        K, T = self.intrinsics, self.T_world_camera
        w, h = int(K.width), int(K.height)
        left = (-0.5 - K.cx) / K.fx * NEAR
        right = (w - 0.5 - K.cx) / K.fx * NEAR
        top = (K.cy + 0.5) / K.fy * NEAR  # OpenGL y is up: image row -0.5 is the top
        bottom = -(h - 0.5 - K.cy) / K.fy * NEAR
        for cam in scene.camera:  # both eyes: mono rendering averages them
            cam.pos[:] = T[:3, 3]
            cam.forward[:] = T[:3, 2]
            cam.up[:] = -T[:3, 1]
            cam.orthographic = 0
            cam.frustum_near = NEAR
            cam.frustum_far = FAR
            cam.frustum_center = 0.5 * (left + right)
            cam.frustum_width = 0.5 * (right - left)  # MuJoCo: half width
            cam.frustum_bottom = bottom
            cam.frustum_top = top

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        with self._lock:
            r, self._renderer = self._renderer, None
            if r is not None:
                self._gl.submit(r.close).result()
                self._gl.shutdown()

    def __enter__(self) -> ArmMasker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def dilate(mask: np.ndarray, margin: int) -> np.ndarray:
    """``mask`` grown by ``margin`` pixels (a disc); unchanged for 0."""
    if margin < 0:
        raise InputError(f"margin must be >= 0 pixels, got {margin}")
    if margin == 0 or not mask.any():
        return mask
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))
    return cv2.dilate(mask.astype(np.uint8), k).astype(bool)


def arm_mask(
    joints: Sequence[float],
    opening: float,
    intrinsics: Intrinsics,
    T_world_camera: Any,
    T_world_base: Any = None,
    margin: int = 0,
) -> np.ndarray:
    """One arm mask (builds and frees a renderer; use :class:`ArmMasker` for a stream)."""
    with ArmMasker(intrinsics, T_world_camera, T_world_base, margin) as masker:
        return masker(joints, opening)
