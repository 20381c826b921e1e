"""A small stand-in for ``cablesim.sim.world.World``: table, board, one hanging hose, the Panda."""

from __future__ import annotations

import mujoco
import numpy as np

from cablesim.errors import PhysicsDivergedError
from cablesim.panda.model import attach_panda, set_home

HOSE_X = 0.56  # hose hangs 4 cm in front of the board face (x = 0.60)
HOSE_TOP = 0.95
HOSE_SEGMENTS = 20
HOSE_LENGTH = 0.6

_XML = f"""
<mujoco model="robot_fixture">
  <option timestep="0.002" integrator="discrete"/>
  <worldbody>
    <light pos="0 0 2" dir="0 0 -1"/>
    <geom name="table" type="box" pos="0.3 0 -0.02" size="0.6 0.8 0.02" rgba="0.6 0.5 0.4 1"/>
    <geom name="board" type="box" pos="0.62 0 0.6" size="0.02 0.6 0.6" rgba="0.8 0.8 0.8 1"/>
    <flexcomp name="hose" type="grid" dim="1" count="{HOSE_SEGMENTS + 1} 1 1"
              spacing="{HOSE_LENGTH / HOSE_SEGMENTS} 1 1"
              pos="{HOSE_X} 0.05 {HOSE_TOP - HOSE_LENGTH / 2}" euler="0 90 0"
              radius="0.0075" mass="0.15" rgba="0.1 0.6 0.1 1">
      <edge equality="true" solimp="0.99 0.999 0.001"/>
      <elasticity young="2e6" poisson="0.3" thickness="0.015" damping="0.002"/>
      <contact selfcollide="none" condim="3" friction="1 0.005 0.0001"/>
      <pin id="0"/>
    </flexcomp>
  </worldbody>
</mujoco>
"""


class FixtureWorld:
    """Exposes what SimPanda needs: model, data, step, T_world_camera, panda, panda_base."""

    def __init__(self, base_pos=(0.0, 0.0, 0.0), base_quat=(1.0, 0.0, 0.0, 0.0)):
        self.controllers: dict = {}
        spec = mujoco.MjSpec.from_string(_XML)
        self.panda = attach_panda(spec, base_pos, base_quat)
        self.panda_base = (tuple(base_pos), tuple(base_quat))
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        set_home(self.model, self.data, self.panda)
        mujoco.mj_forward(self.model, self.data)
        # Camera 1 m in front of the board, behind/above the robot, looking along +x.
        R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # x right,y down,z fwd
        self.T_world_camera = np.eye(4)
        self.T_world_camera[:3, :3] = R
        self.T_world_camera[:3, 3] = (-0.4, 0.0, 0.6)
        self.step(1000)  # let the hose settle

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            for controller in self.controllers.values():  # as World's: the gripper's limit
                controller(self)
            mujoco.mj_step(self.model, self.data)
        if not np.isfinite(self.data.qpos).all():
            raise PhysicsDivergedError("NaN in qpos")

    def hose_vertex_positions(self) -> np.ndarray:
        return self.data.flexvert_xpos[: self.model.flex_vertnum[0]].copy()
