"""Synthetic frame streams with known truth, for tests and benchmarks (no simulator).

:func:`synthetic_stream` builds a stream whose ground-truth flow (``truth.flow_to_target``) is
prescribed per region as a function of the gripper displacement:

- ``"linear"`` regions move as ``gain * d_g`` (metres, converted to pixels by f/Z) along a
  direction (gain may be negative);
- ``"random"`` regions move by random amounts of similar size;
- ``"lag"`` regions follow the gripper with a phase lag;
- ``"oneoff"`` regions jump once and stay;
- ``"oneside"`` regions move as ``gain * d_g`` only while d_g > 0 (a neighbour the grasped hose
  pushes one way and leaves behind the other way) and rest otherwise;
- everything else gets Gaussian flow noise of ``noise_px`` standard deviation.

Images are random textures (warped consistently is not attempted: use the oracle flow).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cablesim.frames import (
    LABEL_BACKGROUND,
    TARGET_ACTION,
    Frame,
    FrameTruth,
    Intrinsics,
    Stream,
)


@dataclass
class Region:
    """A rectangle (y0, y1, x0, x1) with a motion model."""

    box: tuple[int, int, int, int]
    kind: str = "linear"  # linear | random | lag | oneoff | oneside | static
    gain: float = 1.0  # metres of surface motion per metre of gripper motion
    direction: tuple[float, float] | None = None  # image direction; None = action's
    label: int = LABEL_BACKGROUND


@dataclass
class SyntheticSpec:
    height: int = 48
    width: int = 64
    focal: float = 600.0
    depth: float = 1.0
    amplitude: float = 0.02
    periods: int = 3
    samples_per_period: int = 16
    action_dirs: list[tuple[float, float, float]] = field(
        default_factory=lambda: [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
    )
    noise_px: float = 0.2
    seed: int = 0


def triangle_wave(spec: SyntheticSpec) -> np.ndarray:
    """Gripper displacement profile g1 -> +D -> g1 -> -D -> g1, ``periods`` times (metres)."""
    n = spec.periods * spec.samples_per_period + 1
    t = np.arange(n) / spec.samples_per_period  # periods
    phase = t % 1.0
    tri = np.where(phase < 0.25, 4 * phase, np.where(phase < 0.75, 2 - 4 * phase, 4 * phase - 4))
    return spec.amplitude * tri


def synthetic_stream(regions: list[Region], spec: SyntheticSpec | None = None) -> Stream:
    """A stream of len(action_dirs) actions and a target frame with oracle flow."""
    spec = spec or SyntheticSpec()
    rng = np.random.default_rng(spec.seed)
    h, w = spec.height, spec.width
    K = Intrinsics(spec.focal, spec.focal, (w - 1) / 2, (h - 1) / 2, w, h)
    labels = np.full((h, w), LABEL_BACKGROUND, np.int16)
    for r in regions:
        y0, y1, x0, x1 = r.box
        labels[y0:y1, x0:x1] = r.label
    depth = np.full((h, w), spec.depth, np.float32)
    rgb = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    g0 = np.array([0.0, 0.0, spec.depth])
    profile = triangle_wave(spec)
    px_per_m = spec.focal / spec.depth
    frames: list[Frame] = []
    for a, dvec in enumerate(spec.action_dirs):
        u = np.asarray(dvec, float)
        u = u / np.linalg.norm(u)
        img_dir = u[:2] / max(np.linalg.norm(u[:2]), 1e-12)
        lagged = np.roll(profile, spec.samples_per_period // 4)
        lagged[: spec.samples_per_period // 4] = 0
        for k, d in enumerate(profile):
            flow = rng.normal(0.0, spec.noise_px, (h, w, 2)).astype(np.float32)
            if k == 0:
                flow[:] = 0.0
            for r in regions:
                y0, y1, x0, x1 = r.box
                dirn = np.asarray(r.direction if r.direction is not None else img_dir, float)
                dirn = dirn / np.linalg.norm(dirn)
                if r.kind == "linear":
                    mag = r.gain * d
                elif r.kind == "random":
                    mag = r.gain * rng.uniform(-spec.amplitude, spec.amplitude) if k else 0.0
                elif r.kind == "lag":
                    mag = r.gain * lagged[k]
                elif r.kind == "oneoff":
                    mag = r.gain * spec.amplitude * (k >= len(profile) // 2)
                elif r.kind == "oneside":
                    mag = r.gain * max(d, 0.0)
                elif r.kind == "static":
                    mag = 0.0
                else:
                    raise ValueError(f"unknown region kind {r.kind}")
                # flow of frame k to the target (where everything is back at rest): the point
                # shown at target pixel p was at p + displacement in frame k
                flow[y0:y1, x0:x1] += (mag * px_per_m * dirn).astype(np.float32)
            truth = FrameTruth(
                labels=labels, grasped_hose=0, flow_to_target=flow, flow_valid=np.ones((h, w), bool)
            )
            frames.append(
                Frame(
                    rgb=rgb,
                    depth=depth,
                    intrinsics=K,
                    gripper=g0 + d * u,
                    action=a,
                    sample=k,
                    timestamp=float(len(frames)),
                    truth=truth,
                )
            )
    tflow = np.zeros((h, w, 2), np.float32)
    frames.append(
        Frame(
            rgb=rgb,
            depth=depth,
            intrinsics=K,
            gripper=np.array([0.3, 0.3, 0.5]),
            action=TARGET_ACTION,
            sample=0,
            timestamp=float(len(frames)),
            truth=FrameTruth(
                labels=labels,
                grasped_hose=0,
                flow_to_target=tflow,
                flow_valid=np.ones((h, w), bool),
            ),
        )
    )
    return Stream(frames, {"synthetic": True})
