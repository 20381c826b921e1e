"""Connecting FrankyPanda is retried when libfranka's first state does not arrive in time.

Seen in a loop of ``tests/robot`` beside a full test run on two cores: ``fr.Robot(host)`` raised
``NetworkException: libfranka: UDP receive: Timeout`` (libfranka waits one second for franka-sim's
first state after the TCP handshake).  Nothing moves before a connection exists, so the adapter
connects again, at most ``connect_attempts`` times, warning and listing each retry.  Here the
failing attempt is a real connection to franka-sim that is dropped, then reported as that
timeout: the next attempt must get a working session from the same server.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator

import numpy as np
import pytest

from cablesim.errors import ConfigError
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.twin.franka_sim import HOST, FrankaSimServer, FrankaSimUnavailable

franky = pytest.importorskip("franky", reason="franky-control is not installed (the 'real' extra)")

T_WORLD_CAMERA = np.array(
    [[0, 0, -1, 1.2], [1, 0, 0, 0], [0, -1, 0, 0.6], [0, 0, 0, 1]], dtype=float
)
TIMEOUT = "libfranka: UDP receive: Timeout"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FrankaSimServer]:
    s = FrankaSimServer(object_width=0.02, lifetime=120.0, workdir=tmp_path_factory.mktemp("fs"))
    try:
        s.start()
    except FrankaSimUnavailable as e:
        pytest.skip(str(e))
    try:
        yield s
    finally:
        s.stop()


def test_a_timed_out_connection_is_retried_and_the_next_one_works(server, monkeypatch) -> None:
    real = franky.Robot
    calls = []

    def first_times_out(*args, **kwargs):
        calls.append(args)
        if len(calls) == 1:  # a real session, dropped, then the timeout libfranka raised
            dropped = real(*args, **kwargs)
            del dropped
            gc.collect()
            raise franky.NetworkException(TIMEOUT)
        return real(*args, **kwargs)

    monkeypatch.setattr(franky, "Robot", first_times_out)
    with pytest.warns(UserWarning, match=r"arm at .*: connection attempt 1 of 3 failed"):
        panda = FrankyPanda(HOST, T_WORLD_CAMERA, realtime=False)
    try:
        assert len(calls) == 2
        assert len(panda.connect_retries) == 1 and TIMEOUT in panda.connect_retries[0]
        q = panda.joint_positions
        assert q.shape == (7,) and np.all(np.isfinite(q))
        assert panda.gripper is not None and panda.gripper_opening > 0
        moved = panda.move_joints(q + np.r_[0.05, 0, 0, 0, 0, 0, 0], speed_factor=0.2)
        assert moved, moved.reason  # the session controls the arm, not just reads it
        assert abs(panda.joint_positions[0] - q[0] - 0.05) < 0.01
    finally:
        panda.close()
        gc.collect()


def test_the_last_attempts_error_is_raised(monkeypatch) -> None:
    calls = []

    def always_times_out(*args, **kwargs):
        calls.append(args)
        raise franky.NetworkException(TIMEOUT)

    monkeypatch.setattr(franky, "Robot", always_times_out)
    with pytest.warns(UserWarning) as warned:
        with pytest.raises(franky.NetworkException, match="UDP receive"):
            FrankyPanda(HOST, T_WORLD_CAMERA, realtime=False)
    assert len(calls) == 3
    assert [f"attempt {k} of 3 failed" in str(w.message) for k, w in enumerate(warned, 1)] == [
        True,
        True,
    ]


def test_connect_attempts_is_checked() -> None:
    with pytest.raises(ConfigError, match="connect_attempts"):
        FrankyPanda(HOST, T_WORLD_CAMERA, connect_attempts=0)
