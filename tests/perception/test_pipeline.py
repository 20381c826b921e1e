"""Two-stage pipeline, subsampling, action direction, stream-level errors."""

from __future__ import annotations

import subprocess
import sys
import threading

import numpy as np
import pytest

from cablesim.errors import InputError
from cablesim.perception import (
    FlowEstimator,
    Frame,
    Intrinsics,
    OracleFlow,
    Stream,
    action_direction,
    compute_statistics,
    gripper_displacements,
    segment_stream,
    subsample_by_gripper,
)
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream


@pytest.fixture(scope="module")
def stream():
    regions = [
        Region((4, 14, 4, 40), "linear", 0.7, label=0),
        Region((20, 30, 4, 40), "random", 0.8, label=1),
    ]
    return synthetic_stream(regions, SyntheticSpec(seed=4, samples_per_period=8))


def test_pipelined_equals_sequential(stream):
    a = compute_statistics(stream, "oracle", pipelined=False)
    b = compute_statistics(stream, "oracle", pipelined=True, queue_size=1)
    assert a.actions == b.actions and a.n_samples == b.n_samples
    for act in a.actions:
        for name in ("c0", "r2", "psi", "std_dphi", "n"):
            assert np.array_equal(
                getattr(a.correlation[act], name), getattr(b.correlation[act], name)
            )
        assert np.array_equal(a.segmentation[act].votes, b.segmentation[act].votes)


class _Failing(FlowEstimator):
    name = "failing"

    def __init__(self, fail_at: int) -> None:
        self.calls = 0
        self.fail_at = fail_at

    def compute(self, image1, image2):
        raise AssertionError

    def frame_flow(self, frame, target):
        self.calls += 1
        if self.calls == self.fail_at:
            raise RuntimeError("flow exploded")
        return OracleFlow().frame_flow(frame, target)


def test_worker_errors_propagate(stream):
    n_threads = threading.active_count()
    with pytest.raises(RuntimeError, match="flow exploded"):
        compute_statistics(stream, _Failing(5), pipelined=True)
    with pytest.raises(RuntimeError, match="flow exploded"):
        compute_statistics(stream, _Failing(5), pipelined=False)
    assert threading.active_count() <= n_threads


def test_consumer_errors_stop_worker(stream):
    bad = Stream([*stream.frames[:-1], stream.frames[-1]])

    # corrupt one flow's shape via a wrapper: the consumer raises, the worker must stop
    class _BadShape(OracleFlow):
        def frame_flow(self, frame, target):
            f = super().frame_flow(frame, target)
            return f[:-1] if frame.sample == 3 else f

    n_threads = threading.active_count()
    with pytest.raises(InputError, match="size"):
        compute_statistics(bad, _BadShape(), pipelined=True)
    assert threading.active_count() <= n_threads


def _frames(points):
    K = Intrinsics(100, 100, 2, 2, 4, 4)
    rgb = np.zeros((4, 4, 3), np.uint8)
    d = np.ones((4, 4), np.float32)
    return [
        Frame(rgb, d, K, np.asarray(p, float), action=0, sample=i) for i, p in enumerate(points)
    ]


def test_subsample_by_gripper():
    pts = [
        [0, 0, 1],
        [0.0004, 0, 1],
        [0.0011, 0, 1],
        [0.0015, 0, 1],
        [0.0021, 0, 1],
        [0.0021, 0, 1],
    ]
    kept = subsample_by_gripper(_frames(pts), 0.001)
    assert [f.sample for f in kept] == [0, 2, 4]
    assert subsample_by_gripper([], 0.001) == []
    with pytest.raises(InputError):
        subsample_by_gripper(_frames(pts), -1)


def test_action_direction_and_displacement():
    t = np.linspace(0, 2 * np.pi, 30)
    u = np.array([1.0, 2.0, 0.0]) / np.sqrt(5)
    pts = np.array([0.1, 0.0, 1.0]) + 0.02 * np.sin(t)[:, None] * u
    d = action_direction(pts)
    assert abs(abs(d @ u) - 1) < 1e-9
    dg = gripper_displacements(pts)
    assert dg[0] == 0 and dg.max() == pytest.approx(0.02, abs=1e-3)
    assert np.allclose(action_direction(np.ones((4, 3))), 0)


def test_stream_errors(stream):
    no_target = Stream(stream.frames[:-1])
    with pytest.raises(InputError, match="target"):
        segment_stream(no_target, flow="oracle")
    only_target = Stream(stream.frames[-1:])
    with pytest.raises(InputError, match="no action frames"):
        compute_statistics(only_target, "oracle")


def test_perception_never_imports_mujoco():
    code = (
        "import sys, pkgutil, importlib, cablesim.perception as P\n"
        + "mods = [m.name for m in pkgutil.iter_modules(P.__path__)]\n"
        + "assert {'raft', 'correlation', 'grasp_sampler', 'published'} <= set(mods), mods\n"
        + "for m in mods: importlib.import_module('cablesim.perception.' + m)\n"
        + "assert 'mujoco' not in sys.modules, 'mujoco was imported'\n"
        + "assert 'torch' not in sys.modules, 'torch imported eagerly'\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
