"""The model the franka-sim server simulates our Panda with keeps its explicit joint servo stable.

franka-sim 1.1.7 (pinned in ``scripts/constraints-franka-sim.txt``) servoes the arm on
``qfrc_applied`` with ``KP e + KD (dq_c - dq)`` at a 1 ms step; the damping term is explicit, so
it is stable only while ``dt * max eig(M^-1 KD) < 2`` (and free of oscillation below 1).  With the
Menagerie's 0.1 kg m^2 armature our Panda broke that at the twin's stance (joints 1 and 3
aligned): the two joints chattered at the 87 Nm torque limit, finished motions overshot and the
hold drifted up to 15 mm, which made the robot tests' reach checks fail at random.
"""

from __future__ import annotations

import mujoco
import numpy as np
import scipy.linalg

from cablesim.panda import HOME_QPOS, JOINT_LIMITS
from cablesim.twin.franka_sim_model import franka_sim_mjcf

#: franka-sim 1.1.7's ``ARM_POSITION_KD`` (= ``ARM_VELOCITY_KV``), Nm s/rad, and its step (s)
KD = np.array([450.0, 450.0, 350.0, 350.0, 200.0, 200.0, 200.0])
DT = 0.001


def _worst_damping_factor(model: mujoco.MjModel, qs: np.ndarray) -> float:
    data = mujoco.MjData(model)
    worst = 0.0
    for q in qs:
        data.qpos[:7] = q
        mujoco.mj_forward(model, data)
        M = np.zeros((7, 7))
        for j in range(7):
            unit, column = np.zeros(7), np.zeros(7)
            unit[j] = 1.0
            mujoco.mj_mulM(model, data, column, unit)
            M[:, j] = column
        worst = max(worst, float(scipy.linalg.eigvals(np.diag(KD), M).real.max()) * DT)
    return worst


def _stances() -> np.ndarray:
    rng = np.random.default_rng(7)
    lo, hi = np.asarray(JOINT_LIMITS, dtype=float).T
    around_home = HOME_QPOS + rng.uniform(-0.5, 0.5, (40, 7))
    return np.vstack([HOME_QPOS, np.clip(around_home, lo, hi)])


def test_the_servo_is_damped_without_oscillation_around_the_twin_stance() -> None:
    model = mujoco.MjModel.from_xml_string(franka_sim_mjcf())
    assert model.nv == 7
    assert _worst_damping_factor(model, _stances()) < 1.0


def test_the_menagerie_armature_would_make_it_unstable() -> None:
    """The check can fail: at 0.1 kg m^2 the explicit damping diverges at the twin's home."""
    model = mujoco.MjModel.from_xml_string(franka_sim_mjcf())
    model.dof_armature[:] = 0.1
    assert _worst_damping_factor(model, HOME_QPOS[None]) > 2.0
