"""Replaying the robot on the twin's Panda: the measurements at a twin time become commands.

Every physics step replays the sampled measurements (:mod:`cablesim.twin.sampling`) at its twin
time: the Panda's arm position actuators get the joint positions interpolated at that time
(extrapolated with the measured velocities for at most ``extrapolate`` s past the newest
sample), plus ``SimPanda``'s velocity feed-forward; the velocities are scaled by the rate the
robot's clock ran at against the wall clock (:meth:`Replay.clock_rate`: 1 on a robot, about 0.6
against franka-sim in lockstep here); the gripper actuator gets the opening
measured then -- or 0, closing with its force limit on the hose, while the robot reports a grasp
at an opening no wider than the hose (franka-sim's gripper stops at a virtual object; here the
fingers must really squeeze the 15 mm hose for the friction grasp to hold).  The gripper
command moves at the hand's speed (``gripper_speed``: closing, opening; franky's defaults),
since franka-sim's kinematic hand jumps.  The fingers count as settled once they have rested
(slower than ``finger_rest_speed`` m/s) for ``settle_time`` s since their command last changed.
"""

from __future__ import annotations

import math

import numpy as np

from cablesim.panda.description import MAX_OPENING
from cablesim.sim.world import World
from cablesim.twin.sampling import Track

#: Velocity feed-forward through the position target: kv / kp of the arm actuators (SimPanda's).
KV_OVER_KP = 0.1
#: Samples (s) over which the robot's clock rate is measured (:meth:`Replay.clock_rate`).
RATE_WINDOW = 0.025
#: Joint speed (rad/s, norm) below which the clock rate is taken as 1.
RATE_MIN_SPEED = 0.02


class Replay:
    """The measured joints (``joints``: a track of (q, dq)) and gripper (``gripper``: a track
    of (opening, grasped)) replayed onto ``world``'s Panda (module docstring); twin thread only.

    What it last replayed, for the twin's published state: :attr:`q_target` (the joints),
    :attr:`joint_at` (the wall time of the newest joint sample used), :attr:`gripper_in_effect`
    ((opening, grasped, wall time) of the gripper sample in effect), :attr:`gripper_ctrl` (the
    gripper's goal, m; 0 = closing with force) and :attr:`fingers_settled`."""

    def __init__(
        self,
        world: World,
        joints: Track,
        gripper: Track,
        *,
        extrapolate: float,
        hose_diameter: float,
        gripper_speed: tuple[float, float],
        settle_time: float,
        finger_rest_speed: float,
        q: np.ndarray,
        opening: float,
    ) -> None:
        self.world = world
        self.joints = joints
        self.gripper = gripper
        self.extrapolate = float(extrapolate)
        self.hose_diameter = float(hose_diameter)
        self.gripper_speed = (float(gripper_speed[0]), float(gripper_speed[1]))
        self.settle_time = float(settle_time)
        self.finger_rest_speed = float(finger_rest_speed)
        m, d = world.model, world.data
        n = world.panda
        assert n is not None
        self._act = np.asarray([m.actuator(a).id for a in n.actuators])
        self._gripper_act = m.actuator(n.gripper_actuator).id
        self._finger_dofadr = np.asarray([m.jnt_dofadr[m.joint(j).id] for j in n.finger_joints])
        self._dt = float(m.opt.timestep)
        self.q_target = q
        self.joint_at = -math.inf
        self.gripper_in_effect: tuple[float, bool, float] = (opening, False, -math.inf)
        self.gripper_ctrl = float(d.ctrl[self._gripper_act])  # the goal (m)
        self._gripper_cmd = self.gripper_ctrl  # the actuator command, ramped to the goal
        self._finger_still_since: float | None = None
        self.fingers_settled = True
        self.rate = 1.0  # the robot's clock against the wall clock (clock_rate)
        self._rate_at = -math.inf  # the sample time it was measured at

    def command(self, t: float) -> None:
        """Set the arm and gripper actuators for the physics step that ends at twin time ``t``."""
        d = self.world.data
        q, dq = self.joint_target(t)
        self.q_target = q
        d.ctrl[self._act] = q + KV_OVER_KP * dq
        goal = self.gripper_target(t)
        if goal != self.gripper_ctrl:
            self.gripper_ctrl, self._finger_still_since = goal, None
            self.fingers_settled = False
        # the hand moves its fingers at its own speed (a command jumping to 0 would slam
        # them through the thin hose)
        speed = self.gripper_speed[0] if goal < self._gripper_cmd else self.gripper_speed[1]
        step = speed * self._dt
        self._gripper_cmd += float(np.clip(goal - self._gripper_cmd, -step, step))
        d.ctrl[self._gripper_act] = self._gripper_cmd

    def joint_target(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Measured joints and velocities at wall time ``t`` (interpolated; extrapolated a
        little past the newest sample)."""
        before, after = self.joints.around(t)
        if before is None:
            if after is None:
                return self.q_target, np.zeros(7)
            (_, (q, dq)) = after
            self.joint_at = -math.inf
            return q, np.zeros(7)
        t0, (q0, dq0) = before
        self.joint_at = t0
        r = self.clock_rate(t0, q0, dq0)
        if after is None:
            return q0 + r * dq0 * min(t - t0, self.extrapolate), r * dq0
        t1, (q1, dq1) = after
        s = (t - t0) / max(t1 - t0, 1e-9)
        return q0 + s * (q1 - q0), r * (dq0 + s * (dq1 - dq0))

    def clock_rate(self, t0: float, q0: np.ndarray, dq0: np.ndarray) -> float:
        """How fast the robot's own time ran against the wall clock over the
        :data:`RATE_WINDOW` s of samples up to ``t0``: the measured velocities are per second of
        the robot's time, the replay runs in wall time.  1 on a robot (its clock is the wall
        clock); below 1 against a lockstep simulator on a loaded host, which slows the robot's
        time down instead of losing its cycles (measured: median 0.64 with both cores busy).
        Feeding the robot-time velocities forward unscaled pushed the twin's arm ahead of the
        replayed positions.  1 while the arm (nearly) rests, where it is unobservable."""
        if t0 == self._rate_at:  # measured once per sample, not once per physics step
            return self.rate
        older, _ = self.joints.around(t0 - RATE_WINDOW)
        if older is None:
            return self.rate
        self._rate_at = t0
        ta, (qa, dqa) = older
        v = 0.5 * (dqa + dq0)
        vv = float(v @ v)
        if vv < RATE_MIN_SPEED**2 or t0 - ta <= 0.0:
            self.rate = 1.0
        else:
            self.rate = float(np.clip((q0 - qa) @ v / (vv * (t0 - ta)), 0.0, 1.0))
        return self.rate

    def gripper_target(self, t: float) -> float:
        """The gripper's goal (m) at wall time ``t``: the measured opening, or 0 (squeeze)
        while the robot reports a grasp no wider than the hose."""
        before, _ = self.gripper.around(t)
        if before is not None:
            t_g, (width, grasped) = before
            self.gripper_in_effect = (width, grasped, t_g)
        width, grasped, _ = self.gripper_in_effect
        if grasped and width <= self.hose_diameter + 1e-3:
            return 0.0  # the robot holds something: squeeze what is between the fingers
        if math.isfinite(width):
            return float(np.clip(width, 0.0, MAX_OPENING))
        return self.gripper_ctrl

    def watch_fingers(self) -> None:
        """After a physics step: note whether the fingers have come to rest."""
        speed = float(np.max(np.abs(self.world.data.qvel[self._finger_dofadr])))
        t = self.world.time
        if speed > self.finger_rest_speed or self._gripper_cmd != self.gripper_ctrl:
            self._finger_still_since = None
        elif self._finger_still_since is None:
            self._finger_still_since = t
        elif t - self._finger_still_since >= self.settle_time:
            self.fingers_settled = True
