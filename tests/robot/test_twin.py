"""The whole real path with no hardware: a digital twin (cablesim.twin).

``FrankyPanda`` speaks libfranka's protocol to the ``franka-sim`` server on 127.0.0.1 (our
Panda, its base at the twin Panda's base); a cablesim world follows the measured joints and
gripper in real time (the hose is really grasped and moved in it) and feeds RGB-D frames into a
live librealsense software device read by ``RealSenseCamera``; the real runner
(``run_interaction`` with the wall-clock ``StreamClock``) grasps a seeded start segment and
performs two actions; perception (motion correlation, DIS flow) segments the stream; the grasp
sampler proposes the next grasp with the robot's reachability; the twin's ground truth scores
it.  Skips only when franky, pyrealsense2 or the franka-sim environment is missing, or its
ports are taken (as ``test_franky_panda.py`` does).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator

import pytest

pytest.importorskip("franky", reason="franky-control is not installed (the 'real' extra)")
pytest.importorskip("pyrealsense2", reason="pyrealsense2 is not installed (the 'real' extra)")

from cablesim.episode.config import ActionConfig, InteractionConfig  # noqa: E402
from cablesim.sim.config import CameraConfig, EpisodeConfig, HoseConfig, SceneConfig  # noqa: E402
from cablesim.twin import FrankaSimServer, FrankaSimUnavailable  # noqa: E402
from cablesim.twin.episode import TwinEpisode, twin_episode  # noqa: E402

#: seed 3: hose 1; in pure simulation its stream gives F0.4 0.27 and a reachable next grasp on
#: the hose (seed 0's remaining hose is out of the arm's reach, seed 1's grasp is spoilt by
#: franka-sim's drift after a Cartesian motion; see benchmarks/results/twin.md)
CONFIG = EpisodeConfig(
    scene=SceneConfig(seed=3, hoses=HoseConfig(count=3), camera=CameraConfig(320, 240)),
    interaction=InteractionConfig(actions=ActionConfig(periods=1)),
)


pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def episode() -> Iterator[TwinEpisode]:
    # motion limits are checked and logged but do not abort: on a shared CPU lost control
    # cycles become velocity-discontinuity reflexes (test_franky_panda tests the reflexes)
    server = FrankaSimServer(
        object_width=CONFIG.scene.hoses.max_diameter(), enforce_motion_limits=False, lifetime=400
    )
    try:
        server.start()
    except FrankaSimUnavailable as e:
        pytest.skip(str(e))
    try:
        ep = twin_episode(CONFIG)
        print(ep.summary())
        print(json.dumps(ep.metrics()["twin"]), json.dumps(ep.metrics()["truth"]))
        yield ep
    finally:
        server.stop()


def test_the_real_runner_grasps_and_moves_the_hose_in_the_twin(episode: TwinEpisode) -> None:
    r = episode.result
    assert r.success, r.reason
    assert r.hose == episode.hose  # the runner saw the picked hose under the segment
    assert r.details["grasp"]["hold_error"] < 0.005  # the hose followed the hold check
    assert r.target_robot_pixels == 0
    # the grasped hose followed the gripper in the twin, in both actions
    assert len(r.actions) == 2
    for a in r.actions:
        assert a.gain > 0.5, f"{a.label}: gain {a.gain:.3f}"
        assert a.frames_kept >= 3, f"{a.label}: {a.frames_kept} frames kept"
    assert episode.truth["unlabelled_frames"] == 0
    # the twin's arm stays on the replayed joints (measured 0.14-0.39 mm median, p95 1.4-1.7,
    # idle or with both cores busy; 2.7-6.3 mm before the robot's slower clock in lockstep
    # was taken into account, see Replay.clock_rate)
    assert episode.twin["tracking_mm_median"] < 1.0


def test_frames_are_paired_with_poses_measured_at_the_same_time(episode: TwinEpisode) -> None:
    clock = episode.clock
    assert clock["frames"] >= sum(episode.frames_kept)
    assert clock["skew_median_s"] < 0.020
    assert episode.result.details["skew_median_s"] < 0.020


def test_perception_and_the_next_grasp_on_the_twin_stream(episode: TwinEpisode) -> None:
    p = episode.perceived
    assert p.seg is not None and (p.seg.votes > 0).any()
    assert p.proposal is not None and p.proposal.proposal is not None, p.proposal.rejections()
    assert p.proposal_grade is not None
    f04 = p.scores["f0.4"]
    assert math.isfinite(f04) and f04 > 0.05  # a loose floor; the value is reported
