"""Explicit, seeded perturbation of neighbouring hoses during actions.

SPEC section 1: other hoses may be perturbed by the robot or by the grasped hose and must not
be labelled.  Contacts perturb neighbours naturally but rarely by much; this module adds an
explicit, reproducible disturbance so that the claim "motion correlation beats motion
segmentation when neighbouring hoses are perturbed" can be tested on purpose.

Mechanism: :class:`PerturbedWorld` wraps a :class:`~cablesim.sim.world.World` (everything is
delegated to it) and overrides only ``step``.  While an action is being streamed, i.e. while the
episode runner's :class:`~cablesim.episode.trigger.SimTrigger` hooks this object's ``step``
(an instance attribute named ``step`` exists), every physics step first sets
``data.xfrc_applied`` on a few vertex bodies of each perturbed hose: a damped spring pulls each
vertex towards ``rest + A sin(2 pi (t - t0) / P + phase) e``, where ``rest`` is the vertex's
position when the action started, ``e`` a unit direction in the board plane and ``A``, ``P``,
``phase``, ``e`` and the vertices are drawn from the seeded generator at the start of each
action.  The motion is independent of the gripper (its own period and phase).  When the action
ends the forces are removed, so release, retreat and settling (and the target frame) are not
disturbed.  Pass the wrapper wherever the world goes (``SimPanda``, ``SimCamera``,
``run_episode``)::

    pw = PerturbedWorld(world, PerturbConfig(enabled=True), hose_of_interest=2, seed=0)
    robot, camera = SimPanda(pw), SimCamera(pw)
    run_episode(pw, robot, camera, segment, cfg)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cablesim.config import check_positive, check_range
from cablesim.errors import ConfigError


@dataclass
class PerturbConfig:
    """Seeded disturbance of the hoses other than the hose of interest, during actions only."""

    enabled: bool = False
    hoses: tuple[int, ...] | None = None  # None: every hose but the hose of interest
    points: int = 2  # vertex bodies pulled per hose
    span: tuple[float, float] = (0.3, 0.7)  # where along the hose (fraction of its vertices)
    amplitude: tuple[float, float] = (0.01, 0.03)  # m, drawn per action and hose
    period: tuple[float, float] = (2.5, 4.0)  # s: slower than a 1 m hose swings (~1.6 s)
    stiffness: float = 120.0  # N/m
    damping: float = 3.0  # N s/m
    max_force: float = 2.0  # N per vertex

    def __post_init__(self) -> None:
        if self.hoses is not None:
            self.hoses = tuple(int(h) for h in self.hoses)
        self.span = tuple(self.span)  # type: ignore[assignment]
        self.amplitude = tuple(self.amplitude)  # type: ignore[assignment]
        self.period = tuple(self.period)  # type: ignore[assignment]

    def validate(self) -> PerturbConfig:
        if not isinstance(self.points, int) or self.points < 1:
            raise ConfigError("perturb.points", f"must be an integer >= 1, got {self.points!r}")
        check_range("perturb.span", self.span, 0.0, 1.0)
        check_range("perturb.amplitude", self.amplitude, 0.0)
        check_range("perturb.period", self.period, 1e-3)
        for name in ("stiffness", "max_force"):
            check_positive(f"perturb.{name}", getattr(self, name))
        check_positive("perturb.damping", self.damping, allow_zero=True)
        return self


@dataclass
class _Pull:
    body: int
    rest: np.ndarray
    direction: np.ndarray
    amplitude: float
    period: float
    phase: float


class PerturbedWorld:
    """A world whose ``step`` disturbs neighbouring hoses while an action is streamed."""

    def __init__(
        self,
        world: Any,
        config: PerturbConfig | None = None,
        hose_of_interest: int | None = None,
        seed: int = 0,
    ) -> None:
        cfg = (config or PerturbConfig(enabled=True)).validate()
        object.__setattr__(self, "_world", world)
        object.__setattr__(self, "perturb", cfg)
        object.__setattr__(self, "hose_of_interest", hose_of_interest)
        object.__setattr__(self, "_rng", np.random.default_rng([int(seed), 0x9E37]))
        object.__setattr__(self, "_pulls", [])
        object.__setattr__(self, "_t0", 0.0)
        object.__setattr__(self, "log", [])  # one entry per perturbed action

    # ------------------------------------------------------------------ delegation
    def __getattr__(self, name: str) -> Any:
        return getattr(object.__getattribute__(self, "_world"), name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "step":  # SimTrigger's hook lives on this wrapper
            object.__setattr__(self, name, value)
        else:
            setattr(self._world, name, value)

    def __delattr__(self, name: str) -> None:
        if name == "step":
            object.__delattr__(self, name)
        else:
            delattr(self._world, name)

    @property
    def world(self) -> Any:
        """The wrapped world."""
        return self._world

    def set_hose_of_interest(self, hose: int | None) -> None:
        object.__setattr__(self, "hose_of_interest", hose)

    # ------------------------------------------------------------------ stepping
    @property
    def streaming(self) -> bool:
        """True while a camera trigger hooks ``step`` (an action is being recorded)."""
        return "step" in vars(self)

    def step(self, n: int = 1) -> None:
        w = self._world
        if not (self.perturb.enabled and self.streaming):
            if self._pulls:
                self._stop()
            w.step(n)
            return
        if not self._pulls:
            self._start()
        for _ in range(int(n)):
            self._apply()
            w.step(1)

    def _targets(self) -> list[int]:
        cfg = self.perturb
        n = len(self._world.hoses)
        if cfg.hoses is not None:
            return [h for h in cfg.hoses if 0 <= h < n and h != self.hose_of_interest]
        return [h for h in range(n) if h != self.hose_of_interest]

    def _start(self) -> None:
        cfg, rng, w = self.perturb, self._rng, self._world
        d = w.data
        pulls: list[_Pull] = []
        # board plane: the world y and z axes (the board's front face is at constant x)
        for h in self._targets():
            bodies = np.asarray(w.hoses[h].vertex_bodies)
            n = len(bodies)
            lo, hi = int(math.floor(cfg.span[0] * (n - 1))), int(math.ceil(cfg.span[1] * (n - 1)))
            free = [k for k in range(lo, hi + 1) if bodies[k] > 0]
            if not free:
                continue
            ks = rng.choice(free, size=min(cfg.points, len(free)), replace=False)
            angle = rng.uniform(0, 2 * math.pi)
            e = np.array([0.0, math.cos(angle), math.sin(angle)])
            amp = float(rng.uniform(*cfg.amplitude))
            period = float(rng.uniform(*cfg.period))
            phase = float(rng.uniform(0, 2 * math.pi))
            for k in sorted(int(k) for k in ks):
                b = int(bodies[k])
                pulls.append(_Pull(b, d.xpos[b].copy(), e, amp, period, phase))
            self.log.append(
                {
                    "time": float(d.time),
                    "hose": h,
                    "vertices": sorted(int(k) for k in ks),
                    "amplitude_m": amp,
                    "period_s": period,
                    "direction_world": e.tolist(),
                }
            )
        object.__setattr__(self, "_pulls", pulls)
        object.__setattr__(self, "_t0", float(d.time))

    def _apply(self) -> None:
        import mujoco  # here, so that importing the config does not import MuJoCo

        cfg, w = self.perturb, self._world
        m, d = w.model, w.data
        t = float(d.time) - self._t0
        vel = np.zeros(6)
        for p in self._pulls:
            # ramp in over the first 0.2 s so the pull starts without a jolt
            ramp = min(1.0, t / 0.2)
            off = ramp * p.amplitude * math.sin(2 * math.pi * t / p.period + p.phase)
            target = p.rest + off * p.direction
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, p.body, vel, 0)
            f = cfg.stiffness * (target - d.xpos[p.body]) - cfg.damping * vel[3:]
            norm = float(np.linalg.norm(f))
            if norm > cfg.max_force:
                f *= cfg.max_force / norm
            d.xfrc_applied[p.body, :3] = f

    def _stop(self) -> None:
        d = self._world.data
        for p in self._pulls:
            d.xfrc_applied[p.body, :] = 0.0
        object.__setattr__(self, "_pulls", [])
