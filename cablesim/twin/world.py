"""The digital twin: a cablesim world that follows a real-protocol robot in real time.

    twin = TwinWorld(EpisodeConfig.of(seed=0))                   # built, settled, paused
    robot = FrankyPanda(host, twin.T_world_camera, twin.T_world_base,
                        obstacles=twin.obstacles, realtime=False)
    robot.move_joints(twin.park, check=False)     # the robot starts where the twin's arm is
    twin.attach(FrankySource(robot))
    hose, picked = twin.pick_start(robot)                     # seeded, as in pure simulation
    feed = SoftwareRealSense(twin.intrinsics)                 # cablesim.twin.realsense
    twin.outputs.append(lambda f: feed.push(f.rgb, f.depth, f.stamp))
    twin.follow()                                             # real time from here on
    ...                                                       # drive the robot; read the camera
    twin.close()

The world is the scene of pure simulation (``World.build`` of the episode's ``SceneConfig``:
the same board, hoses, camera and Panda base).  Frames are mapped so that the robot's base
frame is the twin Panda's base (``T_world_base``) and the camera's pose is the twin camera's
(``T_world_camera``).

Time.  While following, the twin's own clock (the *twin time*, on ``time.monotonic()``'s time
base: the wall time the world's current state stands for) advances with the simulated time and
tracks the wall clock as closely as the CPU allows.  Two sampler threads record the robot's
measurements with their wall times (:mod:`cablesim.twin.sampling`: the joints every
``joint_period`` s, the gripper); every physics step replays them at its twin time on the
Panda's actuators (:mod:`cablesim.twin.replay`: interpolated joints, extrapolated for at most
``extrapolate`` s, the gripper at the hand's ``gripper_speed``, squeezing the hose while the
robot reports a grasp).  So the twin re-enacts the robot's motion faithfully even when a loaded
machine makes it fall behind the wall clock (the *lag*); it catches up as fast as its physics
runs.  Only beyond ``max_lag`` it skips ahead (counted; the arm then jumps).

Frames.  RGB-D and labels are rendered every ``1 / fps`` s of twin time, at the physics step
of that time, stamped with their twin time (seconds since following started: the camera
device's clock) and handed to the callables in ``outputs``; they are kept ``history`` s for
:meth:`frame_at`.  While the lag exceeds ``frame_lag`` frames are dropped (counted) to let the
physics catch up, but one is rendered at least every ``max_frame_gap`` s of wall time.

Rendering.  The hoses (flex edges drawn as capsules) dominate the cost of a frame on a software
OpenGL: with MuJoCo's default tessellation (28 slices, 16 stacks) a 320x240 RGB-D + labels frame
costs about 19 ms of CPU, with ``tessellation=(12, 6)`` (the default here) about 9 ms; at
320x240 that moves 1.3% of the hose label pixels (30 of 2351, seed 0) and shades the hoses
slightly differently.  ``tessellation=None`` keeps the scene's own setting (pure simulation's);
the start segment is always picked in an image of the scene's own setting.  The setting is
written into the world's model when a renderer is made.

Threads.  The *twin thread* owns the MuJoCo data and the renderer (MuJoCo rendering contexts
belong to the thread that made them).  Other threads read published copies (:meth:`state`,
:meth:`frame_at`), wait for the twin to have re-enacted the present (:meth:`synced`) or run code
on the twin thread (:meth:`call`).  ``nice`` > 0 lowers the twin thread's priority below the
rest of the process (the robot's control loop).
"""

from __future__ import annotations

import concurrent.futures
import math
import os
import queue
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import mujoco
import numpy as np

from cablesim.errors import InputError
from cablesim.frames import Intrinsics
from cablesim.panda.ik import ArmModel, Obstacle, static_obstacles
from cablesim.panda.model import joint_qpos_addresses, robot_body_ids
from cablesim.pose import Pose
from cablesim.seeding import stream
from cablesim.sim.camera import SimCamera, intrinsics_from_fovy
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.session import choose_start
from cablesim.sim.world import World
from cablesim.twin.replay import KV_OVER_KP, Replay
from cablesim.twin.sampling import Samplers
from cablesim.twin.sources import FrankySource, ReplaySource, RobotSource
from cablesim.twin.state import FrameHistory, StateBoard, TwinFrame, TwinState, TwinStats

__all__ = [
    "KV_OVER_KP",
    "FrankySource",
    "ReplaySource",
    "RobotSource",
    "TwinFrame",
    "TwinState",
    "TwinStats",
    "TwinWorld",
]

T = TypeVar("T")

#: Measurements kept behind the twin time (s).
_KEEP = 2.0


class TwinWorld:
    """See the module docstring.  ``config``: the episode (seed, scene, interaction) whose
    scene the twin builds; ``fps``: frames per second (of twin time, i.e. wall time when the
    twin keeps up); ``world``: an already built world of that scene (reset here)."""

    def __init__(
        self,
        config: EpisodeConfig,
        fps: float = 15.0,
        *,
        world: World | None = None,
        max_lag: float = 20.0,
        frame_lag: float = 0.3,
        max_frame_gap: float = 0.2,
        joint_period: float = 0.004,
        extrapolate: float = 0.05,
        history: float = 4.0,
        nice: int = 0,
        tessellation: tuple[int, int] | None = (12, 6),
        settle_time: float = 0.1,
        finger_rest_speed: float = 0.002,
        gripper_speed: tuple[float, float] = (0.05, 0.1),
    ) -> None:
        self.cfg = config
        if not 0 < fps <= 60:
            raise InputError(f"fps must be in (0, 60], got {fps}")
        self.fps = float(fps)
        self.max_lag = float(max_lag)
        self.frame_lag = float(frame_lag)
        self.max_frame_gap = float(max_frame_gap)
        self.nice = int(nice)
        if world is None:
            world = World.build(self.cfg.scene)
        world.reset()
        if world.panda is None or world.panda_base is None:
            raise InputError("the twin needs a scene with the Panda (robot.enabled)")
        self.world = world
        m, d = world.model, world.data
        self._scene_tessellation = (int(m.vis.quality.numslices), int(m.vis.quality.numstacks))
        self.tessellation = self._scene_tessellation if tessellation is None else tessellation
        n = world.panda
        self._qadr = joint_qpos_addresses(m, n.joints)
        self._finger_qadr = joint_qpos_addresses(m, n.finger_joints)
        self._site = m.site(n.site).id
        self._dt = float(m.opt.timestep)
        mujoco.mj_forward(m, d)
        self.obstacles: list[Obstacle] = static_obstacles(
            m, d, exclude_bodies=robot_body_ids(m, n.prefix)
        )
        pos, quat = world.panda_base
        self._arm = ArmModel(pos, quat)  # twin thread only: the replayed TCP for tracking
        c = world.cfg.camera
        self.width, self.height = int(c.width), int(c.height)
        self.intrinsics: Intrinsics = intrinsics_from_fovy(
            self.width, self.height, float(m.cam_fovy[world.camera_id])
        )
        self.outputs: list[Callable[[TwinFrame], None]] = []
        self.stats = TwinStats(timestep=self._dt)
        self.camera: SimCamera | None = None  # created on the twin thread
        self.source: RobotSource | None = None
        self.error: BaseException | None = None

        self._lock = threading.Lock()  # guards the follow request
        self._calls: queue.Queue[tuple[Callable[[TwinWorld], Any], concurrent.futures.Future]] = (
            queue.Queue()
        )
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._follow_request: bool | None = None
        self._following = False
        self._samplers = Samplers(joint_period, self._stop, self._fail)
        self._replay = Replay(
            world,
            self._samplers.joints,
            self._samplers.gripper,
            extrapolate=extrapolate,
            hose_diameter=float(world.cfg.hoses.max_diameter()),
            gripper_speed=gripper_speed,
            settle_time=settle_time,
            finger_rest_speed=finger_rest_speed,
            q=self.q,
            opening=self.opening,
        )
        self._frames = FrameHistory(history)
        self._frame_number = 0
        self._t0 = 0.0  # wall time following started (the frame clock's zero)
        self._wall0 = self._sim0 = 0.0  # twin time = _wall0 + (sim time - _sim0)
        self._next_frame = 0.0
        self._last_render = -math.inf
        self._follow_started = 0.0
        self._board = StateBoard(self._make_state())
        self._thread = threading.Thread(target=self._run, name="cablesim-twin", daemon=True)
        self._ready = threading.Event()
        self._thread.start()
        if not self._ready.wait(60.0) or self.error is not None:
            self.close()
            raise RuntimeError(f"the twin thread did not start: {self.error!r}")

    # ------------------------------------------------------------------ options
    @property
    def joint_period(self) -> float:
        """Seconds between joint samples."""
        return self._samplers.joint_period

    @property
    def extrapolate(self) -> float:
        """Seconds the joints are extrapolated past the newest sample, at most."""
        return self._replay.extrapolate

    @property
    def history(self) -> float:
        """Seconds of wall time rendered frames are kept for :meth:`frame_at`."""
        return self._frames.seconds

    @property
    def settle_time(self) -> float:
        return self._replay.settle_time

    @property
    def finger_rest_speed(self) -> float:
        return self._replay.finger_rest_speed

    @property
    def gripper_speed(self) -> tuple[float, float]:
        return self._replay.gripper_speed

    @property
    def hose_diameter(self) -> float:
        return self._replay.hose_diameter

    # ------------------------------------------------------------------ frames and poses
    @property
    def T_world_base(self) -> np.ndarray:
        """The robot base in the world (4x4): give it to the robot adapter."""
        pos, quat = self.world.panda_base  # type: ignore[misc]
        return Pose(pos, quat).matrix()

    @property
    def T_world_camera(self) -> np.ndarray:
        return self.world.T_world_camera.copy()

    @property
    def park(self) -> tuple[float, ...]:
        """Where the twin's arm starts and waits (the scene's park configuration)."""
        return tuple(float(q) for q in self.world.cfg.robot.park_qpos)

    @property
    def q(self) -> np.ndarray:
        return self.world.data.qpos[self._qadr].copy()

    @property
    def opening(self) -> float:
        return float(np.sum(self.world.data.qpos[self._finger_qadr]))

    # ------------------------------------------------------------------ control
    def attach(self, source: RobotSource) -> None:
        """Read the robot's state from ``source`` (before :meth:`follow`)."""
        if self._following:
            raise InputError("attach the robot source before following")
        self.source = source

    def call(self, fn: Callable[[TwinWorld], T], timeout: float = 120.0) -> T:
        """Run ``fn(twin)`` on the twin thread (rendering, picking) and return its result."""
        if threading.current_thread() is self._thread:
            return fn(self)
        self.check()
        fut: concurrent.futures.Future = concurrent.futures.Future()
        self._calls.put((fn, fut))
        self._wake.set()
        return fut.result(timeout)

    def pick_start(self, robot: Any, interaction: Any = None) -> tuple[int, Any]:
        """The seeded hose of interest and start segment, chosen exactly as pure simulation
        chooses them (:func:`cablesim.sim.session.choose_start` on the draw's ``episode``
        stream), in the twin's current image; call it before :meth:`follow`, while the twin
        still shows the settled scene.  ``robot`` judges reachability.  The twin does not
        re-draw its scene: a draw with no qualifying hose raises ``NoGraspableSegmentError``
        (give the draw that pure simulation used: ``SceneConfig.draw``)."""
        draw = self.cfg.scene.draw
        rng = stream(self.cfg.seed, "episode", *((draw,) if draw else ()))
        cfg = self.cfg if interaction is None else self.cfg.replace(interaction=interaction)

        def pick(twin: TwinWorld) -> tuple[int, Any]:
            # with the scene's own tessellation: the same image as pure simulation's
            camera = twin._camera(twin._scene_tessellation)
            try:
                return choose_start(twin.world, robot, camera, rng, cfg, f"draw {draw}")
            finally:
                camera.close()

        return self.call(pick)

    def follow(self, max_joint_error: float = 0.05, timeout: float = 10.0) -> None:
        """Start following the attached robot.  The robot must stand where the twin's arm is
        (within ``max_joint_error`` rad per joint), or the twin arm would jump through the
        scene."""
        if self.source is None:
            raise InputError("attach a robot source first (twin.attach)")
        self.check()
        q, _ = self.source.joint_state()
        err = float(np.max(np.abs(np.asarray(q) - self._board.latest().q)))
        if err > max_joint_error:
            raise InputError(
                f"the robot's joints are {err:.3f} rad from the twin's arm (tolerance "
                f"{max_joint_error}); move the robot to the twin's configuration first"
            )
        start = time.monotonic()
        self._samplers.start(self.source)
        deadline = start + timeout
        while (
            self._samplers.joints.newest_time() < start
            or self._samplers.gripper.newest_time() < start
        ) and time.monotonic() < deadline:
            self.check()
            time.sleep(0.002)
        with self._lock:
            self._follow_request = True
        self._wake.set()
        self.wait_state(lambda s: s.following, max(0.0, deadline - time.monotonic()))
        if not self._following:
            self.check()
            raise RuntimeError(f"the twin did not start following within {timeout} s")

    def pause(self, timeout: float = 10.0) -> None:
        """Stop following (the world stands still; frames stop)."""
        with self._lock:
            self._follow_request = False
        self._wake.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self.wait_state(lambda s: not s.following, timeout)
        self._samplers.stop()

    def close(self, timeout: float = 10.0) -> None:
        """Stop following, close the renderer on the twin thread and end the threads."""
        self._stop.set()
        self._wake.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        self._samplers.stop()

    def __enter__(self) -> TwinWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def check(self) -> None:
        """Raise the twin's error, if it had one."""
        if self.error is not None:
            raise RuntimeError(f"the digital twin stopped: {self.error!r}") from self.error

    def _fail(self, error: BaseException) -> None:
        """A sampler thread's error: keep it and stop the twin."""
        self.error = error
        self._stop.set()
        self._wake.set()

    # ------------------------------------------------------------------ reading
    def state(self) -> TwinState:
        return self._board.latest()

    def wait_state(self, predicate: Callable[[TwinState], bool], timeout: float) -> TwinState:
        """The first published state (the current one, or a later one) for which
        ``predicate`` holds, or the latest after ``timeout`` s."""
        return self._board.wait(
            predicate,
            timeout,
            give_up=lambda: self.error is not None or not self._thread.is_alive(),
        )

    def synced(
        self, timeout: float = 2.0, joint_tolerance: float = 0.003
    ) -> tuple[TwinState, bool]:
        """The twin's state once it has re-enacted the robot up to now: joint and gripper
        measurements taken after this call applied, the arm within ``joint_tolerance`` rad of
        them and the fingers at rest; (state, True), or (latest state, False) after
        ``timeout`` s."""
        t = time.monotonic()

        def caught_up(s: TwinState) -> bool:
            return (
                s.joints_measured_at > t
                and s.gripper_measured_at > t
                and s.joint_error <= joint_tolerance
                and s.fingers_settled
            )

        s = self.wait_state(caught_up, timeout)
        return s, caught_up(s)

    def frame_at(self, stamp: float, tolerance: float = 5e-4) -> TwinFrame | None:
        """The rendered frame with timestamp ``stamp`` (s on the frame clock), if still kept."""
        return self._frames.at(stamp, tolerance)

    def frame_time(self, image: Any) -> float:
        """When a frame the twin rendered was taken, on ``time.monotonic()``'s time base (the
        twin time it shows), from its timestamp (a camera's ``CameraImage.timestamp``): give it
        to ``StreamClock(frame_time=...)``."""
        return self._t0 + float(image.timestamp)

    def latest_frame(self) -> TwinFrame | None:
        return self._frames.latest()

    # ------------------------------------------------------------------ the twin thread
    def _camera(self, tessellation: tuple[int, int]) -> SimCamera:
        """A renderer with ``tessellation`` (twin thread only)."""
        q = self.world.model.vis.quality
        q.numslices, q.numstacks = (int(x) for x in tessellation)
        return SimCamera(self.world, self.width, self.height)

    def _run(self) -> None:
        try:
            if self.nice > 0:
                tid = threading.get_native_id()
                try:
                    niceness = os.getpriority(os.PRIO_PROCESS, tid) + self.nice
                    os.setpriority(os.PRIO_PROCESS, tid, niceness)
                except (OSError, AttributeError):  # pragma: no cover - not Linux
                    pass
            self.camera = self._camera(self.tessellation)
            self._ready.set()
            while not self._stop.is_set():
                self._serve_calls()
                self._handle_follow_request()
                if not self._following:
                    self._wake.wait(0.01)
                    self._wake.clear()
                    continue
                self._advance()
        except BaseException as e:  # noqa: BLE001 - handed to the other threads
            self.error = e
        finally:
            if self._following:
                self.stats.followed_s += time.monotonic() - self._follow_started
            self._following = False
            self._ready.set()
            self._publish()
            if self.camera is not None:
                self.camera.close()
            while True:
                try:
                    _, fut = self._calls.get_nowait()
                except queue.Empty:
                    break
                fut.set_exception(RuntimeError("the digital twin was closed"))

    def _serve_calls(self) -> None:
        while True:
            try:
                fn, fut = self._calls.get_nowait()
            except queue.Empty:
                return
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                fut.set_result(fn(self))
            except BaseException as e:  # noqa: BLE001 - handed to the caller
                fut.set_exception(e)

    def _handle_follow_request(self) -> None:
        with self._lock:
            request, self._follow_request = self._follow_request, None
        if request is None or request == self._following:
            return
        now = time.monotonic()
        if request:
            self._wall0, self._sim0 = now, self.world.time
            self._next_frame = self._follow_started = now
            if self._frame_number == 0:  # the frame clock starts once (a camera reads it)
                self._t0 = now
        else:
            self.stats.followed_s += now - self._follow_started
        self._following = request
        self._publish()

    @property
    def _twin_time(self) -> float:
        return self._wall0 + (self.world.time - self._sim0)

    def _advance(self) -> None:
        """Step the physics towards the wall clock, replaying the measurements; render the
        frames that fall due on the way."""
        now = time.monotonic()
        if now - self._twin_time > self.max_lag:  # hopelessly behind: skip ahead
            skip = now - self._twin_time - self._dt
            self._wall0 += skip
            self._next_frame = max(self._next_frame, self._twin_time)
            self.stats.skipped_s += skip
            self.stats.skips += 1
        t0 = time.perf_counter()
        budget = t0 + 0.02  # s per pass: then publish, serve calls, look at the clock again
        period = 1.0 / self.fps
        while self._twin_time + 0.5 * self._dt <= now:
            self._replay.command(self._twin_time + self._dt)
            self.world.step(1)
            self.stats.steps += 1
            self._replay.watch_fingers()
            if self._twin_time + 0.5 * self._dt >= self._next_frame:
                wall = time.monotonic()
                lag = wall - self._twin_time
                if lag <= self.frame_lag or wall - self._last_render >= self.max_frame_gap:
                    self.stats.physics_s += time.perf_counter() - t0
                    self._render(wall)
                    t0 = time.perf_counter()
                else:
                    self.stats.dropped += 1
                self._next_frame += period
            if time.perf_counter() > budget:
                break
        self.stats.physics_s += time.perf_counter() - t0
        self._samplers.joints.forget_before(self._twin_time - _KEEP)
        self._samplers.gripper.forget_before(self._twin_time - _KEEP)
        self._publish()
        wait = self._twin_time + self._dt - time.monotonic()
        if wait > 0:
            self._wake.wait(wait)
            self._wake.clear()

    def _make_state(self) -> TwinState:
        d, r = self.world.data, self._replay
        width, grasped, t_grip = r.gripper_in_effect
        return TwinState(
            wall=time.monotonic(),
            twin_time=self._twin_time if self._following else time.monotonic(),
            sim_time=float(d.time),
            following=self._following,
            q=self.q,
            q_target=np.asarray(r.q_target, float).copy(),
            joints_measured_at=r.joint_at,
            gripper_measured=(width, grasped),
            gripper_measured_at=t_grip,
            gripper_ctrl=r.gripper_ctrl,
            tcp=d.site_xpos[self._site].copy(),
            tcp_rotation=d.site_xmat[self._site].reshape(3, 3).copy(),
            opening=self.opening,
            fingers_settled=r.fingers_settled,
            hose_vertices=tuple(self.world.hose_vertices(i) for i in range(len(self.world.hoses))),
        )

    def _publish(self) -> None:
        self._board.publish(self._make_state())

    def _render(self, wall: float) -> None:
        assert self.camera is not None
        t0 = time.perf_counter()
        self._last_render = wall
        snap = self.camera.snapshot()
        state = self._make_state()
        frame = TwinFrame(
            self._frame_number, state.twin_time - self._t0, state.twin_time, wall, snap, state
        )
        self._frame_number += 1
        replayed = self._arm.fk(state.q_target)
        self.stats.tracking_mm.append(1000.0 * float(np.linalg.norm(replayed.position - state.tcp)))
        self.stats.lag_ms.append(1000.0 * (wall - state.twin_time))
        self._frames.add(frame)
        for out in tuple(self.outputs):
            out(frame)
        self.stats.frames += 1
        self.stats.render_s += time.perf_counter() - t0
