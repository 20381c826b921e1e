"""The ground floor's rotation helpers (pure NumPy) give MuJoCo's bits."""

from __future__ import annotations

import mujoco
import numpy as np

from cablesim.pose import Pose, mat_to_quat, quat_to_mat


def _mj_quat_to_mat(q: np.ndarray) -> np.ndarray:
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(q, dtype=float))
    return m.reshape(3, 3)


def _mj_mat_to_quat(R: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(R, dtype=float).reshape(9))
    n = np.linalg.norm(q)
    q = q / n
    return q if q[0] >= 0 else -q


def test_conversions_match_mujoco_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    for i in range(5000):
        q = rng.normal(size=4)
        if i % 2:
            q /= np.linalg.norm(q)
        assert np.array_equal(quat_to_mat(q), _mj_quat_to_mat(q))
        R = _mj_quat_to_mat(q / np.linalg.norm(q))
        if i % 3 == 0:
            R = np.round(R, 2)  # not quite orthonormal: the normalisation counts too
        assert np.array_equal(mat_to_quat(R), _mj_mat_to_quat(R))
    for R in (np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])):
        assert np.array_equal(mat_to_quat(R), _mj_mat_to_quat(R))


def test_pose_round_trip() -> None:
    p = Pose([0.1, 0.2, 0.3], [0.9, 0.1, -0.2, 0.3])
    back = Pose.from_matrix(p.matrix())
    assert np.allclose(back.position, p.position)
    assert np.allclose(back.quaternion, p.quaternion)
    assert np.allclose((p @ p.inverse()).matrix(), np.eye(4))
