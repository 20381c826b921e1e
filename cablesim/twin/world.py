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
measurements with their wall times: the joints (every ``joint_period`` s) and the gripper (a
franky gripper read blocks until the hand's next state packet: 60 Hz on franka-sim).  Every
physics step replays them at its twin time: the Panda's arm position actuators get the joint
positions interpolated at that time (extrapolated with the measured velocities for at most
``extrapolate`` s past the newest sample), plus ``SimPanda``'s velocity feed-forward; the
gripper actuator gets the opening measured then -- or 0, closing with its force limit on the
hose, while the robot reports a grasp at an opening no wider than the hose (franka-sim's gripper
stops at a virtual object; here the fingers must really squeeze the 15 mm hose for the friction
grasp to hold).  The gripper command moves at the hand's speed (``gripper_speed``: closing,
opening; franky's defaults), since franka-sim's kinematic hand jumps.  So the twin re-enacts the robot's motion faithfully even when a loaded machine
makes it fall behind the wall clock (the *lag*); it catches up as fast as its physics runs.
Only beyond ``max_lag`` it skips ahead (counted; the arm then jumps).

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

import bisect
import collections
import concurrent.futures
import math
import os
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import mujoco
import numpy as np

from cablesim.errors import InputError
from cablesim.panda.description import MAX_OPENING
from cablesim.panda.ik import ArmModel, Obstacle, static_obstacles
from cablesim.panda.model import joint_qpos_addresses, robot_body_ids
from cablesim.perception.frames import Intrinsics
from cablesim.sim.camera import SimCamera, SimSnapshot, intrinsics_from_fovy
from cablesim.sim.config import EpisodeConfig
from cablesim.sim.world import World

T = TypeVar("T")

#: Velocity feed-forward through the position target: kv / kp of the arm actuators (SimPanda's).
KV_OVER_KP = 0.1
#: Measurements kept behind the twin time (s).
_KEEP = 2.0


class RobotSource(Protocol):
    """Where the twin reads the robot's measured state."""

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Measured arm joint positions (7,) and velocities (7,)."""

    def gripper_state(self) -> tuple[float, bool]:
        """Measured finger opening (m) and whether the hand reports a grasp."""


class FrankySource:
    """The measured state of a :class:`~cablesim.robot.franky_panda.FrankyPanda` (franky)."""

    def __init__(self, robot: Any) -> None:
        self.robot = robot

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.robot.robot.current_joint_state
        return (
            np.asarray(s.position, dtype=float).reshape(7),
            np.asarray(s.velocity, dtype=float).reshape(7),
        )

    def gripper_state(self) -> tuple[float, bool]:
        gripper = self.robot.gripper
        if gripper is None:
            return math.nan, False
        s = gripper.state
        return float(s.width), bool(s.is_grasped)


class ReplaySource:
    """A :class:`RobotSource` that replays timed way points, e.g. a logged robot session:
    ``joints`` as (t, q) pairs, piecewise linear between them; ``gripper`` as
    (t, opening, grasped) steps.  Times are seconds since :meth:`start` (or the first read)."""

    def __init__(
        self,
        joints: Sequence[tuple[float, Sequence[float]]],
        gripper: Sequence[tuple[float, float, bool]] = ((0.0, MAX_OPENING, False),),
    ) -> None:
        if not joints or not gripper:
            raise InputError("a replay needs at least one joint and one gripper way point")
        self.times = np.asarray([float(t) for t, _ in joints])
        self.q = np.asarray([np.asarray(q, float).reshape(7) for _, q in joints])
        if np.any(np.diff(self.times) <= 0):
            raise InputError("joint way points must be in increasing time order")
        self.gripper = sorted((float(t), float(w), bool(g)) for t, w, g in gripper)
        self.t0: float | None = None

    def start(self, t0: float | None = None) -> None:
        self.t0 = time.monotonic() if t0 is None else float(t0)

    def _t(self) -> float:
        if self.t0 is None:
            self.start()
        assert self.t0 is not None
        return time.monotonic() - self.t0

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        t = self._t()
        i = int(np.searchsorted(self.times, t, side="right"))
        if i == 0:
            return self.q[0].copy(), np.zeros(7)
        if i >= len(self.times):
            return self.q[-1].copy(), np.zeros(7)
        t0, t1 = self.times[i - 1], self.times[i]
        rate = (self.q[i] - self.q[i - 1]) / (t1 - t0)
        return self.q[i - 1] + rate * (t - t0), rate

    def gripper_state(self) -> tuple[float, bool]:
        t = self._t()
        _, width, grasped = self.gripper[0]
        for tg, w, g in self.gripper:
            if tg <= t:
                width, grasped = w, g
        return width, grasped


class _Track:
    """Time-stamped measurements (appended by a sampler, read by the twin thread)."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.values: list[Any] = []
        self.lock = threading.Lock()

    def add(self, t: float, value: Any) -> None:
        with self.lock:
            self.times.append(t)
            self.values.append(value)

    def newest_time(self) -> float:
        with self.lock:
            return self.times[-1] if self.times else -math.inf

    def around(self, t: float) -> tuple[tuple[float, Any] | None, tuple[float, Any] | None]:
        """The newest sample at or before ``t`` and the first one after it."""
        with self.lock:
            i = bisect.bisect_right(self.times, t)
            before = (self.times[i - 1], self.values[i - 1]) if i > 0 else None
            after = (self.times[i], self.values[i]) if i < len(self.times) else None
            return before, after

    def forget_before(self, t: float) -> None:
        """Drop samples older than ``t`` (keeping the newest one at or before it)."""
        with self.lock:
            i = bisect.bisect_right(self.times, t) - 1
            if i > 0:
                del self.times[:i]
                del self.values[:i]


@dataclass(frozen=True)
class TwinState:
    """A published copy of the twin's state (read by other threads)."""

    wall: float  # time.monotonic() when published
    twin_time: float  # the wall time the world's state stands for (monotonic time base)
    sim_time: float  # the world's simulated time
    following: bool
    q: np.ndarray  # twin arm joints (7,)
    q_target: np.ndarray  # the measured joints replayed at twin_time (7,)
    joints_measured_at: float  # wall time of the newest joint sample replayed
    gripper_measured: tuple[float, bool]  # opening (m) and grasp flag in effect at twin_time
    gripper_measured_at: float  # wall time of that gripper sample
    gripper_ctrl: float  # the twin gripper's command (m; 0 = closing with force)
    tcp: np.ndarray  # twin grasp-site position (world)
    tcp_rotation: np.ndarray  # 3x3
    opening: float  # twin finger opening (m)
    fingers_settled: bool  # the fingers have rested since their command last changed
    hose_vertices: tuple[np.ndarray, ...]

    @property
    def joint_error(self) -> float:
        """Largest difference (rad) between the twin's arm and the replayed measurement."""
        return float(np.max(np.abs(self.q - self.q_target)))

    @property
    def lag(self) -> float:
        """How far (s) the twin was behind the wall clock when this was published."""
        return self.wall - self.twin_time


@dataclass
class TwinFrame:
    """One rendered frame of the twin."""

    number: int
    stamp: float  # s of twin time since following started: the camera device's timestamp
    twin_time: float  # the wall time the frame shows (monotonic time base)
    wall: float  # time.monotonic() when rendered
    snapshot: SimSnapshot
    state: TwinState

    @property
    def rgb(self) -> np.ndarray:
        return self.snapshot.image.rgb

    @property
    def depth(self) -> np.ndarray:
        return self.snapshot.image.depth


@dataclass
class TwinStats:
    """What the twin measured about itself while following."""

    steps: int = 0
    frames: int = 0
    followed_s: float = 0.0  # wall time spent following
    skipped_s: float = 0.0  # twin time skipped because the twin fell too far behind
    skips: int = 0
    dropped: int = 0  # frames not rendered to let the physics catch up
    render_s: float = 0.0
    physics_s: float = 0.0
    lag_ms: list[float] = field(default_factory=list)  # per frame: wall - twin time
    tracking_mm: list[float] = field(default_factory=list)  # per frame: TCP, twin vs replayed
    timestep: float = 0.004  # s per physics step

    def summary(self) -> dict[str, float]:
        def q(x: list[float], p: float) -> float:
            return float(np.percentile(x, p)) if x else math.nan

        return {
            "steps": self.steps,
            "frames": self.frames,
            "followed_s": round(self.followed_s, 3),
            "frame_rate_hz": round(self.frames / self.followed_s, 2) if self.followed_s else 0.0,
            "dropped_frames": self.dropped,
            "skipped_s": round(self.skipped_s, 3),
            "skips": self.skips,
            "render_ms_per_frame": round(1000 * self.render_s / max(self.frames, 1), 2),
            "physics_realtime_factor": round(
                self.steps * self.timestep / self.physics_s if self.physics_s else 0.0, 2
            ),
            "lag_ms_median": q(self.lag_ms, 50),
            "lag_ms_max": max(self.lag_ms) if self.lag_ms else math.nan,
            "tracking_mm_median": q(self.tracking_mm, 50),
            "tracking_mm_p95": q(self.tracking_mm, 95),
        }


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
        self.joint_period = float(joint_period)
        self.extrapolate = float(extrapolate)
        self.history = float(history)
        self.nice = int(nice)
        self.settle_time = float(settle_time)
        self.finger_rest_speed = float(finger_rest_speed)
        self.gripper_speed = (float(gripper_speed[0]), float(gripper_speed[1]))
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
        self._finger_dofadr = np.asarray([m.jnt_dofadr[m.joint(j).id] for j in n.finger_joints])
        self._act = np.asarray([m.actuator(a).id for a in n.actuators])
        self._gripper_act = m.actuator(n.gripper_actuator).id
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
        self.hose_diameter = 2.0 * float(world.cfg.hoses.radius)
        self.outputs: list[Callable[[TwinFrame], None]] = []
        self.stats = TwinStats(timestep=self._dt)
        self.camera: SimCamera | None = None  # created on the twin thread
        self.source: RobotSource | None = None
        self.error: BaseException | None = None

        self._lock = threading.Lock()
        self._published = threading.Condition(self._lock)
        self._calls: queue.Queue[tuple[Callable[[TwinWorld], Any], concurrent.futures.Future]] = (
            queue.Queue()
        )
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._follow_request: bool | None = None
        self._following = False
        self._joints = _Track()
        self._grip = _Track()
        self._frames: collections.deque[TwinFrame] = collections.deque()
        self._frame_number = 0
        self._t0 = 0.0  # wall time following started (the frame clock's zero)
        self._wall0 = self._sim0 = 0.0  # twin time = _wall0 + (sim time - _sim0)
        self._next_frame = 0.0
        self._last_render = -math.inf
        self._follow_started = 0.0
        self._q_target = self.q
        self._joint_at = -math.inf
        self._gripper_in_effect: tuple[float, bool, float] = (self.opening, False, -math.inf)
        self._gripper_ctrl = float(d.ctrl[self._gripper_act])  # the goal (m)
        self._gripper_cmd = self._gripper_ctrl  # the actuator command, ramped to the goal
        self._finger_still_since: float | None = None
        self._fingers_settled = True
        self._state = self._make_state()
        self._samplers: list[threading.Thread] = []
        self._sampler_stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cablesim-twin", daemon=True)
        self._ready = threading.Event()
        self._thread.start()
        if not self._ready.wait(60.0) or self.error is not None:
            self.close()
            raise RuntimeError(f"the twin thread did not start: {self.error!r}")

    # ------------------------------------------------------------------ frames and poses
    @property
    def T_world_base(self) -> np.ndarray:
        """The robot base in the world (4x4): give it to the robot adapter."""
        from cablesim.robot.pose import Pose

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
        from cablesim.seeding import stream
        from cablesim.sim.session import choose_start

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
        err = float(np.max(np.abs(np.asarray(q) - self._state.q)))
        if err > max_joint_error:
            raise InputError(
                f"the robot's joints are {err:.3f} rad from the twin's arm (tolerance "
                f"{max_joint_error}); move the robot to the twin's configuration first"
            )
        start = time.monotonic()
        self._start_samplers()
        deadline = start + timeout
        while (
            self._joints.newest_time() < start or self._grip.newest_time() < start
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
        self._stop_samplers()

    def close(self, timeout: float = 10.0) -> None:
        """Stop following, close the renderer on the twin thread and end the threads."""
        self._stop.set()
        self._wake.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        self._stop_samplers()

    def __enter__(self) -> TwinWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def check(self) -> None:
        """Raise the twin's error, if it had one."""
        if self.error is not None:
            raise RuntimeError(f"the digital twin stopped: {self.error!r}") from self.error

    # ------------------------------------------------------------------ reading
    def state(self) -> TwinState:
        with self._lock:
            return self._state

    def wait_state(self, predicate: Callable[[TwinState], bool], timeout: float) -> TwinState:
        """The first published state (the current one, or a later one) for which
        ``predicate`` holds, or the latest after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        with self._published:
            while not predicate(self._state):
                left = deadline - time.monotonic()
                if left <= 0 or self.error is not None or not self._thread.is_alive():
                    break
                self._published.wait(min(left, 0.1))
            return self._state

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
        with self._lock:
            for f in reversed(self._frames):
                if abs(f.stamp - stamp) <= tolerance:
                    return f
            return None

    def frame_time(self, image: Any) -> float:
        """When a frame the twin rendered was taken, on ``time.monotonic()``'s time base (the
        twin time it shows), from its timestamp (a camera's ``CameraImage.timestamp``): give it
        to ``StreamClock(frame_time=...)``."""
        return self._t0 + float(image.timestamp)

    def latest_frame(self) -> TwinFrame | None:
        with self._lock:
            return self._frames[-1] if self._frames else None

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
            with self._published:
                self._state = self._make_state()
                self._published.notify_all()
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

    def _joint_target(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Measured joints and velocities at wall time ``t`` (interpolated; extrapolated a
        little past the newest sample)."""
        before, after = self._joints.around(t)
        if before is None:
            if after is None:
                return self._q_target, np.zeros(7)
            (_, (q, dq)) = after
            self._joint_at = -math.inf
            return q, np.zeros(7)
        t0, (q0, dq0) = before
        self._joint_at = t0
        if after is None:
            return q0 + dq0 * min(t - t0, self.extrapolate), dq0
        t1, (q1, dq1) = after
        s = (t - t0) / max(t1 - t0, 1e-9)
        return q0 + s * (q1 - q0), dq0 + s * (dq1 - dq0)

    def _gripper_target(self, t: float) -> float:
        before, _ = self._grip.around(t)
        if before is not None:
            t_g, (width, grasped) = before
            self._gripper_in_effect = (width, grasped, t_g)
        width, grasped, _ = self._gripper_in_effect
        if grasped and width <= self.hose_diameter + 1e-3:
            return 0.0  # the robot holds something: squeeze what is between the fingers
        if math.isfinite(width):
            return float(np.clip(width, 0.0, MAX_OPENING))
        return self._gripper_ctrl

    def _advance(self) -> None:
        """Step the physics towards the wall clock, replaying the measurements; render the
        frames that fall due on the way."""
        w, d = self.world, self.world.data
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
            t = self._twin_time + self._dt
            q, dq = self._joint_target(t)
            self._q_target = q
            d.ctrl[self._act] = q + KV_OVER_KP * dq
            goal = self._gripper_target(t)
            if goal != self._gripper_ctrl:
                self._gripper_ctrl, self._finger_still_since = goal, None
                self._fingers_settled = False
            # the hand moves its fingers at its own speed (a command jumping to 0 would slam
            # them through the thin hose)
            speed = self.gripper_speed[0] if goal < self._gripper_cmd else self.gripper_speed[1]
            step = speed * self._dt
            self._gripper_cmd += float(np.clip(goal - self._gripper_cmd, -step, step))
            d.ctrl[self._gripper_act] = self._gripper_cmd
            w.step(1)
            self.stats.steps += 1
            self._watch_fingers()
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
        self._joints.forget_before(self._twin_time - _KEEP)
        self._grip.forget_before(self._twin_time - _KEEP)
        self._publish()
        wait = self._twin_time + self._dt - time.monotonic()
        if wait > 0:
            self._wake.wait(wait)
            self._wake.clear()

    def _watch_fingers(self) -> None:
        speed = float(np.max(np.abs(self.world.data.qvel[self._finger_dofadr])))
        t = self.world.time
        if speed > self.finger_rest_speed or self._gripper_cmd != self._gripper_ctrl:
            self._finger_still_since = None
        elif self._finger_still_since is None:
            self._finger_still_since = t
        elif t - self._finger_still_since >= self.settle_time:
            self._fingers_settled = True

    def _make_state(self) -> TwinState:
        d = self.world.data
        width, grasped, t_grip = self._gripper_in_effect
        return TwinState(
            wall=time.monotonic(),
            twin_time=self._twin_time if self._following else time.monotonic(),
            sim_time=float(d.time),
            following=self._following,
            q=self.q,
            q_target=np.asarray(self._q_target, float).copy(),
            joints_measured_at=self._joint_at,
            gripper_measured=(width, grasped),
            gripper_measured_at=t_grip,
            gripper_ctrl=self._gripper_ctrl,
            tcp=d.site_xpos[self._site].copy(),
            tcp_rotation=d.site_xmat[self._site].reshape(3, 3).copy(),
            opening=self.opening,
            fingers_settled=self._fingers_settled,
            hose_vertices=tuple(self.world.hose_vertices(i) for i in range(len(self.world.hoses))),
        )

    def _publish(self) -> None:
        state = self._make_state()
        with self._published:
            self._state = state
            self._published.notify_all()

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
        with self._lock:
            self._frames.append(frame)
            while self._frames and self._frames[0].wall < wall - self.history:
                self._frames.popleft()
        for out in tuple(self.outputs):
            out(frame)
        self.stats.frames += 1
        self.stats.render_s += time.perf_counter() - t0

    # ------------------------------------------------------------------ the sampler threads
    def _start_samplers(self) -> None:
        if any(t.is_alive() for t in self._samplers):
            return
        self._sampler_stop = threading.Event()
        self._samplers = [
            threading.Thread(target=self._sample, args=(read,), name=name, daemon=True)
            for name, read in (
                ("cablesim-twin-joints", self._read_joints),
                ("cablesim-twin-gripper", self._read_gripper),
            )
        ]
        for t in self._samplers:
            t.start()

    def _stop_samplers(self) -> None:
        self._sampler_stop.set()
        for t in self._samplers:
            t.join(5.0)
        self._samplers = []

    def _sample(self, read: Callable[[], None]) -> None:
        try:
            while not (self._sampler_stop.is_set() or self._stop.is_set()):
                read()
        except BaseException as e:  # noqa: BLE001 - handed to the other threads
            self.error = e
            self._stop.set()
            self._wake.set()

    def _read_joints(self) -> None:
        assert self.source is not None
        t0 = time.monotonic()
        q, dq = self.source.joint_state()
        t = 0.5 * (t0 + time.monotonic())
        self._joints.add(t, (np.asarray(q, float).copy(), np.asarray(dq, float).copy()))
        self._sampler_stop.wait(self.joint_period)

    def _read_gripper(self) -> None:
        assert self.source is not None
        width, grasped = self.source.gripper_state()
        self._grip.add(time.monotonic(), (float(width), bool(grasped)))
        self._sampler_stop.wait(0.002)  # a franky read blocks ~17 ms by itself
