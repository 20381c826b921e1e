import mujoco
import numpy as np

from cablesim.panda.model import (
    HOME_QPOS,
    JOINT_LIMITS,
    TCP_OFFSET,
    attach_panda,
    panda_spec,
    robot_body_ids,
    robot_geom_ids,
    set_grasp_force,
)


def _dh_home_tcp() -> np.ndarray:
    # Panda DH (Craig): d1 0.333, d3 0.316, a4 0.0825, a5 -0.0825, d5 0.384, a7 0.088, flange 0.107.
    # At q = (0, 0, 0, -pi/2, 0, pi/2, pi/4) the forearm is horizontal and the hand points down.
    x = 0.0825 + 0.384 + 0.088
    z = 0.333 + 0.316 + 0.0825 - 0.107 - TCP_OFFSET
    return np.array([x, 0.0, z])


def test_standalone_model_compiles_and_home_fk_matches_dh():
    model = panda_spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.site("grasp_site").xpos, _dh_home_tcp(), atol=1e-5)
    np.testing.assert_allclose(data.body("hand").xpos[2], 0.6245, atol=1e-5)
    # hand z points down, fingers close along world y
    R = data.site("grasp_site").xmat.reshape(3, 3)
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-6)
    np.testing.assert_allclose(abs(R[1, 1]), 1.0, atol=1e-6)
    assert np.allclose(data.qpos[:7], HOME_QPOS)


def test_joint_limits_and_actuators():
    model = panda_spec().compile()
    for i in range(7):
        j = model.joint(f"joint{i + 1}")
        np.testing.assert_allclose(model.jnt_range[j.id], JOINT_LIMITS[i])
        assert model.jnt_limited[j.id]
    assert model.nu == 8
    assert model.actuator("actuator1").gainprm[0] == 4500
    # driving a joint past its limit stops at the limit
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.ctrl[3] = -0.0698
    data.qpos[3] = -0.0698
    data.qvel[3] = 5.0
    for _ in range(200):
        mujoco.mj_step(model, data)
    assert data.qpos[3] <= -0.0698 + 0.01


def test_attach_panda_names_and_robot_ids():
    scene = mujoco.MjSpec()
    scene.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1])
    names = attach_panda(scene, pos=(0.1, 0.2, 0.0), quat=(1, 0, 0, 0))
    model = scene.compile()
    for n in names.joints + names.actuators + names.bodies:
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) >= 0 or (
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) >= 0
            or mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) >= 0
        )
    assert model.site(names.site).id >= 0
    assert model.geom(names.finger_geoms[0]).friction[0] == 1.5
    bodies = robot_body_ids(model)
    assert len(bodies) == 11
    geoms = robot_geom_ids(model)
    assert all(model.geom(g).name.startswith("panda/") for g in geoms)
    assert 0 not in bodies
    set_grasp_force(model, names, 30.0)
    assert model.actuator(names.gripper_actuator).forcerange[1] == 30.0
