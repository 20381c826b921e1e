"""Simulation-only measurements of an interaction (ground truth, for verification/evaluation).

- :class:`HosePoint`: a material point of a hose (edge + parameter along it) followed through
  the simulation: "the hose point under the fingers".
- :class:`MotionLog`: per camera tick, the gripper position, the grasped hose point and every
  hose's vertices; :meth:`MotionLog.follow_gain` regresses the hose point's displacement on the
  gripper's along the action direction, :meth:`MotionLog.hose_displacement` is the largest
  vertex displacement of each hose since the action started.
- :func:`settle_hoses`: step until every hose vertex is slower than a speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class HosePoint:
    """Point at parameter ``tau`` of edge ``edge`` (vertex edge -> edge+1) of hose ``hose``."""

    world: Any
    hose: int
    edge: int
    tau: float

    def position(self) -> np.ndarray:
        v = self.world.hose_vertices(self.hose)
        return v[self.edge] + self.tau * (v[self.edge + 1] - v[self.edge])

    __call__ = position

    @staticmethod
    def nearest(world: Any, point: np.ndarray, hose: int | None = None) -> tuple[HosePoint, float]:
        """The hose point nearest to world ``point`` (of hose ``hose``, or of any hose) and
        its distance."""
        p = np.asarray(point, dtype=float)
        best: tuple[HosePoint, float] | None = None
        hoses = range(len(world.hoses)) if hose is None else (hose,)
        for h in hoses:
            v = world.hose_vertices(h)
            a, b = v[:-1], v[1:]
            ab = b - a
            t = np.clip(
                np.einsum("ij,ij->i", p - a, ab) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1
            )
            d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
            e = int(np.argmin(d))
            if best is None or d[e] < best[1]:
                best = (HosePoint(world, h, e, float(t[e])), float(d[e]))
        assert best is not None
        return best


@dataclass
class MotionLog:
    """Gripper and hose positions (world) at every camera tick of each action."""

    hose_point: HosePoint | None = None
    times: dict[int, list[float]] = field(default_factory=dict)
    gripper: dict[int, list[np.ndarray]] = field(default_factory=dict)
    point: dict[int, list[np.ndarray]] = field(default_factory=dict)
    vertices: dict[int, list[list[np.ndarray]]] = field(default_factory=dict)

    def record(self, action: int, time: float, gripper_world: np.ndarray, world: Any) -> None:
        self.times.setdefault(action, []).append(float(time))
        self.gripper.setdefault(action, []).append(np.asarray(gripper_world, float).copy())
        if self.hose_point is not None:
            self.point.setdefault(action, []).append(self.hose_point.position())
        verts = [world.hose_vertices(i) for i in range(len(world.hoses))]
        self.vertices.setdefault(action, []).append(verts)

    def follow_gain(self, action: int, direction: np.ndarray) -> tuple[float, float]:
        """(gain, R^2): least-squares slope of the hose point's displacement on the gripper's,
        both projected on ``direction``, over the action's ticks."""
        if action not in self.point or len(self.point[action]) < 3:
            return math.nan, math.nan
        u = np.asarray(direction, float) / np.linalg.norm(direction)
        g = np.asarray(self.gripper[action])
        p = np.asarray(self.point[action])
        x = (g - g[0]) @ u
        y = (p - p[0]) @ u
        xc, yc = x - x.mean(), y - y.mean()
        sxx = float(xc @ xc)
        if sxx <= 1e-12:
            return math.nan, math.nan
        gain = float(xc @ yc) / sxx
        syy = float(yc @ yc)
        r2 = (float(xc @ yc) ** 2 / (sxx * syy)) if syy > 0 else math.nan
        return gain, r2

    def hose_displacement(self, action: int) -> list[float]:
        """Largest displacement (m) of any vertex of each hose from the action's first tick."""
        ticks = self.vertices.get(action, [])
        if not ticks:
            return []
        out = []
        for h in range(len(ticks[0])):
            v0 = ticks[0][h]
            out.append(max(float(np.linalg.norm(t[h] - v0, axis=1).max()) for t in ticks))
        return out


def settle_hoses(
    world: Any, speed: float = 0.001, max_time: float = 6.0, check_every: float = 0.1
) -> tuple[bool, float]:
    """Step until every hose vertex moves slower than ``speed`` (m/s), both on average over a
    check interval and over its last physics step; (settled, last measured speed)."""
    dt = float(world.model.opt.timestep)
    chunk = max(2, int(round(check_every / dt)))
    t_end = world.time + max_time
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
        if measured < speed:
            return True, measured
    return False, measured
