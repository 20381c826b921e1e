"""Cable surface patterns (stripes, a printed marking, twisted and braided strands): they move
with the cable exactly as the ground-truth flow says, are labelled as their cable, and leave a
solid cable's image untouched.

The warping check: a rope hangs from one end in front of a close camera and is spun about its
own axis (torques on the twist joints of its lower edges) while its free end is pushed sideways,
as in ``test_flow_gt_twist.py``.  The pattern is drawn blue on a yellow rope, so a pixel shows
the pattern where its blue exceeds its red, whatever the shading.  Each rope pixel of the later
image is carried back to the earlier image by the ground-truth flow; where the pattern moves as
the flow says, a pattern pixel lands on a pattern pixel.  With the opposite twist sign the
twisted strands and the marking land elsewhere (a half-turn's difference shifts them around the
rope), which shows the check can fail."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import cablesim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from cablesim.cables import CABLE_KINDS, PATTERNS, pattern_color
from cablesim.cli import main
from cablesim.config import to_dict
from cablesim.dataset.randomize import Randomization, randomize_scene
from cablesim.errors import ConfigError
from cablesim.sim.camera import SimCamera
from cablesim.sim.config import (
    CameraConfig,
    EpisodeConfig,
    HoseConfig,
    RobotConfig,
    SceneConfig,
)
from cablesim.sim.flow_gt import gt_flow
from cablesim.sim.layout import sample_hoses, start_shape
from cablesim.sim.patterns import fallback_frames, pattern_geom_bound, pattern_pieces
from cablesim.sim.world import World

YELLOW, BLUE = (0.9, 0.8, 0.1), (0.1, 0.2, 0.9)


def _about_tangent(frames: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m1 = c[:, None] * frames[:, :, 1] + s[:, None] * frames[:, :, 2]
    return np.stack([frames[:, :, 0], m1, np.cross(frames[:, :, 0], m1)], axis=2)


def _flipped(snap):
    """The snapshot as the opposite twist sign would see it."""
    th = snap.hose_twist[0]
    return dataclasses.replace(
        snap,
        hose_twist=tuple(-t for t in snap.hose_twist),
        hose_frames=(_about_tangent(snap.hose_frames[0], -2 * th),),
    )


def _spun_rope(pattern: str):
    hoses = HoseConfig(
        count=1,
        kind="rope",
        pattern=pattern,
        pattern_color=BLUE,
        colors=(YELLOW,),
        color_jitter=0.0,
        both_ends_probability=0.0,
        length=(0.6, 0.6),
    )
    cfg = SceneConfig(
        seed=1, hoses=hoses, robot=RobotConfig(enabled=False), camera=CameraConfig(320, 240)
    )
    mid = start_shape(cfg, sample_hoses(cfg)[0])[22]
    cfg = cfg.with_values(
        {
            "camera.position": tuple(float(x) for x in mid + np.array([-0.18, 0.0, 0.0])),
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
    ][-10:]
    t0 = d.time

    def drive(_world) -> None:
        d.qfrc_applied[:] = 0.0
        d.xfrc_applied[:] = 0.0
        if d.time - t0 < 0.15:
            d.qfrc_applied[twist_dofs] = 1.2e-4  # N m about each edge
            d.xfrc_applied[hose.vertex_bodies[-1], :3] = (0.0, 0.03, 0.0)

    with SimCamera(world) as cam:
        snaps = [cam.snapshot()]
        with world.hooks(before=[drive]):
            for _ in range(15):
                world.step(int(round(0.02 / m.opt.timestep)))
                snaps.append(cam.snapshot())
    return snaps


@pytest.fixture(scope="module", params=["twisted", "marking", "stripes"])
def spun(request):
    return request.param, _spun_rope(request.param)


def _is_pattern(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., 2].astype(int) > rgb[..., 0].astype(int)


def _landing(later, earlier) -> tuple[float, int]:
    """Share of the later image's pattern pixels (on the rope, validly carried) that the
    ground-truth flow carries onto pattern pixels of the earlier image, and their count."""
    g = gt_flow(later, earlier)
    on = (later.labels == 0) & g.valid
    ys, xs = np.nonzero(on & _is_pattern(later.image.rgb))
    if len(ys) == 0:
        return 0.0, 0
    tx = np.clip(np.rint(xs + g.flow[ys, xs, 0]).astype(int), 0, later.labels.shape[1] - 1)
    ty = np.clip(np.rint(ys + g.flow[ys, xs, 1]).astype(int), 0, later.labels.shape[0] - 1)
    return float(_is_pattern(earlier.image.rgb)[ty, tx].mean()), len(ys)


def test_the_rope_twists_and_moves(spun):
    _, snaps = spun
    twist = np.array([s.hose_twist[0][-8:].mean() for s in snaps])
    moved = np.abs(snaps[-1].hose_vertices[0] - snaps[0].hose_vertices[0]).max()
    assert twist[-1] - twist[0] > 2.0  # radians
    assert moved > 0.01  # metres


def test_patterns_move_as_the_ground_truth_flow_says(spun):
    """Every pair of consecutive snapshots in which the rope's lower part turned by 0.3 to 1
    rad and at least 100 pattern pixels show."""
    pattern, snaps = spun
    checked = 0
    for earlier, later in zip(snaps[:-1], snaps[1:], strict=True):
        dtheta = float(np.mean(later.hose_twist[0][-8:] - earlier.hose_twist[0][-8:]))
        ours, n = _landing(later, earlier)
        if not (0.3 < abs(dtheta) < 1.0 and n >= 100):
            continue
        checked += 1
        opposite, _ = _landing(_flipped(later), _flipped(earlier))
        print(
            f"{pattern} t={later.time:.2f}: twist {dtheta:+.2f} rad, {n} pattern px, "
            f"on the pattern {ours:.2f} (opposite sign {opposite:.2f})"
        )
        assert ours > 0.7
        if pattern != "stripes":  # rings look the same however the rope turns
            assert opposite < ours - 0.2
    assert checked >= 2


def test_pattern_pixels_are_labelled_as_their_cable(spun):
    _, snaps = spun
    s = snaps[-1]
    pattern_px = _is_pattern(s.image.rgb)
    assert pattern_px.sum() > 100
    assert (s.labels[pattern_px] == 0).mean() > 0.99


def test_every_pattern_builds_within_its_bound():
    cfg = SceneConfig(seed=3, hoses=HoseConfig(count=2, kinds=("rope", "thin_wire")))
    for spec in sample_hoses(cfg):
        verts = start_shape(cfg, spec)
        frames = fallback_frames(verts, np.zeros(len(verts) - 1))
        assert np.allclose(np.einsum("eij,eik->ejk", frames, frames), np.eye(3), atol=1e-9)
        rest = spec.length / (spec.n_vertices - 1)
        for name in PATTERNS:
            spec_p = dataclasses.replace(spec, cable=dataclasses.replace(spec.cable, pattern=name))
            pieces = pattern_pieces(
                name, verts, frames, spec.radius, rest, spec_p.cable.pattern_period
            )
            bound = pattern_geom_bound(spec_p)
            if name == "solid":
                assert pieces is None and bound == 0
                continue
            assert 0 < len(pieces) <= bound
            # every piece sits on the cable's surface, near its own stretch of the rod
            dist = np.min(
                np.linalg.norm(pieces.pos[:, None, :] - verts[None, :, :], axis=2), axis=1
            )
            assert dist.max() < rest + 2 * spec.radius


def test_pattern_colour_contrasts_with_the_cable():
    assert pattern_color("marking", (0.9, 0.9, 0.9))[0] < 0.3  # dark print on white
    assert pattern_color("marking", (0.05, 0.05, 0.05))[0] > 0.75  # light print on black
    assert pattern_color("twisted", (0.8, 0.6, 0.4)) == pytest.approx((0.36, 0.27, 0.18))
    assert pattern_color("stripes", (0.1, 0.1, 0.1), (1.0, 0.0, 0.0)) == (1.0, 0.0, 0.0)


def test_bad_patterns_are_refused_by_name():
    with pytest.raises(ConfigError, match="hoses.pattern.*'zigzag'"):
        HoseConfig(pattern="zigzag")
    with pytest.raises(ConfigError, match=r"hoses.patterns\[1\].*'dots'"):
        HoseConfig(patterns=("solid", "dots"))
    with pytest.raises(ConfigError, match="hoses.pattern_period"):
        HoseConfig(kind="rope", pattern="stripes", pattern_period=0.005)
    with pytest.raises(ConfigError, match=r"hoses.pattern_color\[2\]"):
        HoseConfig(pattern_color=(0.1, 0.2, 1.5))


def test_per_cable_patterns_round_trip():
    cfg = SceneConfig(
        hoses=HoseConfig(count=3, kinds=("rope", "electrical_cable"), patterns=("braided",))
    )
    again = SceneConfig.from_dict(cfg.to_dict())
    assert again == cfg
    assert [again.hoses.cable(i).pattern for i in range(3)] == ["braided"] * 3
    assert HoseConfig(kind="rope").cable(0).pattern == "twisted"
    assert HoseConfig().cable(0).pattern == "solid"  # the default hose stays plain


def test_the_dataset_randomiser_draws_patterns_from_their_own_stream() -> None:
    base = SceneConfig()
    every = Randomization(cable_kinds=tuple(CABLE_KINDS), cable_patterns=tuple(PATTERNS))
    scenes = [randomize_scene(s, base, every) for s in range(30)]
    assert {p for c in scenes for p in c.hoses.patterns} == set(PATTERNS)
    assert all(len(c.hoses.patterns) == c.hoses.count for c in scenes)
    # the other draws, kinds included, are those of a dataset made before patterns existed
    kinds_only = Randomization(cable_kinds=tuple(CABLE_KINDS))
    for s, a in enumerate(scenes):
        b = randomize_scene(s, base, kinds_only)
        assert b.hoses.patterns == () and b.hoses.pattern is None
        assert a.replace(hoses=a.hoses.replace(patterns=())) == b
    one = randomize_scene(3, base, Randomization(cable_patterns=("stripes",)))
    assert one.hoses.pattern == "stripes" and one.hoses.patterns == ()
    with pytest.raises(ConfigError, match=r"cable_patterns\[0\]"):
        Randomization(cable_patterns=("plaid",))


def test_the_pattern_flag_puts_one_pattern_on_every_cable(tmp_path, capsys) -> None:
    path = tmp_path / "config.json"
    mixed = EpisodeConfig(scene=SceneConfig(hoses=HoseConfig(patterns=("twisted", "marking"))))
    path.write_text(json.dumps(to_dict(mixed)))
    assert main(["episode", "--config", str(path), "--pattern", "stripes", "--show-config"]) == 0
    out = capsys.readouterr().out
    assert 'scene.hoses.pattern = "stripes"' in out and "scene.hoses.patterns = []" in out
    assert main(["cables", "--patterns"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(PATTERNS)
