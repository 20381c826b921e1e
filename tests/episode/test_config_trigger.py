"""EpisodeConfig round trip and validation; the simulated-time camera trigger."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cablesim.episode.config import EpisodeConfig
from cablesim.episode.primitives import action_direction, periodic_waypoints
from cablesim.episode.trigger import SimTrigger
from cablesim.errors import ConfigError
from cablesim.robot.pose import Pose


def test_config_round_trip_and_print():
    cfg = EpisodeConfig(seed=4, hose=1)
    cfg.actions.extra_directions = ((0.0, 0.0, 1.0),)
    cfg.retreat.qpos = (-1.9, -0.6, 0.0, -2.3, 0.0, 1.7, 0.78)
    again = EpisodeConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg
    assert '"seed": 4' in str(cfg)
    assert cfg.scene_config().seed == 4


@pytest.mark.parametrize(
    "change, field",
    [
        ({"kind": "pull"}, "kind"),
        ({"hose": 9}, "hose"),
        ({"seed": -1}, "seed"),
    ],
)
def test_config_rejects(change, field):
    with pytest.raises(ConfigError, match=field):
        EpisodeConfig(**change).validate()


def test_config_rejects_nested():
    cfg = EpisodeConfig()
    cfg.actions.directions = ("sideways",)
    with pytest.raises(ConfigError, match="actions.directions"):
        cfg.validate()
    cfg = EpisodeConfig()
    cfg.actions.periods = 0
    with pytest.raises(ConfigError, match="actions.periods"):
        cfg.validate()


class FakeWorld:
    class model:  # noqa: N801 - mimics MjModel.opt.timestep
        class opt:  # noqa: N801
            timestep = 0.004

    def __init__(self) -> None:
        self.t = 0.0
        self.steps = 0

    @property
    def time(self) -> float:
        return self.t

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.steps += 1
            self.t = self.steps * 0.004


def test_trigger_fires_at_the_frame_rate_of_simulated_time():
    w = FakeWorld()
    w.step(10)
    times: list[float] = []
    with SimTrigger(w, times.append, rate=15.0):
        w.step(750)  # 3 s
        w.step(1)
    w.step(100)  # not hooked any more
    assert "step" not in vars(w)
    assert len(times) == 1 + 45
    dt = np.diff(times)
    assert np.all(np.abs(dt - 1 / 15) <= 0.004 + 1e-9)
    # ticks stay locked to t0 + i/15 (no drift)
    assert abs(times[-1] - times[0] - 45 / 15) <= 0.0021


def test_trigger_refuses_nesting():
    w = FakeWorld()
    with SimTrigger(w, lambda t: None):
        with pytest.raises(RuntimeError, match="already hooked"):
            SimTrigger(w, lambda t: None).__enter__()
    assert "step" not in vars(w)


def test_action_directions_and_waypoints():
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # looks along +x
    axis = np.array([0.3, 0.2, -0.9])  # a hose leaning towards the board
    along = action_direction("along", axis, T)
    across = action_direction("across", axis, T)
    assert abs(along[0]) < 1e-9  # image plane of this camera is the board plane (y, z)
    assert abs(np.dot(along, across)) < 1e-9 and abs(across[0]) < 1e-9
    g1 = Pose(np.array([0.5, 0.0, 0.5]))
    way = periodic_waypoints(g1, along, 0.02, 3)
    assert len(way) == 12
    d = np.array([w.position - g1.position for w in way]) @ along
    assert np.allclose(d, [0.02, 0, -0.02, 0] * 3)
