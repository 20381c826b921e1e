"""The table-top scene (``SceneConfig.surface = "table"``): cables lying and crossing on a mat,
plugged into sockets on the table at one or both ends, grasped from above."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cablesim.cli import main
from cablesim.config import from_dict, to_dict
from cablesim.dataset.randomize import Randomization, randomize_scene
from cablesim.episode import primitives as prim
from cablesim.episode.surface import BOARD, FINGERTIP_REACH, TABLE
from cablesim.errors import ConfigError
from cablesim.sim.config import (
    SURFACE_IMPRATIO,
    SURFACE_VIEWS,
    EpisodeConfig,
    HoseConfig,
    SceneConfig,
)
from cablesim.sim.layout import sample_hoses, start_shape
from cablesim.sim.table import LEAD, MAT_TOP, MIN_BEND_RADIUS, socket_point, turn_angles, unkink


def table(seed: int = 1, **values) -> SceneConfig:
    return SceneConfig(seed=seed, surface="table").with_values(values)


def _arc(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def _min_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest distance between two polylines, both densified to 5 mm."""
    from scipy.spatial import cKDTree

    def dense(p: np.ndarray) -> np.ndarray:
        out = [p[:1]]
        for u, v in zip(p[:-1], p[1:], strict=True):
            n = max(1, int(np.ceil(np.linalg.norm(v - u) / 0.005)))
            out.append(u + (np.arange(1, n + 1)[:, None] / n) * (v - u))
        return np.concatenate(out)

    return float(cKDTree(dense(b)).query(dense(a))[0].min())


# ---------------------------------------------------------------------- layout (no physics)
@pytest.mark.parametrize("kind", ["garden_hose", "thin_wire", "rope"])
def test_start_shapes_lie_apart_on_the_table_with_their_lengths_and_sockets(kind: str) -> None:
    plugged_far, free_far = 0, 0
    for seed in range(6):
        cfg = table(seed, **{"hoses.kind": kind, "hoses.count": 5})
        specs = sample_hoses(cfg)
        shapes = [start_shape(cfg, s) for s in specs]
        for s, p in zip(specs, shapes, strict=True):
            assert p.shape == (s.n_vertices, 3)
            assert _arc(p) == pytest.approx(s.length, rel=0.01)
            chords = np.linalg.norm(np.diff(p, axis=0), axis=1)
            assert chords.max() / chords.min() < 1.05  # the rod's rest spacing, evenly
            assert np.allclose(p[0], socket_point(cfg, s.ends[0]))
            if s.both_ends:
                assert np.allclose(p[-1], socket_point(cfg, s.ends[1]), atol=1e-9)
                plugged_far += 1
            else:
                free_far += 1
            assert (p[:, 2] >= s.radius).all() and (p[:, 2] < 0.2).all()  # above the table
            x, y = p[:, 0], p[:, 1]
            assert (np.abs(y) < 0.85).all() and ((x > -0.6) & (x < 0.9)).all()  # on it
        # no two start shapes cut into each other: each lies at its own height where they
        # cross, or is lifted over the other (evening the chords out again after a lift may
        # bring them within a fraction of a millimetre of touching)
        for i in range(len(specs)):
            for j in range(i + 1, len(specs)):
                gap = _min_distance(shapes[i], shapes[j])
                assert gap > 0.9 * (specs[i].radius + specs[j].radius), (seed, i, j, gap)
        assert len({s.ends[0] for s in specs}) == len(specs)  # one cable per socket
    assert plugged_far > 0 and free_far > 0  # some far ends plugged, some free


def _u_turn() -> np.ndarray:
    """A plan-view path that leaves its socket along +x for 6 cm, then turns straight back
    through a corner (the kind of path smoothed random waypoints gave)."""
    corners = [(0.0, 0.0), (LEAD, 0.0), (0.1, 0.0), (-0.2, 0.01), (-0.2, 0.25), (0.1, 0.3)]
    out = []
    for a, b in zip(corners[:-1], corners[1:], strict=True):
        t = np.linspace(0.0, 1.0, 200, endpoint=False)[:, None]
        out.append(np.asarray(a) + t * (np.subtract(b, a)))
    return np.vstack([*out, [corners[-1]]])


@pytest.mark.parametrize("both", [False, True])
def test_unkink_rounds_every_corner_and_keeps_the_length_and_the_leads(both: bool) -> None:
    path = _u_turn()
    length, n = _arc(path), 40
    chord = length / (n - 1)
    limit = chord / MIN_BEND_RADIUS

    def at_vertices(p: np.ndarray) -> np.ndarray:
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        t = np.linspace(0.0, s[-1], n)
        return np.stack([np.interp(t, s, p[:, k]) for k in range(2)], 1)

    assert turn_angles(at_vertices(path)).max() > 2.5  # corners of about 180 degrees
    out = unkink(path, n, keep_end=both)
    v = at_vertices(out)
    assert _arc(out) == pytest.approx(length, rel=0.01)
    assert turn_angles(v).max() < 1.15 * limit  # no bend tighter than MIN_BEND_RADIUS
    # the chords on the lead (6 cm straight out of the socket along +x) stay on it
    head = out[: int(math.floor(LEAD / chord) * chord / 0.002)]
    assert np.allclose(out[0], path[0]) and np.abs(head[:, 1]).max() < 1e-9
    if both:  # plugged at both ends: the far end stays in its socket
        assert np.allclose(out[-1], path[-1], atol=1e-6)


def test_start_shapes_on_the_table_bend_like_cables_not_like_hinges() -> None:
    """Over 20 scenes, a cable's start shape turns by at most 1.15 chord / MIN_BEND_RADIUS
    between neighbouring vertices in plan view (free ends), and the plugged-at-both-ends ones
    mostly so: smoothed random waypoints alone gave 90-130 degree corners on most cables, which
    stretched edges by 25-45 % in the first step."""
    free, both = [], []
    for seed in range(20):
        cfg = table(seed)
        for s in sample_hoses(cfg):
            p = start_shape(cfg, s)[:, :2]
            chord = s.length / (s.n_vertices - 1)
            worst = turn_angles(p[1:]).max() / (chord / MIN_BEND_RADIUS)  # past the socket
            (both if s.both_ends else free).append(worst)
    assert len(free) > 10 and len(both) > 10
    assert np.median(free) < 1.15 and np.median(both) < 2.0, (np.median(free), np.median(both))


def test_the_table_layout_is_the_seeds_alone() -> None:
    a = [start_shape(table(5), s) for s in sample_hoses(table(5))]
    b = [start_shape(table(5), s) for s in sample_hoses(table(5))]
    c = [start_shape(table(6), s) for s in sample_hoses(table(6))]
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(x.shape == y.shape and np.allclose(x, y) for x, y in zip(a, c, strict=False))


# ---------------------------------------------------------------------- config
def test_the_table_holds_its_cables_with_stiffer_friction() -> None:
    from cablesim.sim.world import World

    assert table().impratio() == SURFACE_IMPRATIO["table"] == 30.0
    assert SceneConfig().impratio() == SURFACE_IMPRATIO["board"] == 10.0
    assert table(**{"physics.impratio": 100}).impratio() == 100.0
    with pytest.raises(ConfigError, match=r"physics\.impratio.*0\.5"):
        table(**{"physics.impratio": 0.5})
    w = World.build(table(3, **{"hoses.count": 2}), settle=False)
    assert w.model.opt.impratio == 30.0


def test_the_surface_is_a_checked_field_with_its_own_camera_view() -> None:
    assert SceneConfig().surface == "board" and SceneConfig().view() == SURFACE_VIEWS["board"]
    assert table().view() == SURFACE_VIEWS["table"]
    assert table(**{"camera.position": (0.3, -0.4, 0.7)}).view()[0] == (0.3, -0.4, 0.7)
    with pytest.raises(ConfigError, match="surface.*'desk'"):
        SceneConfig(surface="desk")
    with pytest.raises(ConfigError, match="hoses.count.*the table has 2"):
        table(**{"table.connectors": ((0.1, 0.0, 0.0), (0.6, 0.0, math.pi))})
    with pytest.raises(ConfigError, match="table.region"):
        table(**{"table.region": (0.2, 0.25, -0.2, 0.2)})
    with pytest.raises(ConfigError, match=r"table.connectors\[0\].*off the table"):
        table(**{"table.connectors": ((2.0, 0.0, 0.0),) * 4})
    with pytest.raises(ConfigError, match="table.socket_height"):
        table(**{"table.socket_height": 0.006})  # under a 15 mm hose's centre
    with pytest.raises(ConfigError, match="interaction.kind.*table"):
        EpisodeConfig(scene=table()).with_values({"interaction.kind": "push"})


def test_a_mixed_table_scene_round_trips_through_config_json() -> None:
    cfg = EpisodeConfig(
        scene=SceneConfig(
            seed=4, surface="table", hoses=HoseConfig(count=3, kinds=("rope", "thin_wire"))
        )
    )
    again = from_dict(EpisodeConfig, json.loads(json.dumps(to_dict(cfg))))
    assert again == cfg and again.scene.surface == "table"
    assert [s.kind for s in sample_hoses(again.scene)] == ["rope", "thin_wire", "rope"]


def test_the_scene_flag_writes_the_surface(capsys) -> None:
    assert main(["episode", "--scene", "table", "--seed", "3", "--show-config"]) == 0
    out = capsys.readouterr().out
    assert 'scene.surface = "table"' in out and "scene.camera.position = null" in out
    assert main(["benchmark", "thesis", "--scene", "table", "--show-config"]) == 0
    assert 'scene.surface = "table"' in capsys.readouterr().out


def test_the_dataset_randomiser_draws_the_mats_background_on_the_table() -> None:
    board = randomize_scene(7, SceneConfig(), Randomization())
    mat = randomize_scene(7, table(), Randomization())
    assert mat.table.background == board.board.background  # the same draw, on the mat
    assert mat.table.solid_rgb == board.board.solid_rgb
    assert mat.board == SceneConfig().board and board.table == SceneConfig().table


# ---------------------------------------------------------------------- directions, grasp height
def test_actions_on_the_table_stay_in_its_plane() -> None:
    """The table's camera looks down at 62 degrees: the image plane's direction of a cable
    along x would tilt 28 degrees into the table; the table's own plane does not."""
    cfg = table()
    from cablesim.sim.regions import camera_pose

    T = camera_pose(cfg)
    axis = np.array([1.0, 0.3, 0.0]) / np.hypot(1.0, 0.3)
    for name in ("along", "across", "horizontal"):
        d = prim.action_direction(name, axis, T, TABLE)
        assert abs(d[2]) < 1e-12 and np.linalg.norm(d) == pytest.approx(1.0)
    along = prim.action_direction("along", axis, T, TABLE)
    assert along @ axis == pytest.approx(1.0)
    assert prim.action_direction("normal", axis, T, TABLE) == pytest.approx([0, 0, 1])
    on_board = prim.action_direction("along", np.array([0.0, 0.6, -0.8]), T, BOARD)
    assert abs(on_board[2]) > 0.3  # the board keeps the image plane (the thesis's)


def test_a_grasp_on_the_table_brings_the_fingertips_down_to_the_mat() -> None:
    low = np.array([0.3, -0.1, 0.001])  # a 2 mm wire's centre
    assert TABLE.clearance == 0.0
    assert TABLE.grasp_centre(low)[2] == pytest.approx(MAT_TOP + FINGERTIP_REACH)
    high = np.array([0.3, -0.1, 0.05])  # on top of a pile: as seen
    assert np.array_equal(TABLE.grasp_centre(high), high)
    assert np.array_equal(BOARD.grasp_centre(low), low)


# ---------------------------------------------------------------------- physics
@pytest.fixture(scope="module")
def table_world():
    from cablesim.sim.world import World

    cfg = table(2, **{"hoses.count": 3, "camera.width": 160, "camera.height": 120})
    return World.build(cfg.with_values({"physics.cache": False}))


def test_the_table_scene_settles_with_its_cables_lying_on_the_mat(table_world) -> None:
    from cablesim.sim.camera import SimCamera

    w = table_world
    assert w.surface is TABLE and w.hose_stretch().max() < 0.01
    for h in w.hoses:
        v = w.hose_vertices(h.spec.index)
        r = h.spec.radius
        assert v[:, 2].min() == pytest.approx(MAT_TOP + r, abs=0.002)  # resting on the mat
        assert v[:, 2].max() < 0.06  # lying: on the mat, on the other cables, over a plug
        assert np.allclose(v[0], socket_point(w.cfg, h.spec.ends[0]), atol=0.003)  # plugged
    with SimCamera(w) as cam:
        labels = cam.render_labels()
    assert not (labels == -2).any()  # the parked arm is out of the table camera's view
    # settled means still: MuJoCo's soft friction let cables plugged at both ends creep over
    # the mat at 1-5 mm/s at impratio 10; at the table's 30 they creep slower than the settle
    # threshold (0.6 mm/s here), so two seconds more move no vertex by 2 mm
    state = w.get_state()
    before = w.all_hose_vertices().copy()
    w.step(int(2.0 / w.model.opt.timestep))
    moved = np.linalg.norm(w.all_hose_vertices() - before, axis=1).max()
    w.set_state(state)
    assert moved < 2.0 * w.cfg.physics.settle_speed, moved
    assert set(np.unique(labels)) >= {0, 1, 2}  # every cable in view


def _collide(m, g1: int, g2: int | tuple[int, int]) -> bool:
    """MuJoCo's contype/conaffinity rule for geom ``g1`` and geom ``g2`` (or a flex's bits,
    ``(contype, conaffinity)``)."""
    bits = (m.geom_contype[g2], m.geom_conaffinity[g2]) if isinstance(g2, int) else g2
    return bool((m.geom_contype[g1] & bits[1]) or (bits[0] & m.geom_conaffinity[g1]))


def test_the_finger_pads_reach_into_the_mat_but_nothing_else_does(table_world) -> None:
    """The pads pass into the mat and the table top (a grasp on the table brings the
    fingertips down to the mat, as a compliant hand does), while they still hold cables, and
    the rest of the arm, the cables and the planner's arm model still meet the mat."""
    import mujoco

    from cablesim.panda.ik import static_obstacles
    from cablesim.pose import grasp_pose
    from cablesim.sim.sim_panda import SimPanda

    w = table_world
    m = w.model
    gid = {m.geom(g).name: g for g in range(m.ngeom)}
    pads = [g for n, g in gid.items() if n.endswith("finger_pad")]
    bodies = [g for n, g in gid.items() if n.endswith("finger_body")]
    assert len(pads) == 2 and len(bodies) == 2
    for surface in ("mat", "table"):
        assert not any(_collide(m, p, gid[surface]) for p in pads)
        assert all(_collide(m, b, gid[surface]) for b in bodies)
    flex = int(m.flex_contype[0]), int(m.flex_conaffinity[0])
    for g in pads + [gid["mat"], gid["table"]]:  # cables meet the pads and the mat
        assert _collide(m, g, flex)

    robot = SimPanda(w)
    mat = next(o for o in static_obstacles(m, w.data) if o.name == "mat")
    assert (mat.contype, mat.conaffinity) == (
        m.geom_contype[gid["mat"]],
        m.geom_conaffinity[gid["mat"]],
    )
    state = w.get_state()
    try:
        centre = np.array([0.45, 0.0, MAT_TOP + FINGERTIP_REACH])  # fingertips on the mat
        for depth, refused in ((0.0, False), (0.001, False), (0.006, True)):
            pose = grasp_pose(centre - [0, 0, depth], [0.0, 1.0, 0.0], TABLE.approach)
            ok, reason = robot.check_reachable(pose)
            assert ok is not refused, (depth, reason)
            if refused:  # the finger bodies, 2.5 mm short of the fingertips, meet the mat
                assert "finger_body" in reason and ("mat" in reason or "table" in reason), reason
    finally:
        w.set_state(state)
        mujoco.mj_forward(m, w.data)


def test_on_the_table_the_pads_collide_past_the_fingertips_and_look_as_built(table_world) -> None:
    """The table scene's pads reach ``table.pad_reach`` past the fingertips (into the mat that
    lets them in), hidden; a visual-only copy of each pad as built draws it.  The board's pads
    are as built."""
    from cablesim.panda.model import PAD_CONTYPE
    from cablesim.sim.world import World

    m = table_world.model
    reach = table_world.cfg.table.pad_reach
    assert reach == pytest.approx(0.003)
    for side in ("left", "right"):
        pad, look = m.geom(f"panda/{side}_finger_pad"), m.geom(f"panda/{side}_finger_pad_visual")
        tip = look.pos[2] + look.size[2]
        assert pad.pos[2] + pad.size[2] == pytest.approx(tip + reach, abs=1e-12)
        assert pad.pos[2] - pad.size[2] == pytest.approx(look.pos[2] - look.size[2], abs=1e-12)
        assert (pad.group[0], look.group[0]) == (3, 1)  # MuJoCo draws groups 0-2
        assert m.geom_contype[look.id] == m.geom_conaffinity[look.id] == 0
        assert m.geom_contype[pad.id] == PAD_CONTYPE
    board = World.build(SceneConfig(seed=2).with_values({"physics.cache": False}), settle=False)
    as_built = m.geom("panda/left_finger_pad_visual")
    assert np.array_equal(board.model.geom("panda/left_finger_pad").size, as_built.size)
    with pytest.raises(KeyError):
        board.model.geom("panda/left_finger_pad_visual")
    with pytest.raises(ConfigError, match="table.pad_reach"):
        table(2, **{"table.pad_reach": -0.001})


@pytest.mark.parametrize("reach", [0.0, 0.003])
def test_a_wire_pressed_into_a_pad_is_pushed_back_between_the_pads(reach: float) -> None:
    """MuJoCo pushes a cable vertex out of a box through the face nearest its centre.  A 2 mm
    wire held on the mat lies 1 mm above the fingertips; pressed 1.2 mm into a pad, it is
    pushed out through the pad's lower face, under the fingertips (the thin wire's failure on
    the table, docs/cables.md), unless the pad reaches past the tips (``reach_pads``): then it
    is pushed back across the pad's face, between the fingers."""
    import mujoco

    from cablesim.panda.model import panda_spec, reach_pads

    spec = panda_spec(prefix="panda/")
    built = spec.geom("panda/left_finger_pad")
    tip = built.pos[2] + built.size[2]  # the fingertip along the finger's z
    reach_pads(spec, reach, prefix="panda/")
    vertex = spec.worldbody.add_body(name="vertex", mocap=True)
    vertex.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.001, 0, 0])
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_kinematics(m, d)
    finger = m.body("panda/left_finger").id
    R = d.xmat[finger].reshape(3, 3)  # the finger's y: across the pad's face; z: to the tip
    d.mocap_pos[0] = d.xpos[finger] + R @ [0.0, 0.0012, tip - 0.001]
    mujoco.mj_forward(m, d)
    pad = m.geom("panda/left_finger_pad").id
    normals = [
        R.T @ d.contact[i].frame[:3]
        for i in range(d.ncon)
        if pad in (d.contact[i].geom1, d.contact[i].geom2)
    ]
    assert len(normals) == 1
    across, down = abs(normals[0][1]), abs(normals[0][2])
    if reach:
        assert across == pytest.approx(1.0) and down < 1e-9
    else:
        assert down == pytest.approx(1.0) and across < 1e-9


def test_the_perturbation_pulls_in_the_tables_plane(table_world) -> None:
    from cablesim.seeding import stream
    from cablesim.sim.config import PerturbConfig
    from cablesim.sim.perturb import NeighbourPerturbation

    p = NeighbourPerturbation(PerturbConfig(enabled=True), stream(1, "perturb"))
    p.hose_of_interest = 0
    p.start(table_world)
    try:
        assert p.log and all(e["direction_world"][2] == 0.0 for e in p.log)
    finally:
        p.stop(table_world)


def test_a_cable_on_the_table_is_grasped_from_above_and_follows_the_hand() -> None:
    """A whole simulated interaction on the table: the hand comes down (its approach axis is
    world -z), the fingertips stay above the mat, the grasp holds and the cable follows both
    actions, which move in the table's plane."""
    from cablesim.sim.session import SimSession

    scene = table(1, **{"hoses.count": 3, "camera.width": 320, "camera.height": 240})
    cfg = EpisodeConfig(scene=scene).with_values({"interaction.actions.periods": 1})
    session = SimSession.build(cfg)
    try:
        assert session.surface is TABLE
        result = session.interact(session.pick_start().mask)
        assert result.success, (result.outcome, result.reason)
        g = result.grasp
        assert g is not None and g.rotation[:, 2] @ [0, 0, -1] > math.cos(math.radians(15))
        assert g.position[2] >= MAT_TOP + FINGERTIP_REACH
        assert result.details["grasp"]["hold_error"] < 0.005
        assert all(a.gain > 0.5 for a in result.actions), [a.gain for a in result.actions]
        stream, T = result.stream, session.T_world_camera
        assert stream is not None
        for a in range(len(result.actions)):
            path = np.array([T[:3, :3] @ f.gripper + T[:3, 3] for f in stream.action_frames(a)])
            assert np.ptp(path[:, 2]) < 0.005  # the hand slid over the table, not into it
            assert np.hypot(*np.ptp(path[:, :2], axis=0)) > 0.03  # 2 x 2 cm, in the plane
    finally:
        session.close()


def test_a_rescue_on_the_table_ends_once_the_stretch_is_gone() -> None:
    import mujoco

    from cablesim.sim.config import SURFACE_RESCUE_RELEASE
    from cablesim.sim.world import _SOLVERS, World

    assert table().rescue_release() == SURFACE_RESCUE_RELEASE["table"] == 0.1
    assert SceneConfig().rescue_release() == SURFACE_RESCUE_RELEASE["board"] == 0.0
    with pytest.raises(ConfigError, match=r"physics\.rescue_release.*0\.1.*rescue_strain"):
        table(**{"physics.rescue_strain": 0.05})
    with pytest.raises(ConfigError, match=r"physics\.rescue_release.*-1"):
        table(**{"physics.rescue_release": -1})
    for release, left in ((None, 0), (0.0, 99)):
        w = World.build(
            table(3, **{"hoses.count": 2, "physics.rescue_release": release}), settle=False
        )
        m = w.model
        # a rescue under way (as _advance starts one), with every edge near its rest length
        m.opt.solver, m.opt.jacobian = _SOLVERS["Newton"], int(mujoco.mjtJacobian.mjJAC_DENSE)
        w._rescue_steps = 100
        w._advance()
        assert w.hose_stretch().max() < 0.1
        assert w._rescue_steps == left  # the table's ends at once; 0 keeps the whole rescue
        if left == 0:
            assert (m.opt.solver, m.opt.jacobian) == (w._solver, w._jacobian)


def _restore(w, state: np.ndarray) -> None:
    """Put the shared table world back as a test found it: ``state``, with the solver, the
    fallback and rescue counters reset."""
    w.set_state(state)
    w.reset()
    w.set_state(state)


def test_a_hose_sunk_into_the_mat_starts_a_rescue(table_world) -> None:
    """``physics.rescue_depth``: a step that leaves a hose deeper than that in the mat, and
    deeper than a step before by more than ``SINK_SPEED``, is redone by the dense Newton, as
    a stretched edge is (the sparse Newton can let a hose sink
    through the mat while it reports convergence, table rope seed 11326).  A settled scene
    starts none; 0 turns the check off; the board's default is off."""
    import mujoco

    assert table().rescue_depth() == 0.003 and SceneConfig().rescue_depth() == 0.0
    w = table_world
    m, d = w.model, w.data
    state = w.get_state()
    try:
        w.reset()
        w.step(5)
        assert w.solver_rescues == 0 and not w._sinking()  # cables at rest: no rescue
        h = w.hoses[0]
        z_all = w.hose_vertices(0)[:, 2]
        free = np.flatnonzero(np.asarray(h.vertex_bodies) > 0)
        k = int(free[np.argmin(z_all[free])])  # the lowest free vertex: lying on the mat
        body = int(h.vertex_bodies[k])
        joints = range(m.body_jntadr[body], m.body_jntadr[body] + m.body_jntnum[body])
        z = next(j for j in joints if np.allclose(m.jnt_axis[j], (0, 0, 1)))
        w.reset()
        d.qpos[m.jnt_qposadr[z]] -= 0.008  # 8 mm into the mat
        mujoco.mj_forward(m, d)
        assert w._sinking()  # 8 mm deep, from resting on the mat: sinking
        assert not w._sinking()  # as deep as a step before: lying deep is not sinking
        w._rescue_residual = 0.0  # this test is about the depth alone
        for depth, rescues in ((w.cfg.rescue_depth(), 1), (0.0, 0)):
            w.reset()
            w._rescue_depth = depth
            d.qpos[m.jnt_qposadr[z]] -= 0.008
            mujoco.mj_forward(m, d)
            assert w.hose_stretch().max() < w.cfg.physics.rescue_strain  # not stretched
            w.step(1)
            assert w.solver_rescues == rescues
    finally:
        w._rescue_depth = w.cfg.rescue_depth()
        w._rescue_residual = w.cfg.rescue_residual()
        _restore(w, state)


def test_a_step_the_solver_leaves_unsolved_starts_a_rescue(table_world) -> None:
    """``physics.rescue_residual``: a step after which a cable vertex's equation of motion is
    still off by more than that once CG stood in (|M qacc - forces| over its mass; MuJoCo's
    sparse Newton can report convergence with a stretch of thin wire falling through the mat,
    table seed 14139) is redone by the dense Newton, which solves it.  A resting scene is solved far inside the
    threshold; 0 turns the check off; the board's default is off."""
    import mujoco

    assert table().rescue_residual() == 3000.0 and SceneConfig().rescue_residual() == 0.0
    w = table_world
    m, d = w.model, w.data
    state = w.get_state()
    dofs = w._vertex_dofs
    assert len(dofs) > 0 and np.all(m.dof_M0[dofs] > 0)

    def residual() -> float:
        out = np.zeros(m.nv)
        mujoco.mj_mulM(m, d, out, d.qacc)
        r = out[dofs] - d.qfrc_smooth[dofs] - d.qfrc_constraint[dofs]
        return float(np.max(np.abs(r) / m.dof_M0[dofs]))

    plain = w._plain_step
    k = int(dofs[len(dofs) // 2])

    def stopped_short() -> bool:  # the step as built, then the solver's answer made wrong
        plain()
        d.qacc[k] += 1e4
        return False  # not known to be solved: the caller checks it

    try:
        w.reset()
        w.step(5)
        assert w.solver_rescues == 0 and residual() < 30  # at rest: solved
        assert not w._unsolved()
        for threshold, rescues in ((w.cfg.rescue_residual(), 1), (0.0, 0)):
            w.reset()
            w._rescue_residual = threshold
            w._plain_step = stopped_short
            w.step(1)
            assert w.solver_rescues == rescues
            if rescues:  # the dense Newton's step is solved
                assert residual() < 30 and not w._unsolved()
            else:
                assert residual() > 9e3
    finally:
        w._plain_step = plain
        w._rescue_residual = w.cfg.rescue_residual()
        _restore(w, state)


def test_a_newton_step_left_unsolved_is_redone_by_cg(table_world) -> None:
    """A sparse-Newton step that leaves a cable vertex unsolved is redone with CG, which then
    stands in for ``physics.fallback_time`` as after a Newton step that stalls."""
    from cablesim.sim.world import _SOLVERS

    w = table_world
    m = w.model
    state = w.get_state()
    seen: list[int] = []

    def unsolved_once() -> bool:  # the first check (after Newton's step) finds it unsolved
        seen.append(int(m.opt.solver))
        return len(seen) == 1

    try:
        w.reset()
        w._unsolved = unsolved_once
        w.step(1)
        assert seen[0] == _SOLVERS["Newton"] and w._fallbacks == 1
        assert m.opt.solver == _SOLVERS["CG"]
        assert w._fallback_steps == round(w.fallback_time / m.opt.timestep) - 1
    finally:
        del w._unsolved
        _restore(w, state)


def test_slack_to_plugged_ends_is_arc_length_less_the_straight_distance() -> None:
    from cablesim.sim.picker import slack_to_plugged_ends

    straight = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]])
    assert slack_to_plugged_ends(straight, True, 0.07) == pytest.approx([0.0, 0.0], abs=1e-12)
    corner = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0]])
    # 15 cm along: 0.15 m of rod back to the first end, straight distance hypot(0.1, 0.05);
    # the last 5 cm to the far end are straight
    first, last = slack_to_plugged_ends(corner, True, 0.15)
    assert first == pytest.approx(0.15 - math.hypot(0.1, 0.05))
    assert last == pytest.approx(0.0, abs=1e-12)
    assert slack_to_plugged_ends(corner, False, 0.2) == pytest.approx([0.2 - math.hypot(0.1, 0.1)])


def test_the_table_picker_leaves_the_action_amplitude_of_slack_to_each_socket() -> None:
    """Seed 9801's first draw was a grasp 27 cm from the socket on a cable lying straight from
    it (1 mm of slack): the ``along`` pull stretched the cable until it sprang out of the
    fingers.  The picker now turns such a grasp down; the board (hanging hoses) has no rule."""
    from cablesim.sim.picker import _distance_to_polyline, slack_to_plugged_ends
    from cablesim.sim.session import SimSession

    assert TABLE.needs_slack and not BOARD.needs_slack
    cfg = EpisodeConfig(scene=table(9801))
    session = SimSession.build(cfg)
    try:
        picked = session.pick_start()
        verts = session.world.hose_vertices(picked.hose)
        _, arc = _distance_to_polyline(picked.centre_world, verts)
        both = session.world.hoses[picked.hose].spec.both_ends
        assert min(slack_to_plugged_ends(verts, both, arc)) >= cfg.interaction.actions.amplitude
    finally:
        session.close()
