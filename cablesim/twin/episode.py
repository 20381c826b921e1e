"""One interaction through the whole real path, with a digital twin as the world.

    with FrankaSimServer(object_width=0.015, enforce_motion_limits=False):
        ep = twin_episode(EpisodeConfig.of(seed=0, ...))          # grasp, two actions, perception
    print(ep.summary())
    ref = sim_episode(EpisodeConfig.of(seed=0, ...))              # the same seed in pure simulation

:func:`twin_episode` wires the real components together, none of them aware of the twin:
:class:`~cablesim.robot.franky_panda.FrankyPanda` speaks libfranka's protocol to the server on
127.0.0.1 (whose base frame is the twin Panda's base), the twin
(:class:`~cablesim.twin.world.TwinWorld`) follows the measured joints and gripper in real time
and feeds its RGB-D frames into a live librealsense software device read by
:class:`~cablesim.camera.realsense.RealSenseCamera`, the real runner
(:func:`~cablesim.episode.runner.run_interaction` with a wall-clock
:class:`~cablesim.episode.clock.StreamClock`) grasps the seeded start segment and performs the
actions, perception segments the stream with the default CPU flow (DIS), and the grasp sampler
proposes the next grasp with the robot's reachability.  Only the scores and grades read the
twin's ground truth (:class:`~cablesim.twin.truth.TwinTruth`).

:func:`sim_episode` runs the same seed in pure simulation (``simulate_episode``) and the same
perception, for comparison.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cablesim.episode.clock import StreamClock
from cablesim.episode.runner import InteractionOptions, run_interaction
from cablesim.evaluation import scores_dict
from cablesim.frames import Stream
from cablesim.jsonutil import jsonable
from cablesim.perception.grasp_sampler import GraspSampler, SamplingResult
from cablesim.perception.metrics import grade_proposal
from cablesim.perception.pipeline import StreamSegmentation, segment_stream
from cablesim.policies.explore import front_segment, grasp_reachability
from cablesim.progress import Say, quiet
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.session import simulate_episode
from cablesim.twin.franka_sim import HOST
from cablesim.twin.realsense import SoftwareRealSense
from cablesim.twin.truth import TwinTruth
from cablesim.twin.world import FrankySource, TwinWorld

#: FrankyPanda settings against franka-sim: there is no realtime kernel here (the real robot
#: keeps the adapter's defaults); with its servo stable on our model (``FRANKA_SIM_ARMATURE``)
#: the arm ends a motion within a millimetre of its target.
FRANKA_SIM_ROBOT = {
    "dynamics_factor": 0.2,
    "realtime": False,
    "position_tolerance": 0.003,
    "rotation_tolerance": 0.05,
    "joint_tolerance": 0.005,
    "motion_timeout": 15.0,
    # franka-sim's arm runs slower than real time on a loaded host (its log says so); the wait
    # ends as soon as the target is reached
    "settle_time": 10.0,
}


@dataclass
class Perceived:
    """Perception of one stream and the grasp sampler's next proposal, scored."""

    seg: StreamSegmentation | None = None
    scores: dict[str, float] = field(default_factory=dict)
    proposal: SamplingResult | None = None
    segment: np.ndarray | None = None  # the next grasp's segment (front part of the proposal)
    proposal_grade: str | None = None
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        sr = self.proposal
        p = None if sr is None else sr.proposal
        return {
            "scores": self.scores,
            "votes_pixels": None if self.seg is None else int((self.seg.votes > 0).sum()),
            "proposal": None
            if p is None
            else {
                "centre_camera": [float(x) for x in p.centre],
                "pixels": int(p.mask.sum()),
                "segment_pixels": None if self.segment is None else int(self.segment.sum()),
                "grade": self.proposal_grade,
            },
            "proposal_rejections": None if sr is None else sr.rejections(),
            "seconds": self.seconds,
        }


def perceive(
    stream: Stream,
    hose: int,
    start_segment: np.ndarray,
    grasp_centre_world: np.ndarray | None,
    reachable: Any,
    T_world_camera: np.ndarray,
    method: str = "correlation",
    flow: str = "dis",
) -> Perceived:
    """Segment ``stream``, score the mask (votes >= 1) against the target frame's labels of
    ``hose``, and propose the next grasp as exploration does (the first grasp blacklisted, the
    proposal cut to its front-most part in depth), graded against the labels."""

    t0 = time.perf_counter()
    out = Perceived()
    out.seg = segment_stream(stream, method=method, flow=flow)
    target = stream.target
    truth = None if target.truth is None else target.truth.labels == hose
    if truth is not None:
        out.scores = scores_dict(out.seg.mask(1), truth)
    sampler = GraspSampler(reachability=reachable)
    if grasp_centre_world is not None:
        T = np.asarray(T_world_camera, float)
        centre_cam = (np.asarray(grasp_centre_world, float) - T[:3, 3]) @ T[:3, :3]
        sampler.add_grasp(centre_cam, start_segment, blacklist=True)
    out.proposal = sampler.propose(out.seg.votes, target.depth, target.intrinsics)
    if out.proposal.proposal is not None:
        # the front-most part in depth, as exploration aims it (votes bleed onto the board)
        out.segment = front_segment(out.proposal.proposal.mask, target.depth)
        if target.truth is not None:
            out.proposal_grade = grade_proposal(out.segment, target.truth.labels, hose, True)
    out.seconds = time.perf_counter() - t0
    return out


@dataclass
class TwinEpisode:
    """What :func:`twin_episode` did and measured."""

    config: EpisodeConfig
    hose: int
    result: Any  # InteractionResult
    segment: Any  # PickedSegment
    perceived: Perceived
    clock: dict[str, float] = field(default_factory=dict)  # StreamClock statistics
    twin: dict[str, float] = field(default_factory=dict)  # TwinStats summary
    truth: dict[str, Any] = field(default_factory=dict)  # TwinTruthReport summary
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def frames_kept(self) -> list[int]:
        return [a.frames_kept for a in self.result.actions]

    @property
    def gains(self) -> list[float]:
        return [a.gain for a in self.result.actions]

    def metrics(self) -> dict[str, Any]:
        return jsonable(
            {
                "seed": self.config.seed,
                "hose": self.hose,
                "interaction": self.result.to_dict(),
                "frames_kept": self.frames_kept,
                "follow_gain": self.gains,
                "clock": self.clock,
                "twin": self.twin,
                "truth": self.truth,
                "perception": self.perceived.to_dict(),
                "timings_s": self.timings,
            }
        )

    def summary(self) -> str:
        r = self.result
        lines = [f"twin episode seed {self.config.seed}, hose {self.hose}: {r.summary()}"]
        c = self.clock
        if c:
            lines.append(
                f"  stream clock: {c.get('frames', 0)} frames, skew median "
                f"{1000 * c.get('skew_median_s', math.nan):.1f} ms, max "
                f"{1000 * c.get('skew_max_s', math.nan):.1f} ms"
            )
        t = self.twin
        if t:
            lines.append(
                f"  twin: {t['frames']} frames at {t['frame_rate_hz']} Hz "
                f"({t['dropped_frames']} dropped), lag median {t['lag_ms_median']:.0f} ms "
                f"(max {t['lag_ms_max']:.0f}), tracking {t['tracking_mm_median']:.1f} mm "
                f"(p95 {t['tracking_mm_p95']:.1f}), skipped {t['skipped_s']:.2f} s"
            )
        s = self.perceived.scores
        if s:
            lines.append(
                f"  perception: P {s['precision']:.3f} R {s['recall']:.3f} F0.4 {s['f0.4']:.3f}"
                f"; next proposal: {self.perceived.proposal_grade}"
            )
        return "\n".join(lines)


def twin_episode(
    config: EpisodeConfig,
    host: str = HOST,
    fps: float = 15.0,
    method: str = "correlation",
    flow: str = "dis",
    say: Say = quiet,
    robot_options: dict[str, Any] | None = None,
    monitor_every: float = 0.0,
    camera_timeout: float = 5.0,
    drain: float = 120.0,
    max_lag: float = 120.0,
) -> TwinEpisode:
    """One interaction on the franka-sim server at ``host`` with a twin of ``config``'s scene
    (module docstring).  The server must be running (:class:`FrankaSimServer`), its virtual
    gripper object as wide as the hose.  ``monitor_every`` > 0: ``say`` the twin's
    statistics every so many seconds while it follows.  ``drain``: how long the clock waits
    after an action for the frames the twin rendered of it (the twin may lag).  ``max_lag``:
    the twin's (:class:`TwinWorld`): on a host too loaded for the twin to keep real time
    (physics 0.77x real time with a CI run and tests/robot side by side on 2 cores) its lag
    grew past 20 s within an interaction, and skipping ahead dropped a whole action's frames;
    with both at 120 s the twin re-enacts every action, late."""

    cfg = config
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    twin = TwinWorld(cfg, fps=fps, max_lag=max_lag)
    robot = feed = camera = monitor = None
    try:
        timings["build"] = time.perf_counter() - t0
        say(f"twin of seed {cfg.seed} built in {timings['build']:.1f} s")
        options = dict(FRANKA_SIM_ROBOT, **(robot_options or {}))
        robot = FrankyPanda(
            host, twin.T_world_camera, twin.T_world_base, obstacles=twin.obstacles, **options
        )
        # the robot starts where the twin's arm waits (the twin does not follow yet)
        if not robot.open(cfg.interaction.grasp.open_width):
            raise RuntimeError("the gripper did not open")
        r = robot.move_joints(np.asarray(twin.park), speed_factor=0.5, check=False)
        if not r:
            raise RuntimeError(f"could not bring the robot to the twin's park pose: {r.reason}")
        twin.attach(FrankySource(robot))
        t1 = time.perf_counter()
        hose, picked = twin.pick_start(robot)
        timings["pick"] = time.perf_counter() - t1
        say(f"start segment: hose {hose}, {int(picked.mask.sum())} px at {picked.centre_px}")
        feed = SoftwareRealSense(twin.intrinsics, fps=round(fps))
        twin.outputs.append(lambda f: feed.push(f.rgb, f.depth, f.stamp))
        twin.follow()
        monitor = _Monitor(twin, say, every=monitor_every) if monitor_every else None
        camera = feed.camera(twin.T_world_camera, timeout_s=camera_timeout)
        # frames are paired with the pose measured when they were taken (their twin time),
        # not when they arrived: a loaded machine makes the twin lag
        clock = StreamClock(
            robot, camera, frame_time=twin.frame_time, drain=drain, history=drain + 10.0
        )
        truth = TwinTruth(twin)
        t1 = time.perf_counter()
        interaction = cfg.interaction.fitted(2 * cfg.scene.hoses.cable(hose).radius)
        result = run_interaction(
            robot,
            camera,
            clock,
            picked.mask,
            interaction,
            truth=truth,
            options=InteractionOptions(say=say, hose=hose, park=twin.park),
        )
        timings["interaction"] = time.perf_counter() - t1
        twin.pause()
        twin.check()
        perceived = Perceived()
        if result.success and result.stream is not None:
            reachable = grasp_reachability(robot, twin.T_world_camera, interaction)
            perceived = perceive(
                result.stream,
                hose,
                picked.mask,
                result.centre,
                reachable,
                twin.T_world_camera,
                method,
                flow,
            )
            timings["perception"] = perceived.seconds
        timings["total"] = time.perf_counter() - t0
        return TwinEpisode(
            cfg,
            hose,
            result,
            picked,
            perceived,
            clock=clock.stats.summary(),
            twin=twin.stats.summary(),
            truth=truth.report.summary(),
            timings=timings,
        )
    finally:
        if monitor is not None:
            monitor.stop()
        if camera is not None:
            camera.close()
        twin.close()
        if feed is not None:
            feed.close()
        if robot is not None:
            robot.close()


class _Monitor:
    """Says the twin's statistics every ``every`` seconds on a thread."""

    def __init__(self, twin: Any, say: Say, every: float) -> None:
        self._stop = threading.Event()

        def run() -> None:
            while not self._stop.wait(every):
                st = twin.stats
                state = twin.state()
                say(
                    f"twin: {st.steps} steps, {st.frames} frames ({st.dropped} dropped), "
                    f"lag {1000 * state.lag:.0f} ms, skipped {st.skipped_s:.2f} s, "
                    f"joint error {state.joint_error:.4f} rad"
                )

        self._thread = threading.Thread(target=run, name="cablesim-twin-monitor", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


def sim_episode(
    config: EpisodeConfig, method: str = "correlation", flow: str = "dis"
) -> tuple[Any, Perceived]:
    """The same seed in pure simulation and the same perception: (SimulatedEpisode, Perceived)."""

    ep = simulate_episode(config)
    try:
        res = ep.result
        perceived = Perceived()
        if res.success and res.stream is not None:
            session = ep.session
            reachable = grasp_reachability(
                session.robot, session.T_world_camera, session.interaction_config()
            )
            perceived = perceive(
                res.stream,
                int(session.hose),
                ep.segment.mask,
                res.centre,
                reachable,
                session.T_world_camera,
                method,
                flow,
            )
        return ep, perceived
    finally:
        ep.close()
