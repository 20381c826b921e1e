"""One default simulated interaction with the default CPU perception, timed by stage.

Shared by ``bench_episode.py`` (one core, stages) and ``bench_throughput.py`` (worker
processes).  The stages are measured from outside the simulator, by wrapping the camera's
snapshot and unlabelled capture (rendering: RGB + depth of every kept frame and the target
frame, and the label passes of the labelled ones)
and ``cablesim.sim.flow_gt.flow_to_target`` (ground truth), so the same script also measures
older commits of cablesim; physics and control is the rest of the interaction (stepping,
IK, contact checks, settling, the runner).  Perception is
``segment_stream(stream, method="correlation", flow="dis")``, the default CPU perception.

Wall time (``time.perf_counter``) and CPU time of the process (``time.process_time``, all
threads: the software OpenGL renderer and the flow thread of the pipelined perception count)
are both recorded.
"""

from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim import provenance


def single_thread_environment() -> None:
    """Software OpenGL in the calling thread (llvmpipe with ``LP_NUM_THREADS=0``), as BLAS
    and OpenCV (:mod:`benchmarks._env`).  Call before the first rendering; worker processes
    started afterwards inherit it."""
    os.environ.setdefault("LP_NUM_THREADS", "0")


def pin_to_one_core(core: int | None = None) -> int | None:
    """Pin this process to one CPU core (the first allowed one by default); None if the
    platform cannot."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    c = allowed[0] if core is None else allowed[core % len(allowed)]
    os.sched_setaffinity(0, {c})
    return c


class Stopwatch:
    """Accumulates wall and CPU seconds of the calls it wraps."""

    def __init__(self) -> None:
        self.wall = 0.0
        self.cpu = 0.0
        self.calls = 0

    def wrap(self, fn: Any) -> Any:
        def timed(*args: Any, **kwargs: Any) -> Any:
            t, c = time.perf_counter(), time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.wall += time.perf_counter() - t
                self.cpu += time.process_time() - c
                self.calls += 1

        return timed


@dataclass
class InteractionRun:
    """Timings (seconds) and outcome of one interaction + perception."""

    seed: int
    hose: int | None
    success: bool
    reason: str = ""
    wall: dict[str, float] = field(default_factory=dict)
    cpu: dict[str, float] = field(default_factory=dict)
    frames: int = 0
    ticks: int = 0
    sim_time: float = math.nan
    physics_steps: int = 0
    gains: list[float] = field(default_factory=list)
    others_mm: list[float] = field(default_factory=list)
    still: str = ""
    digest: str = ""  # sha256 of every frame's RGB, depth, labels, GT flow and the votes

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def stream_digest(stream: Any, votes: np.ndarray | None) -> str:
    h = hashlib.sha256()
    for f in stream:
        h.update(np.ascontiguousarray(f.rgb).tobytes())
        h.update(np.ascontiguousarray(f.depth).tobytes())
        h.update(np.asarray(f.gripper, np.float64).tobytes())
        if f.truth is not None:
            h.update(np.ascontiguousarray(f.truth.labels).tobytes())
            if f.truth.flow_to_target is not None:
                h.update(np.ascontiguousarray(f.truth.flow_to_target).tobytes())
                h.update(np.ascontiguousarray(f.truth.flow_valid).tobytes())
    if votes is not None:
        h.update(np.ascontiguousarray(votes).tobytes())
    return h.hexdigest()


def run_interaction(session: Any, segment_mask: np.ndarray, perception: bool = True) -> Any:
    """One interaction of ``session`` at ``segment_mask``, then perception; timed by stage."""
    import cablesim.sim.flow_gt as flow_gt
    import cablesim.sim.truth as sim_truth
    from cablesim.perception import segment_stream

    render, truth = Stopwatch(), Stopwatch()
    camera = session.camera
    original_snapshot, original_flow = camera.snapshot, flow_gt.flow_to_target
    camera.snapshot = render.wrap(original_snapshot)
    # the unlabelled frames of capture.truth_every > 1 (older cablesim has no such method)
    original_unlabelled = getattr(camera, "capture_unlabelled", None)
    if original_unlabelled is not None:
        camera.capture_unlabelled = render.wrap(original_unlabelled)
    # the truth provider calls the name it imported: wrap it there too
    flow_gt.flow_to_target = sim_truth.flow_to_target = truth.wrap(original_flow)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        res = session.interact(segment_mask)
    finally:
        camera.snapshot = original_snapshot
        if original_unlabelled is not None:
            camera.capture_unlabelled = original_unlabelled
        flow_gt.flow_to_target = sim_truth.flow_to_target = original_flow
    t1, c1 = time.perf_counter(), time.process_time()
    run = InteractionRun(session.cfg.seed, session.hose, bool(res.success), res.reason)
    run.wall = {
        "rendering": render.wall,
        "ground_truth": truth.wall,
        "physics_control": (t1 - t0) - render.wall - truth.wall,
        "interaction": t1 - t0,
    }
    run.cpu = {
        "rendering": render.cpu,
        "ground_truth": truth.cpu,
        "physics_control": (c1 - c0) - render.cpu - truth.cpu,
        "interaction": c1 - c0,
    }
    if not res.success:
        return run, res, None
    seg = None
    if perception:
        seg = segment_stream(res.stream, method="correlation", flow="dis")
        t2, c2 = time.perf_counter(), time.process_time()
        run.wall["perception"], run.cpu["perception"] = t2 - t1, c2 - c1
    run.wall["total"] = run.wall["interaction"] + run.wall.get("perception", 0.0)
    run.cpu["total"] = run.cpu["interaction"] + run.cpu.get("perception", 0.0)
    d = session.world.data
    run.frames = len(res.stream)
    run.ticks = int(res.details.get("ticks", 0))
    run.sim_time = float(res.stream.target.timestamp)
    run.physics_steps = int(round(float(d.time) / float(session.world.model.opt.timestep)))
    run.gains = [float(a.gain) for a in res.actions]
    run.others_mm = [1000.0 * x for x in res.other_hose_displacement()]
    run.still = str(res.details.get("still", ""))
    run.digest = stream_digest(res.stream, None if seg is None else seg.votes)
    return run, res, seg


def uptime() -> str:
    try:
        return subprocess.run(
            ["uptime"], capture_output=True, text=True, check=False
        ).stdout.strip()
    except OSError:
        return f"load average {provenance.load_average()}"


def versions_line() -> str:
    import cv2
    import mujoco

    import cablesim

    return (
        f"python {sys.version.split()[0]}, mujoco {mujoco.__version__}, opencv {cv2.__version__}, "
        f"numpy {np.__version__}, cablesim {cablesim.__version__} at {cablesim.__file__}; "
        f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}, "
        f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', '(unset)')}, "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', '(unset)')}"
    )


def run_meta(**extra: Any) -> dict[str, Any]:
    """What every benchmark result records about its run: date, commit, machine
    (:func:`cablesim.provenance.provenance`) and versions, then ``extra``."""
    return provenance.provenance(versions=versions_line(), **extra)
