"""The real Panda through franky-control (``pip install 'cablesim[real]'``).

:class:`FrankyPanda` implements the same :class:`~cablesim.robot.base.Robot` interface as the
simulated :class:`~cablesim.sim.sim_panda.SimPanda`, so the episode code drives either.

Frames.  Poses given to and returned by the interface are TCP poses in the *world* frame (the
frame of the camera extrinsics ``T_world_camera``).  The robot works in its *base* frame ``O``;
``T_world_base`` places it in the world.  The TCP is the Franka Hand's: 0.1034 m along the
flange z axis, turned -45 degrees about it (:data:`FLANGE_T_TCP`), the same point as the
simulated model's ``grasp_site``.  At connection the adapter sets ``NE_T_EE`` (``Robot.set_ee``)
so that the robot's end-effector frame ``EE`` *is* this TCP whatever end effector Desk has
configured (``F_T_EE = F_T_NE * NE_T_EE = FLANGE_T_TCP``); ``O_T_EE`` is then the TCP pose in
the base frame and Cartesian motions move the TCP along straight lines.

Motions.  Before anything is sent, a Cartesian target is checked on the arm-only
:class:`~cablesim.panda.ik.ArmModel` (the same kinematics, joint limits and static obstacles as
the simulated robot): IK along the straight line, every waypoint within limits and free of
collisions.  A target that fails this check returns ``MoveResult(False, reason)`` with
``outcome=Outcome.UNREACHABLE`` without moving.  A motion the robot aborts (franky's
``ControlException`` carrying a reflex, e.g. a collision or a joint limit; ``CommandException``;
``InvalidOperationException``) also returns ``MoveResult(False, reason)``, after
``recover_from_errors()``, with no outcome of its own (the step that asked for it names it).
Only a lost connection (``NetworkException``) raises.  Connecting is retried (at most
``connect_attempts`` times, each warned and listed in ``connect_retries``) when libfranka's first
state does not arrive in time: nothing has moved then.

Speeds.  franky scales its velocity, acceleration and jerk limits by a relative dynamics
factor.  ``move_to``'s ``speed`` and ``angular_speed`` become the velocity factor
``min(speed / v_max, angular_speed / w_max)`` (so both peaks stay within the requested
values); acceleration and jerk use ``dynamics_factor``.  ``move_joints``' ``speed_factor`` is
the velocity factor directly.

Testing without hardware: the digital twin's ``franka-sim`` server
(:mod:`cablesim.twin.franka_sim`, serving the arm model of :mod:`cablesim.twin.franka_sim_model`)
speaks libfranka's protocol on loopback (see ``tests/robot/test_franky_panda.py`` and the
README's "Real robot" section).
"""

from __future__ import annotations

import math
import os
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np

from cablesim.errors import ConfigError
from cablesim.outcomes import Outcome
from cablesim.panda.description import FLANGE_T_TCP, MAX_OPENING
from cablesim.panda.ik import ArmModel, ArmModelChecks, Obstacle
from cablesim.pose import Pose
from cablesim.robot.base import Frame, MoveResult, Robot

if TYPE_CHECKING:  # pragma: no cover
    import franky


def _import_franky() -> Any:
    try:
        import franky  # lazy: optional heavy package
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "FrankyPanda needs franky-control; install the 'real' extra: "
            "pip install 'cablesim[real]' (franky-control==2.0.0)"
        ) from exc
    return franky


class _Scheduling:
    """The calling thread's scheduling policy, kept apart from libfranka's control thread's.

    libfranka raises the thread that constructs a ``franky.Robot`` to its realtime policy
    (``SCHED_FIFO`` 99, also with ``RealtimeConfig.Ignore`` whenever the process may) and leaves
    it there; franky's control thread, started by an asynchronous ``move``, inherits the policy
    of the thread that starts it.  Left alone, the caller's own thread (IK checks, perception,
    logging) would run at the control loop's priority and, on a shared core, hold it off.  So
    the caller's policy is given back after connecting (:meth:`connected`) and lent again only
    while a motion's control thread is being started (:meth:`starting_motion`).
    """

    def __init__(self) -> None:
        self.caller = (os.sched_getscheduler(0), os.sched_getparam(0))
        self.control = self.caller

    def _set(self, policy: tuple[int, os.sched_param]) -> None:
        if os.sched_getscheduler(0) != policy[0] or os.sched_getparam(0) != policy[1]:
            os.sched_setscheduler(0, *policy)

    def connected(self) -> None:
        """Call right after ``franky.Robot(...)``: remember libfranka's policy, restore ours."""
        self.control = (os.sched_getscheduler(0), os.sched_getparam(0))
        self._set(self.caller)

    @contextmanager
    def starting_motion(self) -> Iterator[None]:
        self._set(self.control)
        try:
            yield
        finally:
            self._set(self.caller)


def _column_major(T: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(T, dtype=float).T.reshape(16)]


class FrankyPanda(ArmModelChecks, Robot):
    """The :class:`Robot` interface on a real Panda (or FR3) through franky-control.

    ``host``: the robot's FCI address.  ``T_world_camera``: camera extrinsics (4x4, OpenCV
    camera frame).  ``T_world_base``: the robot base in the world (4x4).  ``dynamics_factor``
    (0, 1]: acceleration and jerk scaling of every motion and the cap on its velocity scaling.
    ``obstacles``: static obstacles in world coordinates for the reachability check.
    ``realtime``: demand a realtime kernel (libfranka's ``RealtimeConfig.Enforce``); switch off
    only for a simulated robot.  ``collision_thresholds``: (torque Nm, force N) reflex
    thresholds, or None for franky's defaults.  ``robot``/``gripper``: already-connected franky
    objects (otherwise connected to ``host``); ``gripper=False`` runs without a hand.
    ``rest_velocity`` (rad/s), ``rest_window`` and ``rest_timeout`` (s): a motion starts only
    from rest, when no joint moved faster than ``rest_velocity`` on average over the last
    ``rest_window`` of the robot's clock (the states' timestamps); an arm still moving after
    ``rest_timeout`` fails the motion (``MoveResult`` reason ``"arm not at rest: ..."``)
    without sending it.  The average over a window, not the
    measured ``dq`` of one state, because a position-controlled arm holding still chatters:
    franka-sim's arm reports up to 0.4 rad/s of sign-flipping ``dq`` at a standstill.
    """

    def __init__(
        self,
        host: str,
        T_world_camera: np.ndarray,
        T_world_base: np.ndarray | None = None,
        dynamics_factor: float = 0.2,
        obstacles: Sequence[Obstacle] = (),
        *,
        realtime: bool = True,
        collision_thresholds: tuple[float, float] | None = None,
        position_tolerance: float = 0.003,
        rotation_tolerance: float = 0.05,
        joint_tolerance: float = 0.01,
        waypoint_spacing: float = 0.01,
        max_joint_jump: float = 0.25,
        motion_timeout: float = 30.0,
        settle_time: float = 0.5,
        rest_velocity: float = 0.02,
        rest_window: float = 0.05,
        rest_timeout: float = 2.0,
        flange_T_tcp: np.ndarray = FLANGE_T_TCP,
        robot: Any = None,
        gripper: Any = None,
        connect_attempts: int = 3,
    ):
        if not 0.0 < dynamics_factor <= 1.0:
            raise ValueError(f"dynamics_factor must be in (0, 1], got {dynamics_factor}")
        self._franky = _import_franky()
        fr = self._franky
        self.host = host
        self.T_world_camera = np.asarray(T_world_camera, dtype=float).reshape(4, 4)
        self.T_world_base = (
            np.eye(4) if T_world_base is None else np.asarray(T_world_base, dtype=float)
        ).reshape(4, 4)
        self._T_base_world = np.linalg.inv(self.T_world_base)
        self.dynamics_factor = float(dynamics_factor)
        self.position_tolerance = position_tolerance
        self.rotation_tolerance = rotation_tolerance
        self.joint_tolerance = joint_tolerance
        self.waypoint_spacing = waypoint_spacing
        self.max_joint_jump = max_joint_jump
        self.motion_timeout = motion_timeout
        self.settle_time = settle_time
        for name, value in (("rest_velocity", rest_velocity), ("rest_window", rest_window)):
            if not value > 0:
                raise ConfigError(name, f"must be > 0, got {value}")
        if not rest_timeout >= rest_window:
            raise ConfigError(
                "rest_timeout", f"must be >= rest_window ({rest_window}), got {rest_timeout}"
            )
        self.rest_velocity = float(rest_velocity)
        self.rest_window = float(rest_window)
        self.rest_timeout = float(rest_timeout)
        self.flange_T_tcp = np.asarray(flange_T_tcp, dtype=float).reshape(4, 4)

        base = Pose.from_matrix(self.T_world_base)
        self.arm = ArmModel(base.position, base.quaternion, obstacles)

        self._scheduling = _Scheduling()
        if not isinstance(connect_attempts, int) or connect_attempts < 1:
            raise ConfigError("connect_attempts", f"must be >= 1, got {connect_attempts!r}")
        self.connect_attempts = connect_attempts
        self.connect_retries: list[str] = []  # one line per failed attempt that was retried
        if robot is None:
            config = fr.RealtimeConfig.Enforce if realtime else fr.RealtimeConfig.Ignore
            robot = self._connect("arm", lambda: fr.Robot(host, realtime_config=config))
            self._scheduling.connected()
        self.robot: franky.Robot = robot
        self.robot.relative_dynamics_factor = 1.0  # per-motion factors carry the scaling
        if collision_thresholds is not None:
            self.robot.set_collision_behavior(*collision_thresholds)
        self._set_tcp()
        self._v_max = float(self.robot.translation_velocity_limit.get())
        self._w_max = float(self.robot.rotation_velocity_limit.get())
        if gripper is None:
            gripper = self._connect("gripper", lambda: fr.Gripper(host))
        self.gripper: franky.Gripper | None = gripper or None

    def _connect(self, what: str, make: Any) -> Any:
        """``make()``, the franky object that connects to the arm or the gripper, tried up to
        ``connect_attempts`` times.  libfranka waits one second for the first state over UDP
        after the TCP handshake; a host too loaded to send it in time (measured here: franka-sim
        beside a full test run on two cores) or a lossy network fails the attempt with
        ``NetworkException``.  Nothing has moved yet, so a new connection is safe; each retry
        is warned and listed in ``connect_retries``, and the last attempt's error is raised."""
        fr = self._franky
        for attempt in range(1, self.connect_attempts + 1):
            try:
                return make()
            except fr.NetworkException as exc:
                if attempt == self.connect_attempts:
                    raise
                line = (
                    f"{what} at {self.host}: connection attempt {attempt} of "
                    f"{self.connect_attempts} failed ({exc}); trying again"
                )
                self.connect_retries.append(line)
                warnings.warn(line, stacklevel=3)
                time.sleep(0.5)
        raise AssertionError("unreachable")  # pragma: no cover

    def _set_tcp(self) -> None:
        """Make the robot's EE frame the TCP: ``NE_T_EE = F_T_NE^-1 * FLANGE_T_TCP``."""
        if self.robot.has_errors:
            self.robot.recover_from_errors()
        F_T_NE = np.asarray(self.robot.state.F_T_NE.matrix, dtype=float)
        self.robot.set_ee(_column_major(np.linalg.inv(F_T_NE) @ self.flange_T_tcp))

    def close(self) -> None:
        """Drop the connections (franky disconnects when its objects are destroyed)."""
        self.robot = None  # type: ignore[assignment]
        self.gripper = None

    def __enter__(self) -> FrankyPanda:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- state -------------------------------------------------------------------------------
    def _base_T_tcp(self) -> np.ndarray:
        return np.asarray(
            self.robot.current_cartesian_state.pose.end_effector_pose.matrix, dtype=float
        )

    def ee_pose(self) -> Pose:
        return Pose.from_matrix(self.T_world_base @ self._base_T_tcp())

    @property
    def joint_positions(self) -> np.ndarray:
        return np.asarray(self.robot.current_joint_state.position, dtype=float).reshape(7).copy()

    @property
    def gripper_opening(self) -> float:
        return float(self.gripper.width) if self.gripper is not None else float("nan")

    def to_base(self, pose: Pose) -> Pose:
        """A world-frame pose in the robot base frame."""
        return Pose.from_matrix(self._T_base_world @ pose.matrix())

    # ---- planning (the same arm-only model as the simulated robot) ---------------------------
    def check_line(self, target: Pose) -> str:
        """Empty if IK follows the straight TCP line to ``target`` within limits, free of
        collisions and without branch jumps (from the current joints); else the reason."""
        _, problem = self.arm.plan_line(
            self.ee_pose(),
            self.joint_positions,
            target,
            self._opening_for_checks(),
            self.waypoint_spacing,
            0.1,
            self.max_joint_jump,
        )
        return f"unreachable: {problem}" if problem.startswith("IK") else problem

    # ---- motion ------------------------------------------------------------------------------
    def _cartesian_factor(self, speed: float, angular_speed: float) -> Any:
        velocity = min(speed / self._v_max, angular_speed / self._w_max, self.dynamics_factor)
        velocity = max(velocity, 1e-3)
        return self._franky.RelativeDynamicsFactor(
            velocity, self.dynamics_factor, self.dynamics_factor
        )

    def move_to(
        self, pose: Pose, speed: float = 0.1, angular_speed: float = 0.8, check: bool = True
    ) -> MoveResult:
        """Straight-line TCP motion to ``pose`` (world frame); ``check=False`` skips the
        arm-model check and leaves the judgement to the robot (its reflexes)."""
        if speed <= 0 or angular_speed <= 0:
            return MoveResult(False, "speed must be > 0")
        if check:
            problem = self.check_line(pose)
            if problem:
                return MoveResult(
                    False, problem, self._pos_error(pose), outcome=Outcome.UNREACHABLE
                )
        fr = self._franky
        target = fr.Affine(self._T_base_world @ pose.matrix())
        motion = fr.CartesianMotion(
            fr.RobotPose(target),
            fr.ReferenceType.Absolute,
            self._cartesian_factor(speed, angular_speed),
        )
        return self._run(motion, pose)

    def move_relative(
        self,
        delta: np.ndarray,
        frame: Frame = "world",
        speed: float = 0.1,
        check: bool = True,
    ) -> MoveResult:
        """Translate the TCP by ``delta`` (m) in ``frame``, as a franky relative motion (the
        target is expressed in the TCP frame at the start of the motion)."""
        if speed <= 0:
            return MoveResult(False, "speed must be > 0")
        current = self.ee_pose()
        d = np.asarray(delta, dtype=float).reshape(3)
        if frame == "camera":
            d_world = self.T_world_camera[:3, :3] @ d
        elif frame == "tcp":
            d_world = current.rotation @ d
        else:
            d_world = d
        target = current.translated(d_world)
        if check:
            problem = self.check_line(target)
            if problem:
                return MoveResult(
                    False, problem, self._pos_error(target), outcome=Outcome.UNREACHABLE
                )
        fr = self._franky
        d_tcp = current.rotation.T @ d_world
        motion = fr.CartesianMotion(
            fr.RobotPose(fr.Affine(d_tcp, np.array([0.0, 0.0, 0.0, 1.0]))),
            fr.ReferenceType.Relative,
            self._cartesian_factor(speed, 1.0),
        )
        return self._run(motion, target)

    def move_joints(
        self, q: np.ndarray, speed_factor: float = 0.3, check: bool = True
    ) -> MoveResult:
        q = np.asarray(q, dtype=float).reshape(7)
        if not 0 < speed_factor <= 1:
            return MoveResult(False, f"speed_factor must be in (0, 1], got {speed_factor}")
        problem = self.arm.limit_violation(q)
        if problem:
            return MoveResult(False, f"joint limit: {problem}", outcome=Outcome.UNREACHABLE)
        if check:
            problem = self.arm.check_joint_path(self.joint_positions, q, self._opening_for_checks())
            if problem:
                return MoveResult(False, problem, outcome=Outcome.UNREACHABLE)
        fr = self._franky
        factor = fr.RelativeDynamicsFactor(
            min(speed_factor, 1.0), self.dynamics_factor, self.dynamics_factor
        )
        motion = fr.JointMotion(q, fr.ReferenceType.Absolute, factor)
        return self._run(motion, None, q)

    def _timed_joints(self) -> tuple[np.ndarray, float]:
        """The measured joint positions and the robot's own timestamp (s) of that state."""
        state = self.robot.state
        return np.asarray(state.q, dtype=float).reshape(7).copy(), state.time.to_sec()

    def wait_for_rest(self) -> str:
        """Wait until the arm is at rest (see the class docstring); empty when it is, else the
        reason, after ``rest_timeout``.

        Speeds are measured on the robot's clock (the timestamps of its states), not the
        host's: a state stream that stalls (a loaded host, where the simulated robot or
        libfranka's thread misses cycles; a dropped connection) shows the same joint angles
        for a while, which over host time would read as rest while the arm still moves.  A
        window counts only once the robot's clock has advanced by half of ``rest_window``."""
        deadline = time.monotonic() + self.rest_timeout
        q0, t0 = self._timed_joints()
        speed = float("nan")
        while True:
            time.sleep(self.rest_window)
            q1, t1 = self._timed_joints()
            if t1 - t0 >= self.rest_window / 2:
                speed = float(np.max(np.abs(q1 - q0))) / (t1 - t0)
                if speed <= self.rest_velocity:
                    return ""
                q0, t0 = q1, t1
            if time.monotonic() >= deadline:
                if speed != speed:  # no window counted: the robot's states did not advance
                    return (
                        f"arm not at rest: the robot's clock advanced {1000 * (t1 - t0):.0f} ms "
                        f"in {self.rest_timeout:.1f} s, too little to measure its speed (rest_window "
                        f"{self.rest_window} s)"
                    )
                return (
                    f"arm not at rest: a joint moved at {speed:.3f} rad/s (rest_velocity "
                    f"{self.rest_velocity} rad/s) {self.rest_timeout:.1f} s after the motion was asked"
                )

    def _run(
        self, motion: Any, target: Pose | None, q_target: np.ndarray | None = None
    ) -> MoveResult:
        """Execute ``motion`` from rest; a reflex or a refused command becomes a failed
        MoveResult."""
        fr = self._franky
        problem = self.wait_for_rest()
        if problem:
            return MoveResult(
                False, problem, self._pos_error(target) if target is not None else float("nan")
            )
        t0 = time.monotonic()
        try:
            with self._scheduling.starting_motion():
                self.robot.move(motion, asynchronous=True)
            finished = self.robot.join_motion(self.motion_timeout)
        except (fr.ControlException, fr.CommandException, fr.InvalidOperationException) as exc:
            duration = time.monotonic() - t0
            recovered = self._recover()
            reason = f"robot aborted the motion: {type(exc).__name__}: {exc}".strip()
            reason += "; recovered" if recovered else "; recovery FAILED"
            err = self._pos_error(target) if target is not None else float("nan")
            return MoveResult(False, reason, err, duration)
        duration = time.monotonic() - t0
        if not finished:
            self._stop()
            return MoveResult(
                False,
                f"motion did not finish within {self.motion_timeout:.0f} s; stopped",
                self._pos_error(target) if target is not None else float("nan"),
                duration,
            )
        settle_until = time.monotonic() + self.settle_time
        if target is None:
            assert q_target is not None
            while True:
                err_q = float(np.max(np.abs(self.joint_positions - q_target)))
                if err_q <= self.joint_tolerance or time.monotonic() > settle_until:
                    break
                time.sleep(0.01)
            if err_q > self.joint_tolerance:
                return MoveResult(
                    False, f"joint target not reached (error {err_q:.3f} rad)", duration=duration
                )
            return MoveResult(True, "", self._pos_error(self.arm.fk(q_target)), duration)
        while True:
            pos_err, rot_err = self.ee_pose().distance_to(target)
            reached = pos_err <= self.position_tolerance and rot_err <= self.rotation_tolerance
            if reached or time.monotonic() > settle_until:
                break
            time.sleep(0.01)
        if not reached:
            return MoveResult(
                False,
                f"target not reached within tolerance (error {pos_err * 1000:.1f} mm, "
                f"{math.degrees(rot_err):.1f} deg)",
                pos_err,
                duration,
            )
        return MoveResult(True, "", pos_err, duration)

    def stop(self) -> None:
        """Stop the motion in progress (franky's ``stop``) and recover from errors."""
        if self.robot is not None:
            self._stop()

    def _stop(self) -> None:
        fr = self._franky
        try:
            self.robot.stop()
            self.robot.join_motion(5.0)
        except (fr.ControlException, fr.CommandException, fr.InvalidOperationException):
            pass
        self._recover()

    def _recover(self) -> bool:
        fr = self._franky
        try:
            return bool(self.robot.recover_from_errors())
        except (fr.ControlException, fr.CommandException, fr.InvalidOperationException):
            return False

    def recover(self) -> None:
        self._recover()

    def _pos_error(self, target: Pose) -> float:
        return float(np.linalg.norm(self.ee_pose().position - target.position))

    # ---- gripper -----------------------------------------------------------------------------
    def open(self, width: float = MAX_OPENING, speed: float = 0.1) -> bool:
        if self.gripper is None:
            return False
        fr = self._franky
        width = float(np.clip(width, 0.0, MAX_OPENING))
        try:
            return bool(self.gripper.move(width, speed))
        except (fr.GripperException, fr.CommandException):
            return False

    def grasp(
        self,
        width: float = 0.015,
        force: float = 70.0,
        speed: float = 0.05,
        epsilon_inner: float = 0.01,
        epsilon_outer: float = 0.01,
    ) -> bool:
        if self.gripper is None:
            return False
        fr = self._franky
        try:
            return bool(self.gripper.grasp(width, speed, force, epsilon_inner, epsilon_outer))
        except (fr.GripperException, fr.CommandException):
            return False
