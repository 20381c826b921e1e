"""The Panda's mesh look: vendored files and licence, visual-only geoms on the right frames, and
physics that is the same bit for bit with either look."""

from __future__ import annotations

import cv2
import mujoco
import numpy as np
import pytest

from cablesim.assets import path as asset_path
from cablesim.errors import ConfigError
from cablesim.panda.description import FORWARD_QPOS, HOME_QPOS
from cablesim.panda.model import (
    PAD_CONTYPE,
    ROBOT_CONAFFINITY,
    ROBOT_CONTYPE,
    panda_spec,
    robot_body_ids,
)
from cablesim.panda.visuals import HIDDEN_COLLISION_GROUP, VISUAL_GROUP, check_visual, mesh_parts
from cablesim.sim.config import RobotConfig, SceneConfig

from .fixture_world import _XML


def test_vendored_meshes_and_licence():
    parts = mesh_parts()
    links = {p["link"] for p in parts}
    assert links == {f"link{i}" for i in range(8)} | {"hand", "finger"}
    for p in parts:
        f = asset_path("panda", p["file"])
        assert f.is_file() and f.stat().st_size == 84 + 50 * p["faces"], p  # binary STL
    notice = asset_path("panda", "NOTICE").read_text()
    assert "Copyright 2017 Franka Emika GmbH" in notice and "Apache License" in notice
    assert "Modifications" in notice
    licence = asset_path("panda", "LICENSE-2.0.txt").read_text()
    assert "TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION" in licence


def test_visual_switch_is_validated():
    assert check_visual("mesh") == "mesh"
    with pytest.raises(ConfigError, match="robot.visual"):
        SceneConfig(robot=RobotConfig(visual="pretty"))
    with pytest.raises(ConfigError, match="visual"):
        panda_spec(visual="pretty")


def test_meshes_are_visual_only_and_the_primitives_unchanged():
    prim = panda_spec(visual="primitive").compile()
    mesh = panda_spec(visual="mesh").compile()
    visual = mesh.geom_group == VISUAL_GROUP
    assert visual.sum() == 2 * len(mesh_parts()) - sum(
        1 for p in mesh_parts() if p["link"] != "finger"
    )  # one geom per part and body, the finger parts on both fingers
    assert np.all(mesh.geom_type[visual] == mujoco.mjtGeom.mjGEOM_MESH)
    assert not mesh.geom_contype[visual].any() and not mesh.geom_conaffinity[visual].any()
    # the primitives: same geoms, same contact parameters, only drawn in a hidden group
    hidden = np.flatnonzero(~visual)
    assert len(hidden) == prim.ngeom
    assert np.all(mesh.geom_group[hidden] == HIDDEN_COLLISION_GROUP)
    fields = ("type", "size", "pos", "quat", "friction", "solref", "solimp", "priority", "contype")
    for name in fields:
        a, b = getattr(prim, f"geom_{name}"), getattr(mesh, f"geom_{name}")[hidden]
        assert np.array_equal(a, b), name
    pads = np.array([mesh.geom(int(g)).name.endswith("finger_pad") for g in hidden])
    assert pads.sum() == 2  # the pads have their own contype (the table's mat lets them in)
    assert np.all(mesh.geom_contype[hidden][pads] == PAD_CONTYPE)
    assert np.all(mesh.geom_contype[hidden][~pads] == ROBOT_CONTYPE)
    assert np.all(mesh.geom_conaffinity[hidden] == ROBOT_CONAFFINITY)
    for name in ("body_mass", "body_inertia", "body_ipos", "body_iquat", "body_pos", "body_quat"):
        assert np.array_equal(getattr(prim, name), getattr(mesh, name)), name


def _body_silhouettes(model: mujoco.MjModel, q: np.ndarray) -> np.ndarray:
    """Per view (8 around the arm, 320x240) the body id seen at each pixel (-1: none)."""
    data = mujoco.MjData(model)
    data.qpos[:7] = q
    data.qpos[7:9] = 0.04
    mujoco.mj_forward(model, data)
    out = []
    with mujoco.Renderer(model, 240, 320) as r:
        r.enable_segmentation_rendering()
        for azimuth in (0, 90, 180, 270):
            for elevation in (-20, 20):
                cam = mujoco.MjvCamera()
                cam.lookat[:] = (0.3, 0.0, 0.45)
                cam.distance, cam.azimuth, cam.elevation = 2.0, azimuth, elevation
                r.update_scene(data, cam)
                geom = r.render()[..., 0]
                out.append(np.where(geom >= 0, model.geom_bodyid[np.clip(geom, 0, None)], -1))
    return np.array(out)


@pytest.mark.parametrize("q", [HOME_QPOS, FORWARD_QPOS], ids=["home", "forward"])
def test_meshes_sit_on_the_link_frames(q):
    """Each link's mesh is drawn where the primitive arm is: >= 85% of its pixels within 2 px
    of the primitive silhouette from 8 directions (a link mesh turned 90 degrees about a
    non-symmetric axis scores 0.26-0.75), and the two silhouettes overlap (IoU > 0.7)."""
    prim = _body_silhouettes(panda_spec(visual="primitive").compile(), q)
    mesh_model = panda_spec(visual="mesh").compile()
    mesh = _body_silhouettes(mesh_model, q)
    near = np.array(
        [cv2.dilate((p >= 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0 for p in prim]
    )
    for body in robot_body_ids(mesh_model, ""):
        drawn = mesh == body
        assert drawn.sum() > 50, mesh_model.body(body).name
        covered = (near & drawn).sum() / drawn.sum()
        assert covered >= 0.85, (mesh_model.body(body).name, covered)
    iou = ((prim >= 0) & (mesh >= 0)).sum() / ((prim >= 0) | (mesh >= 0)).sum()
    assert iou > 0.7


def _fixture_model(visual: str) -> tuple[mujoco.MjModel, mujoco.MjData]:
    from cablesim.panda.model import attach_panda, set_home

    spec = mujoco.MjSpec.from_string(_XML)
    names = attach_panda(spec, visual=visual)
    model = spec.compile()
    data = mujoco.MjData(model)
    set_home(model, data, names)
    mujoco.mj_forward(model, data)
    return model, data


def test_physics_is_the_same_bit_for_bit():
    """Arm, table, board and a hanging hose that the hand sweeps through: 400 steps with mesh
    visuals give the very states of the primitive model, contacts included."""
    runs = {}
    for visual in ("primitive", "mesh"):
        model, data = _fixture_model(visual)
        robot = set(robot_body_ids(model).tolist())
        target = np.array([0.35, 0.3, 0.0, -1.9, 0.0, 2.2, 0.78])
        states, robot_contacts = [], 0
        for k in range(400):
            data.ctrl[:7] = HOME_QPOS + (target - HOME_QPOS) * min(1.0, k / 200)
            mujoco.mj_step(model, data)
            con = data.contact[: data.ncon]
            robot_contacts += sum(
                (model.geom_bodyid[c.geom[0]] in robot) != (model.geom_bodyid[c.geom[1]] in robot)
                for c in con
            )
            states.append(np.concatenate([data.qpos, data.qvel, data.act, data.qacc_warmstart]))
        runs[visual] = (np.array(states), robot_contacts)
    assert runs["primitive"][1] > 0, "the arm never touched anything: the check is empty"
    assert runs["primitive"][1] == runs["mesh"][1]
    assert np.array_equal(runs["primitive"][0], runs["mesh"][0])
