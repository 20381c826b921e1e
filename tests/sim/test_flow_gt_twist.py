"""The twist convention of ground-truth flow, checked against MuJoCo's own rod code.

A plain round hose looks the same however it is twisted, so the check uses a flat ribbon: a
rod of box section (40 x 15 mm), which MuJoCo draws as oriented boxes in the rod's material
frame (its time-parallel reference frame turned by the edge's twist angle).  The ribbon hangs
from one end and is spun about its own axis (a torque on the twist joints of its lower edges)
while its free end is pushed sideways.  Each hose pixel of the later image is carried back to
the earlier image by the ground-truth flow; where the convention is right, the carried surface
point lies on the ribbon MuJoCo rendered there (same label, depth within 6 mm: the flow's own
``valid``); with the opposite sign it mostly does not."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import CameraConfig, HoseConfig, RobotConfig, SceneConfig
from cablesim.sim.flow_gt import gt_flow
from cablesim.sim.layout import sample_hoses, start_shape
from cablesim.sim.world import World


def _about_tangent(frames: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Material frames turned by ``angle`` about their own tangent (first column)."""
    c, s = np.cos(angle), np.sin(angle)
    m1 = c[:, None] * frames[:, :, 1] + s[:, None] * frames[:, :, 2]
    m2 = np.cross(frames[:, :, 0], m1)
    return np.stack([frames[:, :, 0], m1, m2], axis=2)


def _flipped(snap):
    """The snapshot as an opposite twist sign would see it (frames turned by -2 theta)."""
    th = snap.hose_twist[0]
    return dataclasses.replace(
        snap,
        hose_twist=tuple(-t for t in snap.hose_twist),
        hose_frames=(_about_tangent(snap.hose_frames[0], -2 * th),),
    )


def _without_frames(snap):
    """The snapshot without MuJoCo's frames: bending from the centre line, plus the twist."""
    return dataclasses.replace(snap, hose_frames=())


@pytest.fixture(scope="module")
def ribbon():
    hoses = HoseConfig(
        count=1,
        section="box",
        section_size=(0.02, 0.0075),
        both_ends_probability=0.0,
        length=(0.6, 0.6),
        young=(3e6, 3e6),
        colors=((0.9, 0.7, 0.2),),
        color_jitter=0.0,
    )
    cfg = SceneConfig(
        seed=1, hoses=hoses, robot=RobotConfig(enabled=False), camera=CameraConfig(240, 180)
    )
    mid = start_shape(cfg, sample_hoses(cfg)[0])[15]
    cfg = cfg.with_values(
        {
            "camera.position": tuple(float(x) for x in mid + np.array([-0.45, 0.0, 0.0])),
            "camera.look_at": tuple(float(x) for x in mid),
        }
    )
    world = World.build(cfg)
    m, d = world.model, world.data
    hose = world.hoses[0]
    twist_dofs = [
        m.jnt_dofadr[j]
        for j in range(m.njnt)
        if m.joint(j).name.startswith(hose.spec.name + "_twist")
    ][-6:]
    t0 = d.time

    def drive(_world) -> None:
        d.qfrc_applied[:] = 0.0
        d.xfrc_applied[:] = 0.0
        if d.time - t0 < 0.15:
            d.qfrc_applied[twist_dofs] = 1.5e-4  # N m about each edge
            d.xfrc_applied[hose.vertex_bodies[-1], :3] = (0.0, 0.05, 0.0)

    with SimCamera(world) as cam:
        snaps = [cam.snapshot()]
        with world.hooks(before=[drive]):
            for _ in range(12):
                world.step(int(round(0.05 / m.opt.timestep)))
                snaps.append(cam.snapshot())
    return snaps


def _carried_onto_ribbon(later, earlier) -> float:
    """Share of the later image's ribbon pixels whose surface point, carried back by the
    ground-truth flow, lies on the ribbon rendered in the earlier image."""
    g = gt_flow(later, earlier)
    on = later.labels == 0
    return float(g.valid[on].mean())


def test_ribbon_twists_while_it_moves(ribbon):
    assert all(s.hose_frames[0] is not None for s in ribbon[1:])  # frames after physics
    twist = np.array([s.hose_twist[0].mean() for s in ribbon])
    moved = [np.abs(s.hose_vertices[0] - ribbon[0].hose_vertices[0]).max() for s in ribbon]
    assert twist[-1] - twist[0] > 1.5  # radians
    assert max(moved) > 0.01  # metres


@pytest.mark.parametrize("pair", [(2, 3), (3, 4), (4, 6), (8, 12)])
def test_twist_sign_matches_mujoco(ribbon, pair):
    """The carried points land on MuJoCo's ribbon with the convention of cablesim's flow, and
    clearly less often with the opposite sign; the same holds for the flow's fallback (bending
    from the centre line plus the change of twist) used when a snapshot has no rod state."""
    a, b = (ribbon[i] for i in pair)
    dtheta = float(np.mean(b.hose_twist[0] - a.hose_twist[0]))
    assert 0.3 < dtheta < 0.9, dtheta  # large enough to see, small enough to stay in view
    ours = _carried_onto_ribbon(b, a)
    opposite = _carried_onto_ribbon(_flipped(b), _flipped(a))
    print(
        f"pair {pair}: twist {dtheta:+.2f} rad, on the ribbon {ours:.2f} (opposite {opposite:.2f})"
    )
    assert ours > 0.85
    assert opposite < ours - 0.25
    fallback = _carried_onto_ribbon(_without_frames(b), _without_frames(a))
    fallback_opposite = _carried_onto_ribbon(
        _without_frames(_flipped(b)), _without_frames(_flipped(a))
    )
    assert fallback > fallback_opposite + 0.25
