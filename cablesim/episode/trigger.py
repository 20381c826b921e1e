"""Camera triggering on simulated time at a fixed rate.

The robot interface's motions are blocking (as on the real robot), so frames are captured
*while* a primitive moves the arm by hooking the world's physics step: the real camera
streams at 15 frames/s on its own clock; in simulation a :class:`SimTrigger` calls
``on_frame(time)`` at the first physics step at or after each tick ``t0 + i / rate`` of
simulated time (jitter below one physics step).

    with SimTrigger(world, on_frame, rate=15.0):
        robot.move_to(pose)          # on_frame runs every 1/15 s of simulated time

The hook shadows ``world.step`` with an instance attribute for the duration of the ``with``
block only (the world's class is untouched), so anything that steps this world object,
e.g. :class:`cablesim.robot.sim_panda.SimPanda`, triggers the camera.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol


class SteppableWorld(Protocol):
    @property
    def time(self) -> float: ...

    def step(self, n: int = 1) -> None: ...


class SimTrigger:
    """Calls ``on_frame(sim_time)`` every ``1 / rate`` seconds of simulated time."""

    def __init__(
        self,
        world: Any,
        on_frame: Callable[[float], None],
        rate: float = 15.0,
        capture_at_start: bool = True,
    ):
        if not rate > 0 or not math.isfinite(rate):
            raise ValueError(f"rate must be a positive number of frames per second, got {rate}")
        self.world = world
        self.on_frame = on_frame
        self.period = 1.0 / rate
        self.capture_at_start = capture_at_start
        self.frames = 0
        self._t0 = 0.0
        self._original: Callable[..., None] | None = None
        self._hook: Callable[..., None] | None = None

    def _next_time(self) -> float:
        return self._t0 + self.frames * self.period

    def _step(self, n: int = 1) -> None:
        assert self._original is not None
        half_dt = 0.5 * float(self.world.model.opt.timestep) if hasattr(self.world, "model") else 0
        for _ in range(int(n)):
            self._original(1)
            if self.world.time + half_dt >= self._next_time():
                self.frames += 1
                self.on_frame(self.world.time)

    def __enter__(self) -> SimTrigger:
        if "step" in vars(self.world):
            raise RuntimeError("the world's step is already hooked (nested SimTrigger?)")
        self._original = self.world.step
        self._t0 = self.world.time
        self.frames = 0
        if self.capture_at_start:
            self.frames = 1
            self.on_frame(self.world.time)
        self._hook = self._step  # one bound method, to recognise it on exit
        self.world.step = self._hook
        return self

    def __exit__(self, *exc: object) -> None:
        if vars(self.world).get("step") is self._hook:
            del self.world.step
        self._original = None
