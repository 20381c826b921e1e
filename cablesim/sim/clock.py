"""The simulated clock: frames on simulated time, stillness by settling the physics.

    clock = SimClock(world, robot, grab=camera.capture, rate=15.0, action_hooks=[perturbation])
    with clock.streaming(on_tick):
        robot.move_to(pose)        # on_tick(Tick) every 1/15 s of simulated time

The robot's motions are blocking (as on the real robot), so frames are taken *while* a motion
runs by a world step hook: ``on_tick`` is called at the first physics step at or after each
tick ``t0 + i / rate`` of simulated time (jitter below one physics step), with the gripper pose
read at that very step (skew 0).  The frame itself is grabbed lazily, only when the receiver
asks for it (only kept frames are rendered).  ``action_hooks`` (objects with ``start(world)``,
``before_step(world)`` and ``stop(world)``, e.g. the neighbour perturbation) run only while
streaming, i.e. while an action is recorded.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol

import numpy as np

from cablesim.camera.base import CameraImage
from cablesim.episode.clock import StillResult, Tick
from cablesim.errors import ConfigError
from cablesim.robot.base import Robot


class ActionHook(Protocol):
    def start(self, world: Any) -> None: ...

    def before_step(self, world: Any) -> None: ...

    def stop(self, world: Any) -> None: ...


class SimClock:
    """See the module docstring."""

    def __init__(
        self,
        world: Any,
        robot: Robot,
        grab: Callable[[], CameraImage],
        rate: float = 15.0,
        action_hooks: Sequence[ActionHook] = (),
    ) -> None:
        if not (isinstance(rate, int | float) and math.isfinite(rate) and rate > 0):
            raise ConfigError("capture.frame_rate", f"must be a positive number, got {rate!r}")
        self.world = world
        self.robot = robot
        self._grab = grab
        self.period = 1.0 / float(rate)
        self.action_hooks = list(action_hooks)

    def now(self) -> float:
        return float(self.world.time)

    def grab(self) -> CameraImage:
        return self._grab()

    def _tick(self) -> Tick:
        r = self.robot
        return Tick(
            self.now(), r.ee_pose(), float(r.gripper_opening), r.joint_positions, grab=self._grab
        )

    @contextlib.contextmanager
    def streaming(
        self, on_tick: Callable[[Tick], None], capture_at_start: bool = True
    ) -> Iterator[None]:
        world = self.world
        t0 = world.time
        frames = 0
        half_dt = 0.5 * float(world.model.opt.timestep)

        def after_step(w: Any) -> None:
            nonlocal frames
            if w.time + half_dt >= t0 + frames * self.period:
                frames += 1
                on_tick(self._tick())

        if capture_at_start:
            frames = 1
            on_tick(self._tick())
        for hook in self.action_hooks:
            hook.start(world)
        try:
            with world.hooks(before=[h.before_step for h in self.action_hooks], after=[after_step]):
                yield
        finally:
            for hook in self.action_hooks:
                hook.stop(world)

    def wait_still(self, cfg: Any) -> StillResult:
        """Step until every hose vertex moves slower than ``cfg.settle_speed`` (m/s), both on
        average over ``cfg.settle_check_every`` and over the last physics step, or
        ``cfg.settle_max_time`` s of simulated time passed."""
        world = self.world
        dt = float(world.model.opt.timestep)
        chunk = max(2, int(round(cfg.settle_check_every / dt)))
        t_start = world.time
        t_end = t_start + cfg.settle_max_time
        measured = math.inf
        while world.time < t_end:
            start = world.all_hose_vertices()
            world.step(chunk - 1)
            before_last = world.all_hose_vertices()
            world.step(1)
            end = world.all_hose_vertices()
            mean_speed = float(np.linalg.norm(end - start, axis=1).max()) / (chunk * dt)
            last_speed = float(np.linalg.norm(end - before_last, axis=1).max()) / dt
            measured = max(mean_speed, last_speed)
            if measured < cfg.settle_speed:
                break
        return StillResult(
            measured < cfg.settle_speed,
            measured,
            world.time - t_start,
            f"fastest hose vertex {measured * 1000:.2f} mm/s",
        )
