"""The real robot and camera as a session of the interaction runner and the exploration loop.

    cfg = RealConfig(robot_host="172.16.0.2", camera="realsense", calibration="calib.json")
    with RealSession.open(cfg) as session:                      # FrankyPanda + RealSense
        result = session.interact(segment_mask)                  # the same runner as in sim

What it holds: ``FrankyPanda`` (franky-control) inside a :class:`~cablesim.robot.guard.
GuardedRobot` (workspace box and speed caps from ``cfg.safety``), ``RealSenseCamera`` (a live
camera, a serial number, or a ``.db3`` recording), a :class:`~cablesim.episode.clock.
StreamClock` (frames from the camera's own stream while franky moves the arm, each paired with
the gripper pose measured nearest to it), the camera extrinsics and the robot base from the
calibration file written by ``cablesim calibrate``, and the park configuration out of the
camera's view.  There is no ground truth: the runner gets no truth provider, the exploration
loop no evaluator.  ``RealSession.open(cfg, dry_run=True)`` reads the robot's state and the
camera but replaces the robot by a :class:`~cablesim.robot.dry_run.DryRunRobot` that plans and
checks every motion without moving.

Nothing here imports the simulator.  The digital twin (``cablesim.twin``) gives a session of
the same kind against the ``franka-sim`` server with no hardware.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cablesim.cables import DEFAULT_KIND, cable_kind
from cablesim.calibration import load_calibration
from cablesim.camera.base import Camera
from cablesim.camera.realsense import RealSenseCamera
from cablesim.config import Config, check_positive
from cablesim.episode.clock import PlanningClock, StreamClock
from cablesim.episode.config import InteractionConfig
from cablesim.episode.session import Session
from cablesim.errors import ConfigError
from cablesim.panda.description import PARK_QPOS
from cablesim.panda.ik import Obstacle
from cablesim.robot.base import Robot
from cablesim.robot.dry_run import DryRunRobot
from cablesim.robot.franky_panda import FrankyPanda
from cablesim.robot.guard import GuardedRobot, SafetyConfig

#: The default scene's static obstacles in the world frame (centre xyz, half sizes xyz): the
#: table top (z < 0) and the task board (front face at x = 0.62).  A real set-up lists its own.
DEFAULT_OBSTACLES: tuple[tuple[float, ...], ...] = (
    (0.15, 0.0, -0.02, 0.75, 0.85, 0.02),
    (0.63, 0.0, 0.5, 0.01, 0.45, 0.5),
)


@dataclass
class RealConfig(Config):
    """Devices, calibration, safety and the interaction of a real-robot session."""

    robot_host: str = "172.16.0.2"
    camera: str = "realsense"  # realsense | realsense:SERIAL | realsense:/path/recording.db3
    calibration: str = ""  # the file written by ``cablesim calibrate``
    width: int = 640
    height: int = 480
    fps: int = 15
    dynamics_factor: float = 0.2  # franky's relative acceleration/jerk factor
    realtime: bool = True  # demand a realtime kernel (False only for a simulated robot)
    park_qpos: tuple[float, ...] = PARK_QPOS  # out of the camera's view
    obstacles: tuple[tuple[float, ...], ...] = DEFAULT_OBSTACLES  # world boxes (c, half)
    seed: int = 0  # the policy's own random choices (random-grasp baseline)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    interaction: InteractionConfig = field(default_factory=InteractionConfig)
    # the kind of the cables on the bench (``cablesim cables``): the grasp closes on its
    # diameter where ``interaction.grasp`` leaves width, epsilon and surface offset open
    cable: str = DEFAULT_KIND

    def validate(self) -> RealConfig:
        if not self.robot_host:
            raise ConfigError("robot_host", "the robot's address is empty")
        kind = self.camera.split(":", 1)[0]
        if kind != "realsense":
            raise ConfigError(
                "camera", f"must be realsense[:SERIAL|:FILE.db3], got {self.camera!r}"
            )
        if not self.calibration:
            raise ConfigError("calibration", "a calibration file is needed (cablesim calibrate)")
        for name in ("width", "height", "fps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ConfigError(name, f"must be a positive integer, got {v!r}")
        check_positive("dynamics_factor", self.dynamics_factor)
        if self.dynamics_factor > 1:
            raise ConfigError("dynamics_factor", f"must be in (0, 1], got {self.dynamics_factor}")
        if len(self.park_qpos) != 7:
            raise ConfigError("park_qpos", f"need 7 joint angles, got {self.park_qpos!r}")
        for i, box in enumerate(self.obstacles):
            if len(box) != 6 or any(not np.isfinite(x) for x in box) or min(box[3:]) <= 0:
                raise ConfigError(
                    f"obstacles[{i}]", f"expected (cx, cy, cz, hx, hy, hz), got {box}"
                )
        self.safety.validate()
        self.interaction.validate()
        cable_kind(self.cable, "cable")
        return self


def open_camera(spec: str, width: int, height: int, fps: int, T_world_camera: Any) -> Camera:
    """``realsense`` (the first camera), ``realsense:SERIAL`` or ``realsense:FILE.db3``."""

    _, _, arg = spec.partition(":")
    if arg and (arg.endswith(".db3") or Path(arg).exists()):
        return RealSenseCamera(arg, T_world_camera=T_world_camera)
    return RealSenseCamera(
        width=width, height=height, fps=fps, serial=arg or None, T_world_camera=T_world_camera
    )


class RealSession(Session):
    """See the module docstring; build with :meth:`open` (or from devices you opened)."""

    def __init__(
        self, cfg: RealConfig, robot: Robot, camera: Camera, clock: Any, dry_run: bool = False
    ) -> None:
        self.cfg = cfg
        self.robot = robot
        self.camera = camera
        self.clock = clock
        self.dry_run = dry_run

    @classmethod
    def open(cls, cfg: RealConfig, dry_run: bool = False) -> RealSession:
        """Connect to the robot, open the camera, read the calibration (errors name the file or
        the field before anything moves)."""

        cfg = cfg.validate()
        cal = load_calibration(cfg.calibration)
        obstacles = [
            Obstacle.box(f"obstacle{i}", box[:3], box[3:]) for i, box in enumerate(cfg.obstacles)
        ]
        camera = open_camera(cfg.camera, cfg.width, cfg.height, cfg.fps, cal.T_world_camera)
        try:
            arm = FrankyPanda(
                cfg.robot_host,
                cal.T_world_camera,
                T_world_base=cal.T_world_base,
                dynamics_factor=cfg.dynamics_factor,
                obstacles=obstacles,
                realtime=cfg.realtime,
            )
        except BaseException:
            camera.close()
            raise
        robot: Robot = GuardedRobot(arm, cfg.safety)
        if dry_run:
            robot = DryRunRobot(robot)
            clock: Any = PlanningClock(camera)
        else:
            clock = StreamClock(robot, camera)
        return cls(cfg, robot, camera, clock, dry_run)

    @property
    def park(self) -> tuple[float, ...]:
        return tuple(self.cfg.park_qpos)

    def close(self) -> None:
        super().close()
        close = getattr(getattr(self.robot, "robot", None), "close", None)
        if callable(close):
            close()
