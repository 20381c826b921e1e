"""Explicit, seeded perturbation of neighbouring hoses during actions.

SPEC section 1: other hoses may be perturbed by the robot or by the grasped hose and must not
be labelled.  Contacts perturb neighbours naturally but rarely by much; this module adds an
explicit, reproducible disturbance so that the claim "motion correlation beats motion
segmentation when neighbouring hoses are perturbed" can be tested on purpose.

Mechanism: :class:`NeighbourPerturbation` is an action hook of the simulated clock
(:class:`~cablesim.sim.clock.SimClock`): it runs only while an action is recorded.  At the
start of each action it draws, from its seeded generator, a few vertex bodies of each perturbed
hose, an amplitude ``A``, a period ``P``, a phase and a unit direction ``e`` in the board plane;
before every physics step of the action it sets ``data.xfrc_applied`` on those vertices: a
damped, capped spring pulls each towards ``rest + A sin(2 pi (t - t0) / P + phase) e``, where
``rest`` is the vertex's position when the action started (its gains scaled down on a vertex
lighter than :data:`REFERENCE_MASS`, its damping capped at the vertex's mass over the physics
timestep: :func:`stable_damping`).  The motion is independent of the
gripper (its own period and phase).  When the action ends the forces are removed, so release,
retreat and settling (and the target frame) are not disturbed::

    perturbation = NeighbourPerturbation(PerturbConfig(enabled=True), stream(seed, "perturb"))
    perturbation.hose_of_interest = 2
    clock = SimClock(world, robot, camera.capture, action_hooks=[perturbation])
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from cablesim.sim.config import PerturbConfig

#: kg: the config's stiffness, damping and force cap are for a vertex at least this heavy (the
#: garden hose's weighs 4.3 g); a lighter one gets them times its mass over this, so that the
#: pull moves every cable alike.  Unscaled, the explicit damping (3 N s/m, over a 4 ms step)
#: overshot on light vertices: 136 of the 140 thin-wire scenes (0.2 g vertices) the
#: realistic-flow benchmark tried tore during the perturbed actions; the electrical cable's
#: (1.6 g) and the rope's (1.3 g) got 2.7 and 3.4 times the hose's damping per unit mass.
REFERENCE_MASS = 0.004


def stable_damping(damping: float, mass: float, timestep: float) -> float:
    """``damping`` (N s/m) capped at ``mass / timestep``.

    The pull is an explicit force, read from the vertex's velocity at the start of a step.  One
    step of a vertex of mass m under a spring k and a damper c maps (velocity, position) with
    determinant ``1 - c dt / m``: above ``c dt / m = 2`` the step amplifies, and above 1 the
    damper alone reverses the vertex's velocity within a step.  The config's 3 N s/m on a
    4.3 g hose vertex over a 4 ms step is ``c dt / m = 2.8``: the pulled vertices rang at the
    step's frequency up to the force cap (velocity reversed on 14-24 % of the steps, peaks of
    1.5 m/s where the pull's own motion is about 0.05 m/s; on the table, where the mat's
    friction takes part, a perturbed rope's action took 0.6 s per step and failed).  Capped,
    ``c dt / m <= 1``: no reversal, the pull moves the vertex as drawn."""
    return min(float(damping), float(mass) / float(timestep))


def spring_force(
    model: Any,
    data: Any,
    body: int,
    target: np.ndarray,
    stiffness: float,
    damping: float,
    max_force: float,
) -> np.ndarray:
    """The explicit pull on ``body`` towards ``target``: ``stiffness (target - x) - damping v``
    (v the body's linear velocity), its norm capped at ``max_force`` (N).  Give it a damping
    from :func:`stable_damping`.  Shared by the perturbation and ``cablesim scene``'s pull."""
    vel = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, vel, 0)
    f = stiffness * (target - data.xpos[body]) - damping * vel[3:]
    norm = float(np.linalg.norm(f))
    if norm > max_force:
        f *= max_force / norm
    return f


@dataclass
class _Pull:
    body: int
    rest: np.ndarray
    direction: np.ndarray
    amplitude: float
    period: float
    phase: float
    scale: float  # of the gains and the cap: min(1, the vertex's mass / REFERENCE_MASS)
    damping: float  # N s/m: the scaled damping, capped by stable_damping


class NeighbourPerturbation:
    """Seeded disturbance of the hoses other than ``hose_of_interest`` during actions."""

    def __init__(
        self,
        config: PerturbConfig | None = None,
        rng: np.random.Generator | None = None,
        hose_of_interest: int | None = None,
    ) -> None:
        self.config = config or PerturbConfig(enabled=True)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.hose_of_interest = hose_of_interest
        self.log: list[dict[str, Any]] = []  # one entry per perturbed hose and action
        self._pulls: list[_Pull] = []
        self._t0 = 0.0

    def _targets(self, world: Any) -> list[int]:
        cfg = self.config
        n = len(world.hoses)
        if cfg.hoses is not None:
            return [h for h in cfg.hoses if 0 <= h < n and h != self.hose_of_interest]
        return [h for h in range(n) if h != self.hose_of_interest]

    # ---- action hook ----------------------------------------------------------------------
    def start(self, world: Any) -> None:
        """Draw this action's pulls (nothing when disabled)."""
        self._pulls = []
        if not self.config.enabled:
            return
        cfg, rng = self.config, self.rng
        d = world.data
        # in the surface's plane: the board's world y and z axes, the table's x and y
        e1, e2 = (np.asarray(a, float) for a in world.surface.plane)
        for h in self._targets(world):
            bodies = np.asarray(world.hoses[h].vertex_bodies)
            n = len(bodies)
            lo, hi = int(math.floor(cfg.span[0] * (n - 1))), int(math.ceil(cfg.span[1] * (n - 1)))
            free = [k for k in range(lo, hi + 1) if bodies[k] > 0]
            if not free:
                continue
            ks = rng.choice(free, size=min(cfg.points, len(free)), replace=False)
            angle = rng.uniform(0, 2 * math.pi)
            e = math.cos(angle) * e1 + math.sin(angle) * e2
            e[e == 0] = 0.0  # no -0.0 in the log
            amp = float(rng.uniform(*cfg.amplitude))
            period = float(rng.uniform(*cfg.period))
            phase = float(rng.uniform(0, 2 * math.pi))
            for k in sorted(int(k) for k in ks):
                b = int(bodies[k])
                m = world.model  # the vertex's weight (an inertia_scale is compensated)
                weight = float(m.body_mass[b]) * (1.0 - float(m.body_gravcomp[b]))
                scale = min(1.0, weight / REFERENCE_MASS)
                damping = stable_damping(scale * cfg.damping, m.body_mass[b], m.opt.timestep)
                self._pulls.append(
                    _Pull(b, d.xpos[b].copy(), e, amp, period, phase, scale, damping)
                )
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
        self._t0 = float(d.time)

    def before_step(self, world: Any) -> None:
        if not self._pulls:
            return

        cfg = self.config
        m, d = world.model, world.data
        t = float(d.time) - self._t0
        for p in self._pulls:
            # ramp in over the first 0.2 s so the pull starts without a jolt
            ramp = min(1.0, t / 0.2)
            off = ramp * p.amplitude * math.sin(2 * math.pi * t / p.period + p.phase)
            target = p.rest + off * p.direction
            # a vertex lighter than REFERENCE_MASS gets the gains and the cap in proportion to
            # its mass: the same pull per unit mass as the hose's; the damping stays stable
            s = p.scale
            d.xfrc_applied[p.body, :3] = spring_force(
                m, d, p.body, target, s * cfg.stiffness, p.damping, s * cfg.max_force
            )

    def stop(self, world: Any) -> None:
        for p in self._pulls:
            world.data.xfrc_applied[p.body, :] = 0.0
        self._pulls = []
