"""The dm_env adapter: specs match the observations, a short episode ends in LAST."""

from __future__ import annotations

import dm_env
import numpy as np

import cablesim  # noqa: F401  (headless GL before mujoco)
from cablesim.envs import HoseExploreConfig
from cablesim.envs.dm import DmEnvAdapter

TINY = HoseExploreConfig.of(scene_seed=2, hoses=2, width=160, height=120, budget=1, periods=1)


def test_dm_env_adapter_episode():
    env = DmEnvAdapter(TINY, seed=3)
    try:
        ts = env.reset()
        assert ts.first()
        obs_spec = env.observation_spec()
        for k, spec in obs_spec.items():
            spec.validate(ts.observation[k])
        act_spec = env.action_spec()
        action = {k: s.generate_value() for k, s in act_spec.items()}
        action["point"] = np.array([0.02, 0.02], np.float32)  # the corner: fails fast
        for k, s in act_spec.items():
            s.validate(action[k])
        ts = env.step(action)
        assert ts.last() and ts.discount == 1.0  # budget reached: truncation
        assert isinstance(ts.reward, float)
        env.reward_spec().validate(np.float64(ts.reward))
        assert env.step(action).first()  # stepping after LAST starts a new episode
    finally:
        env.close()


def test_dm_env_is_an_environment():
    assert issubclass(DmEnvAdapter, dm_env.Environment)


def test_dm_control_mjcf_builds_models_for_mujoco_4():
    """dm_control's mjcf parses, edits and writes MJCF that MuJoCo 4.0 compiles (its Physics
    does not work with MuJoCo 4.0: README, "dm-control")."""
    import mujoco
    from dm_control import mjcf

    root = mjcf.from_xml_string(
        '<mujoco model="probe"><worldbody><body name="b" pos="0 0 1"><freejoint/>'
        '<geom type="sphere" size="0.1"/></body></worldbody></mujoco>'
    )
    root.worldbody.add("body", name="c", pos=[0.3, 0, 1]).add("geom", type="box", size=[0.1] * 3)
    model = mujoco.MjModel.from_xml_string(root.to_xml_string())
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)
    assert model.nbody == 3 and data.time > 0
