"""Typed, seeded, printable configuration of a simulated scene and of a simulated
interaction in it (:class:`EpisodeConfig`).

Two surfaces hold the cables (``SceneConfig.surface``): ``board``, cables hanging from
couplings on a vertical task board (the thesis's set-up), and ``table``, cables lying and
crossing on a mat on the table top, the first end of each plugged into a socket on the table
(:class:`TableConfig`).  Frame conventions (world, metres): table top at z = 0, x from the
robot towards the board, z up.  The board's front face is the plane x = ``board.x``;
connectors stick out of it towards -x.  Every config is checked when it is made (:class:`cablesim.config.Config`): an impossible
value is a ``ConfigError`` naming the field; configs are frozen (``replace`` and
``with_values`` make checked copies).

The seed lives in one place, ``SceneConfig.seed`` (``EpisodeConfig.scene.seed``,
``ExploreConfig.episode.scene.seed``): it draws the scene and names every random stream of a
run in it (:mod:`cablesim.seeding`); ``EpisodeConfig.seed`` reads it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from cablesim.cables import DEFAULT_KIND, CableKind, cable_kind, check_pattern
from cablesim.config import (
    Config,
    ConfigMigrationWarning,
    check_number,
    check_positive,
    check_range,
    check_vector,
    is_int,
    moved_fields,
)
from cablesim.episode.config import InteractionConfig
from cablesim.errors import ConfigError
from cablesim.panda.description import (
    JOINT_LIMITS,
    PARK_QPOS,
    check_visual,
)

BACKGROUNDS = ("wood", "bushes", "cables", "solid")
MAX_HOSES = 8  # cables one scene holds
#: What holds the cables: a vertical task board, or the table top (SceneConfig.surface).
SURFACES = ("board", "table")
#: Each surface's camera view, (position, look_at), where ``camera.position`` or
#: ``camera.look_at`` is None.  The table's camera hangs above the robot's base and looks down
#: (62 degrees) over the mat, so that the arm's base and its park pose stay out of view.
SURFACE_VIEWS: Mapping[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "board": ((-0.42, 0.0, 0.62), (0.62, 0.0, 0.46)),
    "table": ((0.35, -0.42, 0.60), (0.35, -0.10, 0.0)),
}
#: Each surface's MuJoCo ``impratio`` (the friction-to-normal impedance ratio of the elliptic
#: cones), where ``physics.impratio`` is None.  MuJoCo's soft friction lets a contact slip at a
#: speed that grows with the tangential force it holds, and a higher ratio shrinks that slip.
#: On the board the hoses hang, and 10 holds them still.  On the table a cable plugged at both
#: ends presses its bend sideways on the mat and on the cables it crosses: at 10 it crept at
#: 2-4 mm/s for 20 s and more (seed 11), at 100 at 0.3 mm/s, under ``physics.settle_speed``.
#: But at 100 the stiff friction of cables lying on one another made the interaction blow up:
#: a cable squirted out from under the grasped one or from beside a finger, an edge stretched
#: 20-60 % in one step, and the grasp was lost (seeds 9700-9705 with the rescue release: 1 of
#: 6 interactions held at 100; at 30, 4 of the 4 tried, 9700, 9702, 9704 and 9705; at 30
#: without the release 5 of 6, 9700 and 9702-9706).  30 is the compromise: scenes still
#: settle (29 of 30, seeds 9200-9229, median 2.0 s CPU), and a cable still creeps, slower
#: than the settle threshold (1 mm/s).
SURFACE_IMPRATIO: Mapping[str, float] = {"board": 10.0, "table": 30.0}
#: Each surface's ``physics.rescue_release``, where it is None.  The table's dense-Newton
#: rescue steps are 8x the board's (118-174 ms: about 1 800 degrees of freedom in contact with
#: the mat), and a spike there is gone after a few steps; the board keeps the whole rescue.
SURFACE_RESCUE_RELEASE: Mapping[str, float] = {"board": 0.0, "table": 0.1}

#: Each surface's ``physics.rescue_depth``, where it is None: the table's 3 mm; off on the
#: board, whose hanging hoses rest up to 4.7 mm deep in the table below it under the sparse
#: Newton (board seeds 1 and 3 at their start; not looked into further).
SURFACE_RESCUE_DEPTH: Mapping[str, float] = {"board": 0.0, "table": 0.003}

#: Each surface's ``physics.rescue_residual`` (m/s^2), where it is None: the table's 3000; off
#: on the board (whose pinned runs it would change, and where the failure was not traced).
#: Measured over a whole table thin-wire interaction (seed 14139, 7018 sparse Newton steps):
#: a cable vertex's equation of motion is off by a median 0.04 m/s^2 and by more than 83
#: m/s^2 in 1 % of the steps, most of them the failure itself: up to 6.8e5 m/s^2 while a
#: stretch of wire 16 cm from the grasp fell through the mat and pulled the wire out of the
#: fingers (docs/cables.md, "Table, thin wire").  CG's steps there are off by at most 601
#: m/s^2.  Sent straight to the dense-Newton rescue, at 300 the check fired 348 times (the dense
#: Newton's own steps are off by 150-1400 m/s^2: 8x the CPU), at 3000 twice, but on seed 14600
#: it fired step after step (not ended after 4.5 min of CPU, against 59 s as built); redone with
#: CG first, both seeds held with no rescue at 49 and 46 s of CPU (53 and 59 s as built).
SURFACE_RESCUE_RESIDUAL: Mapping[str, float] = {"board": 0.0, "table": 3000.0}

# Sanity bounds that keep MuJoCo away from degenerate models (the table top is the box
# x in [TABLE_X[0], TABLE_X[1]], |y| <= TABLE_HALF_WIDTH; see cablesim.sim.world).
TABLE_X = (-0.6, 0.9)
TABLE_HALF_WIDTH = 0.85
BOARD_X = (-0.4, 0.9)  # the board's front face stays over the table
HOSE_LENGTH = (0.1, 3.0)  # metres: a hose longer than 3 m does not fit on the table
MAX_HOSE_VERTICES = 300  # per hose (length / segment_length)
WORLD_LIMIT = 10.0  # metres: every configured position lies within +-10 m of the origin
MIN_HOSE_VERTICES = 8


def hose_vertex_count(length: float, segment_length: float) -> int:
    """Vertices of a hose of ``length`` with edges of about ``segment_length`` (at least 8)."""
    return max(MIN_HOSE_VERTICES, int(round(length / segment_length)) + 1)


def min_vertex_spacing(lengths: tuple[float, float], segment_length: float) -> float:
    """The smallest edge length of any hose with a length in ``lengths``: at the shortest
    length, or just above a length where the vertex count steps up."""
    lo, hi = float(lengths[0]), float(lengths[1])
    points = [lo, hi]
    k = max(0, int(lo / segment_length) - 1)
    while (k + 0.5) * segment_length <= hi and len(points) < 2 * MAX_HOSE_VERTICES:
        for x in ((k + 0.5) * segment_length * (1 + e) for e in (-1e-12, 0.0, 1e-12)):
            if lo <= x <= hi:
                points.append(x)
        k += 1
    return min(x / (hose_vertex_count(x, segment_length) - 1) for x in points)


# Default connector layout on the board: (y, z) of each male connector, two rows of five.
DEFAULT_CONNECTORS: tuple[tuple[float, float], ...] = tuple(
    (y, z) for z in (0.86, 0.62) for y in (-0.30, -0.15, 0.0, 0.15, 0.30)
)


@dataclass(frozen=True)
class BoardConfig(Config):
    """The vertical task board with male garden-hose connectors."""

    SECTION = "board"

    x: float = 0.62  # front face of the board
    width: float = 0.9  # along y
    height: float = 1.0  # along z, from the table top
    thickness: float = 0.02
    background: str = "wood"  # one of BACKGROUNDS
    solid_rgb: tuple[float, float, float] = (0.55, 0.55, 0.58)  # used by "solid"
    connectors: tuple[tuple[float, float], ...] = DEFAULT_CONNECTORS
    connector_length: float = 0.06  # how far a male connector sticks out of the board

    def _validate(self) -> None:
        if self.background not in BACKGROUNDS:
            raise ConfigError(
                "board.background",
                f"unknown background {self.background!r}; choose one of {BACKGROUNDS}",
            )
        for name in ("width", "height", "thickness", "connector_length"):
            check_positive(f"board.{name}", getattr(self, name))
        check_number("board.x", self.x, *BOARD_X)
        check_number("board.width", self.width, hi=2 * TABLE_HALF_WIDTH)
        check_number("board.height", self.height, hi=3.0)
        check_number("board.thickness", self.thickness, hi=0.2)
        check_number("board.connector_length", self.connector_length, hi=0.3)
        if len(self.solid_rgb) != 3 or not all(0 <= c <= 1 for c in self.solid_rgb):
            raise ConfigError(
                "board.solid_rgb", f"expected three values in [0, 1], got {self.solid_rgb}"
            )
        if not self.connectors:
            raise ConfigError("board.connectors", "the board needs at least one connector")
        for i, c in enumerate(self.connectors):
            if len(c) != 2:
                raise ConfigError(f"board.connectors[{i}]", f"expected (y, z), got {c!r}")
            y, z = c
            if abs(y) > self.width / 2 or not (0 < z < self.height):
                raise ConfigError(f"board.connectors[{i}]", f"({y}, {z}) is off the board")


# Default sockets on the table: (x, y, yaw) of each, yaw the direction (radians about z) in
# which a plugged cable leaves it; on three sides of the mat's cable region, 5 cm outside it.
DEFAULT_TABLE_CONNECTORS: tuple[tuple[float, float, float], ...] = (
    *((0.60, y, math.pi) for y in (-0.28, -0.12, 0.04)),
    *((x, 0.15, -math.pi / 2) for x in (0.22, 0.36, 0.50)),
    *((0.10, y, 0.0) for y in (-0.25, -0.05)),
)


@dataclass(frozen=True)
class TableConfig(Config):
    """The table-top scene (``SceneConfig.surface = "table"``): a mat on the table, cables
    lying and crossing in ``region`` (x0, x1, y0, y1: where their start shapes wander), the
    first end of each plugged into a socket (``connectors``: x, y and the yaw in which the
    cable leaves), the far end plugged into another with ``hoses.both_ends_probability``,
    else free.  The region's default lies where the Panda reaches the table from above."""

    SECTION = "table"

    region: tuple[float, float, float, float] = (0.15, 0.55, -0.35, 0.10)
    connectors: tuple[tuple[float, float, float], ...] = DEFAULT_TABLE_CONNECTORS
    socket_height: float = 0.02  # m: the plugged cable end's centre above the table
    background: str = "wood"  # the mat's look: one of BACKGROUNDS
    solid_rgb: tuple[float, float, float] = (0.55, 0.55, 0.58)  # used by "solid"
    mat_margin: float = 0.12  # m: the mat reaches this far beyond the region
    # m: the finger pads' collision boxes reach this far past the fingertips, into the mat and
    # the table top that let them in (cablesim.panda.model.reach_pads: a thin wire held on the
    # mat is otherwise pushed out under the fingertips); they look as built.  0: as built
    pad_reach: float = 0.003

    def _validate(self) -> None:
        x0, x1, y0, y1 = check_vector("table.region", self.region, 4)
        if not (x1 - x0 >= 0.1 and y1 - y0 >= 0.1):
            raise ConfigError(
                "table.region", f"(x0, x1, y0, y1) = {self.region}: need x1 - x0 and y1 - y0 >= 0.1"
            )
        if not (TABLE_X[0] <= x0 and x1 <= TABLE_X[1] and -TABLE_HALF_WIDTH <= y0):
            raise ConfigError("table.region", f"{self.region} is not on the table")
        if y1 > TABLE_HALF_WIDTH:
            raise ConfigError("table.region", f"{self.region} is not on the table")
        if self.background not in BACKGROUNDS:
            raise ConfigError(
                "table.background",
                f"unknown background {self.background!r}; choose one of {BACKGROUNDS}",
            )
        for k, v in enumerate(check_vector("table.solid_rgb", self.solid_rgb, 3)):
            check_number(f"table.solid_rgb[{k}]", v, 0.0, 1.0)
        check_number("table.socket_height", self.socket_height, 0.005, 0.1)
        check_number("table.mat_margin", self.mat_margin, 0.0, 0.5)
        check_number("table.pad_reach", self.pad_reach, 0.0, 0.01)
        if not self.connectors:
            raise ConfigError("table.connectors", "the table needs at least one socket")
        for i, c in enumerate(self.connectors):
            x, y, _ = check_vector(f"table.connectors[{i}]", c, 3, 2 * math.pi + 1e-9)
            if not (TABLE_X[0] <= x <= TABLE_X[1] and abs(y) <= TABLE_HALF_WIDTH):
                raise ConfigError(f"table.connectors[{i}]", f"({x}, {y}) is off the table")


@dataclass(frozen=True)
class HoseConfig(Config):
    """The cables of a scene: how many, how long, of which kind (:mod:`cablesim.cables`),
    and any of the kind's parameters overridden.  Each cable's values are drawn from these
    ranges (seeded); :meth:`cable` gives the parameters cable ``i`` is built with."""

    SECTION = "hoses"

    count: int = 4
    length: tuple[float, float] = (0.6, 1.5)
    # the kind of every cable (``cablesim cables`` lists them), or one kind per cable in
    # ``kinds`` (cable i is ``kinds[i % len(kinds)]``; empty: every cable is ``kind``)
    kind: str = DEFAULT_KIND
    kinds: tuple[str, ...] = ()
    # overrides of the kinds' parameters, for every cable; None: the cable's kind's value
    radius: float | None = None  # m (garden hose: 0.0075, 15 mm thick)
    segment_length: float | None = None  # target edge length; vertex count follows
    young: tuple[float, float] | None = None  # Pa, bending/twist stiffness of the rod
    poisson: float | None = None
    mass_per_metre: float | None = None  # kg/m
    damping: float | None = None  # N s/m on each vertex dof (air drag, internal losses)
    inertia_scale: float | None = None  # vertex inertia x this, weight unchanged
    grip_dmax: float | None = None  # the fingers' contact solimp dmax (the largest kind's)
    both_ends_probability: float = 0.75  # else attached at one end and hanging free
    colors: tuple[tuple[float, float, float], ...] | None = None
    color_jitter: float | None = None
    # every cable wears the colour the first one draws (each still jittered by its kind's
    # ``color_jitter``): a tangle of identical cables; the layout is drawn as without it
    same_colour: bool = False
    friction: float | None = None
    # cross-section of the rod: "circle" of ``radius`` (default), or "box" of half-sizes
    # ``section_size`` (a flat ribbon), which MuJoCo draws in the rod's material frame, so its
    # twist shows in the image (the twist check of the ground-truth flow uses one)
    section: str = "circle"
    section_size: tuple[float, float] | None = None  # None: (radius, radius)
    # the surface look (``cablesim cables --patterns``): None is the kind's; ``patterns``
    # gives one per cable (cable i wears ``patterns[i % len(patterns)]``)
    pattern: str | None = None
    patterns: tuple[str, ...] = ()
    pattern_period: float | None = None  # m
    pattern_color: tuple[float, float, float] | None = None  # None: contrast with the cable

    def kind_of(self, i: int) -> str:
        """The kind of cable ``i``."""
        return self.kinds[i % len(self.kinds)] if self.kinds else self.kind

    def used_kinds(self) -> tuple[str, ...]:
        """The kinds of the ``count`` cables, each once, in cable order."""
        return tuple(dict.fromkeys(self.kind_of(i) for i in range(self.count)))

    def max_diameter(self) -> float:
        """The thickest cable's diameter (m): what a gripper closing on any of them needs."""
        return max(2 * self.cable(i).radius for i in range(self.count))

    def finger_contact_dmax(self) -> float:
        """The fingers' contact hardness (MuJoCo solimp dmax) for these cables: the largest
        ``grip_dmax`` of the ``count`` cables' kinds, so a scene that mixes kinds grips each
        as hard as its hardest-gripped kind asks."""
        return max(self.cable(i).grip_dmax for i in range(self.count))

    def cable(self, i: int) -> CableKind:
        """The parameters cable ``i`` is built with: its kind's, with this config's overrides."""
        c = self._resolve(self.kind_of(i))
        if self.patterns:
            c = replace(c, pattern=self.patterns[i % len(self.patterns)])
        return c

    def _resolve(self, name: str) -> CableKind:
        base = cable_kind(name, "hoses.kinds" if self.kinds else "hoses.kind")
        overrides = {f: getattr(self, f) for f in _CABLE_OVERRIDES if getattr(self, f) is not None}
        return replace(base, **overrides) if overrides else base

    def _validate(self) -> None:
        if not isinstance(self.count, int) or not 1 <= self.count <= MAX_HOSES:
            raise ConfigError(
                "hoses.count", f"1 to {MAX_HOSES} hoses are supported, got {self.count!r}"
            )
        check_range("hoses.length", self.length, *HOSE_LENGTH)
        cable_kind(self.kind, "hoses.kind")
        for i, name in enumerate(self.kinds):
            cable_kind(name, f"hoses.kinds[{i}]")
        for name in self.used_kinds():
            self._validate_cable(self._resolve(name))
        for i, name in enumerate(self.patterns):
            check_pattern(name, f"hoses.patterns[{i}]")
        if not 0 <= self.both_ends_probability <= 1:
            raise ConfigError("hoses.both_ends_probability", "must be in [0, 1]")
        if self.section not in ("circle", "box"):
            raise ConfigError("hoses.section", f"must be 'circle' or 'box', got {self.section!r}")
        if self.section == "box" and self.section_size is not None:
            if len(self.section_size) != 2 or min(self.section_size) <= 0:
                raise ConfigError(
                    "hoses.section_size", f"need two positive half-sizes, got {self.section_size}"
                )
            for name in self.used_kinds():
                radius = self._resolve(name).radius
                if abs(min(self.section_size) - radius) > 1e-12:
                    raise ConfigError(
                        "hoses.section_size",
                        f"the smaller half-size {min(self.section_size)} must equal the radius "
                        f"{radius} of the {name} cables (MuJoCo collides a box rod as a capsule "
                        "of that radius)",
                    )

    def _validate_cable(self, c: CableKind) -> None:
        """Check one resolved kind; an overridden value is named by its field, a preset's by
        the kind."""

        def name(f: str) -> str:
            return f"hoses.{f}" if getattr(self, f) is not None else f"hoses.kind {c.name!r}: {f}"

        check_positive(name("radius"), c.radius)
        check_number(name("radius"), c.radius, hi=0.05)
        check_positive(name("segment_length"), c.segment_length)
        if c.segment_length < 2 * c.radius:
            raise ConfigError(
                name("segment_length"),
                f"{c.segment_length} is shorter than the cable diameter {2 * c.radius}",
            )
        n = self.length[1] / c.segment_length
        if n > MAX_HOSE_VERTICES:
            raise ConfigError(
                name("segment_length"),
                f"{c.segment_length} m makes {n:.0f} vertices of a {self.length[1]} m cable "
                f"(at most {MAX_HOSE_VERTICES})",
            )
        spacing = min_vertex_spacing(self.length, c.segment_length)
        if spacing < 2 * c.radius * (1 + 1e-6):  # MuJoCo: spacing > diameter
            raise ConfigError(
                "hoses.length",
                f"a {c.name} of {self.length[0]} to {self.length[1]} m gets vertices "
                f"{spacing:.4g} m apart, not more than its diameter {2 * c.radius:.4g} m (make "
                "the cables longer, the segments longer or the radius smaller)",
            )
        check_range(name("young"), c.young, lo=1e-9, hi=1e12)
        if not 0 <= c.poisson < 0.5:
            raise ConfigError(name("poisson"), f"must be in [0, 0.5), got {c.poisson}")
        check_positive(name("mass_per_metre"), c.mass_per_metre)
        check_positive(name("damping"), c.damping, allow_zero=True)
        check_number(name("inertia_scale"), c.inertia_scale, lo=1.0, hi=100.0)
        if not c.colors:
            raise ConfigError(name("colors"), "need at least one colour")
        for i, rgb in enumerate(c.colors):
            for k, v in enumerate(check_vector(f"{name('colors')}[{i}]", rgb, 3)):
                check_number(f"{name('colors')}[{i}][{k}]", v, 0.0, 1.0)
        check_number(name("color_jitter"), c.color_jitter, 0.0, 1.0)
        check_positive(name("friction"), c.friction, allow_zero=True)
        check_pattern(c.pattern, name("pattern"))
        check_positive(name("pattern_period"), c.pattern_period)
        check_number(name("grip_dmax"), c.grip_dmax, 0.95, 0.9999)
        if c.pattern_period < 2 * c.radius:
            raise ConfigError(
                name("pattern_period"),
                f"{c.pattern_period} m is shorter than the cable diameter {2 * c.radius} m",
            )
        if c.pattern_color is not None:
            for k, v in enumerate(check_vector(name("pattern_color"), c.pattern_color, 3)):
                check_number(f"{name('pattern_color')}[{k}]", v, 0.0, 1.0)


#: The HoseConfig fields that override a kind's parameter of the same name.
_CABLE_OVERRIDES = (
    "radius",
    "segment_length",
    "young",
    "poisson",
    "mass_per_metre",
    "damping",
    "inertia_scale",
    "grip_dmax",
    "colors",
    "color_jitter",
    "friction",
    "pattern",
    "pattern_period",
    "pattern_color",
)


@dataclass(frozen=True)
class RGBSensorConfig(Config):
    """The optional RGB sensor model (``cablesim.sim.sensor.rgb_sensor``): the rendered image
    is taken as the scene radiance; the sensor collects ``full_well * exposure`` electrons at
    white, adds shot (Poisson) and read noise, applies the gain that restores the brightness
    (so a short exposure is a noisier image, not a darker one), blurs the noise as demosaicing
    does, varies the brightness from frame to frame (auto-exposure, mains flicker) and
    quantises to 8 bits."""

    SECTION = "camera.rgb_sensor"

    full_well: float = 4000.0  # electrons at white, nominal exposure
    read_noise: float = 4.0  # electrons (std)
    exposure: float = 1.0  # fraction of the nominal light collected; the gain is 1 / exposure
    frame_gain_jitter: float = 0.01  # std of the per-frame brightness factor
    demosaic_sigma: float = 0.6  # px, Gaussian correlation of the noise (0: independent)

    def _validate(self) -> None:
        check_positive("camera.rgb_sensor.full_well", self.full_well)
        check_positive("camera.rgb_sensor.read_noise", self.read_noise, allow_zero=True)
        check_positive("camera.rgb_sensor.exposure", self.exposure)
        if self.exposure > 1:
            raise ConfigError(
                "camera.rgb_sensor.exposure", f"must be in (0, 1], got {self.exposure}"
            )
        check_positive("camera.rgb_sensor.frame_gain_jitter", self.frame_gain_jitter, True)
        check_positive("camera.rgb_sensor.demosaic_sigma", self.demosaic_sigma, True)


DEPTH_MODELS = ("gaussian", "stereo")


@dataclass(frozen=True)
class StereoDepthConfig(Config):
    """The stereo-like depth model (``cablesim.sim.sensor.stereo_depth``), modelled on an active
    IR stereo camera with block matching (RealSense D4xx): the error lives in disparity
    (sigma_z = z^2 sigma_d / (f b)), it is spatially correlated over the matching window, and at
    depth edges the window's winner spreads the near surface over the far one (fattening) or
    the far one over a thin near object (erosion) by up to ``edge_px`` pixels, in patches
    ``edge_scale_px`` long; some edge pixels return nothing."""

    SECTION = "camera.depth_stereo"

    baseline: float = 0.095  # m, the D456's stereo baseline
    disparity_noise: float = 0.08  # px (std), sub-pixel matching error
    window_px: int = 7  # matching window: the error's correlation length
    edge_px: int = 2  # largest fattening / erosion at a depth edge, pixels
    edge_scale_px: float = 12.0  # px, length of the patches that fatten or erode alike
    fatten_probability: float = 0.6  # share of edge patches where the near surface spreads
    edge_jump: float = 0.005  # m: a neighbourhood spanning more depth than this is an edge
    edge_dropout: float = 0.15  # probability that an edge pixel returns nothing
    quantum: float = 0.001  # m, depth unit

    def _validate(self) -> None:
        check_positive("camera.depth_stereo.baseline", self.baseline)
        check_positive("camera.depth_stereo.disparity_noise", self.disparity_noise, True)
        for name in ("window_px", "edge_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ConfigError(
                    f"camera.depth_stereo.{name}", f"must be an integer >= 0, got {v!r}"
                )
        check_positive("camera.depth_stereo.edge_scale_px", self.edge_scale_px)
        for name in ("fatten_probability", "edge_dropout"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ConfigError(f"camera.depth_stereo.{name}", f"must be in [0, 1], got {v}")
        check_positive("camera.depth_stereo.edge_jump", self.edge_jump)
        check_positive("camera.depth_stereo.quantum", self.quantum, True)


@dataclass(frozen=True)
class CameraConfig(Config):
    """A fixed RGB-D camera modelled on an Intel RealSense D456.

    The D456 colour sensor sees about 90 x 65 degrees at 1280x800 (16:10); its 4:3 modes crop
    the sides.  The default 640x480 is the speed/detail compromise (perception at the thesis's
    ~408x552 scale runs in real time on a CPU); any size up to 1280x720 works: ``fovy`` is kept,
    the horizontal field follows from the aspect ratio.
    """

    SECTION = "camera"

    width: int = 640
    height: int = 480
    fovy: float = 58.0  # degrees, vertical field of view
    # None: the surface's view (SURFACE_VIEWS; SceneConfig.view() resolves it)
    position: tuple[float, float, float] | None = None
    look_at: tuple[float, float, float] | None = None
    position_jitter: float = 0.0  # metres, uniform per axis (randomised camera pose)
    look_at_jitter: float = 0.0
    depth_noise: bool = False
    depth_noise_std_per_m2: float = 0.0015  # RealSense-like: sigma = k * z^2 ("gaussian")
    near: float = 0.05
    far: float = 5.0
    # stacks of the rendered spheres and capsule caps (MuJoCo's default is 16).  A hose is
    # drawn as one capsule per edge whose caps hide inside the neighbouring edges, so 8 stacks
    # cost 25% less rendering and change only a few pixels at hose ends: 21 of 307,200 (at
    # most one grey level, no label) on the seed-2 start image; with the arm in view also
    # ~1,400 pixels on its capsule ends.  16 renders exactly as MuJoCo's default.
    sphere_stacks: int = 8
    # the depth noise model: "gaussian" (per pixel, sigma = k z^2, quantised, edge dropout)
    # or "stereo" (correlated disparity error, edges fattened or eroded: ``depth_stereo``)
    depth_model: str = "gaussian"
    depth_stereo: StereoDepthConfig = field(default_factory=StereoDepthConfig)
    rgb_noise: bool = False  # the RGB sensor model (``rgb_sensor``); off: the rendered image
    rgb_sensor: RGBSensorConfig = field(default_factory=RGBSensorConfig)

    @classmethod
    def thesis(cls, **changes: object) -> CameraConfig:
        """The thesis's image geometry: the D456 colour stream at 1280x720 (about 89 x 58
        degrees), where a 15 mm hose at 1 m is about 9-10 px wide (SPEC section 8)."""
        return cls(**{"width": 1280, "height": 720, "fovy": 58.0, **changes})  # type: ignore[arg-type]

    @classmethod
    def realistic(cls, **changes: object) -> CameraConfig:
        """Both noise models on (RGB sensor noise, stereo-like depth), as SPEC section 7 asks
        of every result with estimated flow."""
        return cls(**{"rgb_noise": True, "depth_noise": True, "depth_model": "stereo", **changes})  # type: ignore[arg-type]

    def _validate(self) -> None:
        if not (16 <= self.width <= 1280 and 16 <= self.height <= 720):
            raise ConfigError(
                "camera.width/height",
                f"size must be within 16x16 .. 1280x720, got {self.width}x{self.height}",
            )
        if not 10 <= self.fovy <= 120:
            raise ConfigError("camera.fovy", f"must be within 10..120 degrees, got {self.fovy}")
        check_positive("camera.position_jitter", self.position_jitter, allow_zero=True)
        check_positive("camera.look_at_jitter", self.look_at_jitter, allow_zero=True)
        check_positive("camera.depth_noise_std_per_m2", self.depth_noise_std_per_m2, True)
        if self.depth_model not in DEPTH_MODELS:
            raise ConfigError(
                "camera.depth_model", f"unknown {self.depth_model!r}; choose one of {DEPTH_MODELS}"
            )
        for name in ("depth_noise", "rgb_noise"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(
                    f"camera.{name}", f"must be true or false, got {getattr(self, name)!r}"
                )
        if not 0 < self.near < self.far:
            raise ConfigError("camera.near", "need 0 < near < far")
        if self.position is not None:
            check_vector("camera.position", self.position, 3, WORLD_LIMIT)
        if self.look_at is not None:
            check_vector("camera.look_at", self.look_at, 3, WORLD_LIMIT)
        check_number("camera.position_jitter", self.position_jitter, hi=1.0)
        check_number("camera.look_at_jitter", self.look_at_jitter, hi=1.0)
        # the view itself (the two points apart, not straight down) is checked by the scene,
        # which knows the surface whose view stands in for None (SceneConfig.view)

        if (
            isinstance(self.sphere_stacks, bool)
            or not isinstance(self.sphere_stacks, int)
            or not 2 <= self.sphere_stacks <= 64
        ):
            raise ConfigError(
                "camera.sphere_stacks", f"must be an integer in 2..64, got {self.sphere_stacks!r}"
            )


def check_view(field: str, position: tuple[float, ...], look_at: tuple[float, ...], jitter=0.0):
    """A camera at ``position`` looking at ``look_at`` (each moved by up to ``jitter`` per
    axis) has a view direction: the two points are apart and not one above the other (the
    image's x axis is the view direction crossed with world z)."""
    d = [b - a for a, b in zip(position, look_at, strict=True)]
    norm = math.sqrt(sum(x * x for x in d))
    margin = 2 * math.sqrt(3) * jitter
    if not norm > max(margin, 1e-3):
        raise ConfigError(
            field,
            f"{tuple(look_at)} is (within the jitter) the camera position {tuple(position)}",
        )
    horizontal = math.hypot(d[0], d[1])
    if not horizontal > margin + 1e-3 * norm:
        raise ConfigError(
            field,
            f"the camera looks straight up or down from {tuple(position)} to {tuple(look_at)} "
            "(the image has no x axis)",
        )


@dataclass(frozen=True)
class RobotConfig(Config):
    """The simulated Panda: where it stands on the table (its base must stay out of the
    camera's view), where it waits and how it is drawn (how hard its fingers' contacts are is
    the cables' ``hoses.grip_dmax``)."""

    SECTION = "robot"

    enabled: bool = True
    base_position: tuple[float, float, float] = (0.22, -0.62, 0.0)
    base_yaw: float = 1.1  # radians about z; 0 faces +x
    # where the arm waits: away from the hoses and out of the default camera's view (the scene
    # starts and settles with the arm here; ``SimPanda`` retreats here before a target frame)
    park_qpos: tuple[float, ...] = PARK_QPOS
    # a ChArUco board (cablesim.calibration.BoardSpec's default, at its nominal mount) welded
    # to the hand, visual only: the simulated set-up of ``cablesim calibrate``
    hand_board: bool = False
    # how the arm is drawn: "primitive" (the capsules and boxes it collides with) or "mesh"
    # (franka_ros's visual meshes); it collides through the primitives either way, so the
    # physics is the same bit for bit (cablesim.panda.visuals).  The meshed shoulder is wider:
    # at this base position it shows at the right edge of the default camera in every park
    # pose, so "mesh" adds a static robot strip to every frame (~950 px at 640x480)
    visual: str = "primitive"

    def _validate(self) -> None:
        if len(self.base_position) != 3:
            raise ConfigError("robot.base_position", "expected (x, y, z)")
        check_vector("robot.base_position", self.base_position, 3, WORLD_LIMIT)
        if len(self.park_qpos) != 7:
            raise ConfigError("robot.park_qpos", f"expected 7 joint angles, got {self.park_qpos}")
        for i, (q, (lo, hi)) in enumerate(zip(self.park_qpos, JOINT_LIMITS, strict=True)):
            check_number(f"robot.park_qpos[{i}]", q, float(lo), float(hi))
        if not isinstance(self.hand_board, bool):
            raise ConfigError("robot.hand_board", f"must be true or false, got {self.hand_board!r}")
        if self.hand_board and not self.enabled:
            raise ConfigError("robot.hand_board", "a board in the hand needs the robot (enabled)")
        check_visual(self.visual, "robot.visual")


@dataclass(frozen=True)
class LightConfig(Config):
    """Lighting: the camera's headlight and a directional key light.  ``jitter`` > 0 draws,
    from the seed's ``lighting`` stream, a brightness factor in [1 - jitter, 1 + jitter] for
    each light and turns the key light by up to ``jitter`` radians (randomised datasets); 0
    keeps the fixed lighting."""

    SECTION = "light"

    ambient: float = 0.35  # headlight
    diffuse: float = 0.35  # headlight
    key: float = 0.55  # directional key light (diffuse)
    jitter: float = 0.0

    def _validate(self) -> None:
        for name in ("ambient", "diffuse", "key"):
            check_positive(f"light.{name}", getattr(self, name), allow_zero=True)
        check_positive("light.jitter", self.jitter, allow_zero=True)
        if self.jitter >= 1:
            raise ConfigError("light.jitter", f"must be < 1, got {self.jitter}")


SOLVERS = ("Newton", "CG")


@dataclass(frozen=True)
class PhysicsConfig(Config):
    """MuJoCo options of the scene.

    ``solver``: Newton converges in one or two iterations per step in most states of this
    scene, but MuJoCo 4.0's Newton stalls at its iteration limit in some hose-on-hose contact
    states (then the hoses jitter and never settle: measured up to 170 mm/s after 6 s).  With
    ``fallback_time`` > 0 such a step is redone with CG, which converges there, and CG goes on
    for ``fallback_time`` seconds of simulated time before Newton resumes; 0 keeps Newton's
    unconverged steps.  ``solver`` CG uses CG throughout (robust against the stall, but 2x the
    cost per step and unstable in other states).
    """

    SECTION = "physics"

    timestep: float = 0.004
    solver: str = "Newton"  # one of SOLVERS
    fallback_time: float = 1.0  # s of CG after a Newton step that did not converge
    # the same once the scene has settled (every step outside ``settle_world``: the
    # interaction's); None: ``fallback_time``.  In the actions a grasped, taut hose stalls
    # Newton again and again: 0.25 s of CG instead of 1 s lets Newton, a few times cheaper per
    # step where it converges, back sooner (issue 21: 0.4-1 s of CPU less per default
    # interaction; 0.1 s stalls it more often and saves no more).  The settle keeps
    # ``fallback_time``: the settled states and their cache keys do not depend on this.  A
    # file written before the field existed reruns with None (``_migrate``).
    run_fallback_time: float | None = 0.25
    settle_speed: float = 0.001  # m/s: settled when every hose vertex is slower than this
    settle_max_time: float = 20.0  # simulated seconds before giving up
    settle_check_every: float = 0.1
    gravity: float = -9.81
    cache: bool = True  # cache the settled state per config (see cablesim.sim.settle)
    # a hose edge stretched by more than this share of its rest length means the physics blew
    # up (PhysicsDivergedError).  Measured: at most 1.3 % while a scene settles, up to 16 %
    # next to the gripper when an action pulls a taut hose (seeds 6003, 6004); a blow-up
    # (test seed 702 with perturbed neighbours) went 1 % -> 55 % -> 100 % in 8 steps and tore
    # the hoses apart, with no NaN and no MuJoCo warning
    max_hose_strain: float = 0.5
    # a step that leaves a hose edge stretched by more than this is redone, and the next
    # ``rescue_time`` s are stepped, by Newton on a dense Jacobian (World._advance): in the
    # taut-hose states that tore hoses (seeds 6015, 6032, 6064, 6079) CG at its iteration cap
    # and the sparse Newton stop short of the solution and the stretch runs away; the dense
    # Newton converges there in a few iterations, at 16 ms per step instead of ~2.  0 turns
    # it off.  Must lie between the largest stretch of normal pulling (~16 %) and
    # ``max_hose_strain``.
    rescue_strain: float = 0.2
    rescue_time: float = 0.5
    # > 0: a rescue ends before ``rescue_time`` once a dense step leaves every hose edge
    # stretched by less than this (the spike is gone); 0 runs every rescue for the whole
    # ``rescue_time``; None: the surface's (:data:`SURFACE_RESCUE_RELEASE`, resolved by
    # ``SceneConfig.rescue_release()``).  Must lie below ``rescue_strain``.
    rescue_release: float | None = None
    # m: a step that leaves a hose sunk deeper than this into the board, the table or its
    # mat, and deeper than a step before by more than ``world.SINK_SPEED`` (0.1 m/s), starts a
    # rescue as a stretched edge does (and a rescue ends early only once nothing is sinking);
    # a cable that lies deep and stays there is left alone (a plugged rope end rests 3.2 mm
    # deep beside its socket, table rope seed 11420).  0 turns it off; None: the surface's
    # (:data:`SURFACE_RESCUE_DEPTH`, ``SceneConfig.rescue_depth()``: the table's 3 mm, off on
    # the board).  The sparse Newton can fail on a cable lying on the table while it reports
    # convergence in one or two iterations: a few vertices accelerate through the mat, and an
    # edge stretches past ``rescue_strain`` only once they are 18 mm deep (table rope seed
    # 11326, then torn), or the cable ends up inside the table unnoticed (table hose seed
    # 11301).  Over whole interactions on the table (Intel, seed 11301 of each kind) the thin
    # wire lay at most 2.1 mm deep, the rope and the electrical cable passed 3 mm for 6-7 steps
    # (to 9.9 and 4.9 mm) and the hose went through the table (docs/cables.md, "Cables sinking
    # into the table")
    rescue_depth: float | None = None
    # m/s^2: a sparse-Newton step after which a cable vertex's equation of motion is off by
    # more than this (|M qacc - forces| over the vertex's mass: MuJoCo 4.0's sparse Newton
    # can report convergence in one to three iterations and leave a vertex accelerating
    # through the mat with its contact forces unbalanced) is redone with CG, which stands in
    # for ``fallback_time`` as after a Newton stall; a step CG leaves that far off starts a
    # rescue as a stretched edge does.  0 turns it off; None: the surface's
    # (:data:`SURFACE_RESCUE_RESIDUAL`, resolved by ``SceneConfig.rescue_residual()``: the
    # table's 3000, off on the board).
    rescue_residual: float | None = None
    # MuJoCo's sleeping islands: > 0 turns them on with this velocity tolerance (m/s on the
    # hoses' vertex joints, rad/s on hinges).  An island (bodies joined by constraints:
    # a hose's edges, contacts, its end couplings) whose every degree of freedom stays
    # slower than this for 10 steps is put to sleep: its velocity is set to zero and it costs
    # no collision or constraint solving until something awake touches it, or a force is
    # applied to it (the neighbour perturbation).  0 (the default) keeps everything awake.
    sleep_tolerance: float = 0.0
    # > 0: the same sleeping islands, with this tolerance, only while the simulated arm is in
    # transit holding nothing (``Robot.transit``: the approach to a grasp or push and the
    # retreat; :meth:`~cablesim.sim.world.World.transit`): the hoses the hand does not touch
    # rest there and cost no collision or constraint solving; the hand, a hose it moves or a
    # force touching one wakes it, and every hose wakes at the first step after each motion
    # (the grasp, the hold check, the actions and the waits run with everything awake).
    # Issue 21: 1-1.7 s of CPU less per default interaction.  0 keeps everything awake
    # throughout; a file written before the field existed reruns with 0 (``_migrate``).
    # Ignored while ``sleep_tolerance`` > 0 (sleep on throughout).  The settle does not move
    # the arm: the settled state and its cache key do not depend on it.
    transit_sleep: float = 1e-3
    # MuJoCo's impratio for the elliptic friction cones; None: the surface's
    # (:data:`SURFACE_IMPRATIO`; ``SceneConfig.impratio()`` resolves it)
    impratio: float | None = None

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """A file without ``transit_sleep`` was written while every hose stayed awake through
        the arm's motions (before issue 21's transit sleep): it reruns as it ran, with 0; one
        without ``run_fallback_time`` while every step fell back to CG for
        ``fallback_time``: it reruns with None."""
        data.setdefault("transit_sleep", 0.0)
        data.setdefault("run_fallback_time", None)
        return data

    def _validate(self) -> None:
        if not 0 < self.timestep <= 0.016:
            raise ConfigError("physics.timestep", f"must be in (0, 0.016] s, got {self.timestep}")
        if self.solver not in SOLVERS:
            raise ConfigError("physics.solver", f"must be one of {SOLVERS}, got {self.solver!r}")
        check_positive("physics.fallback_time", self.fallback_time, allow_zero=True)
        if self.run_fallback_time is not None:
            check_positive("physics.run_fallback_time", self.run_fallback_time, allow_zero=True)
            check_number("physics.run_fallback_time", self.run_fallback_time, hi=60.0)
        check_positive("physics.settle_speed", self.settle_speed)
        check_positive("physics.settle_max_time", self.settle_max_time)
        check_positive("physics.settle_check_every", self.settle_check_every)
        check_number("physics.settle_max_time", self.settle_max_time, hi=600.0)
        check_number("physics.gravity", self.gravity, -100.0, 100.0)
        check_number("physics.max_hose_strain", self.max_hose_strain, 1e-4, 10.0)
        check_positive("physics.rescue_strain", self.rescue_strain, allow_zero=True)
        if self.rescue_release is not None:
            check_positive("physics.rescue_release", self.rescue_release, allow_zero=True)
        check_positive("physics.rescue_time", self.rescue_time)
        if self.rescue_depth is not None:
            check_number("physics.rescue_depth", self.rescue_depth, 0.0, 0.05)
        if self.rescue_residual is not None:
            check_number("physics.rescue_residual", self.rescue_residual, 0.0, 1e9)
        check_positive("physics.sleep_tolerance", self.sleep_tolerance, allow_zero=True)
        check_number("physics.sleep_tolerance", self.sleep_tolerance, hi=1.0)
        check_positive("physics.transit_sleep", self.transit_sleep, allow_zero=True)
        check_number("physics.transit_sleep", self.transit_sleep, hi=1.0)
        if self.impratio is not None:
            check_number("physics.impratio", self.impratio, 1.0, 1000.0)
        if self.rescue_strain >= self.max_hose_strain:
            raise ConfigError(
                "physics.rescue_strain",
                f"must be below physics.max_hose_strain ({self.max_hose_strain:g}), "
                f"got {self.rescue_strain}",
            )


@dataclass(frozen=True)
class SceneConfig(Config):
    """Everything that defines a scene; ``seed`` draws the random parts (and, in a simulated
    run, names every random stream of the run: it is the run's one seed).

    ``draw`` numbers the layout drawn from the seed: 0 is the seed's own (stream ``hoses``),
    k > 0 the k-th re-draw (child k of stream ``scene_resample``), which the simulated session
    makes when a draw does not settle or shows no graspable segment (:mod:`cablesim.sim.session`).
    The camera pose is the seed's in every draw."""

    seed: int = 0
    draw: int = 0
    surface: str = "board"  # what holds the cables: one of SURFACES
    board: BoardConfig = field(default_factory=BoardConfig)
    table: TableConfig = field(default_factory=TableConfig)
    hoses: HoseConfig = field(default_factory=HoseConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    light: LightConfig = field(default_factory=LightConfig)

    MOVED = {"robot.finger_contact_dmax": "hoses.grip_dmax"}  # where ``--set`` finds it

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """Earlier layout (2026-12-05): the fingers' contact hardness was the robot's
        ``robot.finger_contact_dmax``; it is the cable kinds' ``hoses.grip_dmax`` now (an
        override for every kind, so the old run's value grips every cable as it did)."""
        robot = data.get("robot")
        if not isinstance(robot, dict) or "finger_contact_dmax" not in robot:
            return data
        robot = dict(robot)
        value = robot.pop("finger_contact_dmax")
        hoses = data.get("hoses", {})
        if not isinstance(hoses, dict):
            raise ConfigError(f"{path}hoses", f"expected a mapping, got {hoses!r}")
        hoses = dict(hoses)
        old, new = f"{path}robot.finger_contact_dmax", f"{path}hoses.grip_dmax"
        if hoses.get("grip_dmax") not in (None, value):
            raise ConfigError(
                old,
                f"moved to {new}, and the file gives both ({value!r} and "
                f"{hoses['grip_dmax']!r}): keep one of them",
            )
        hoses["grip_dmax"] = value
        warnings.warn(ConfigMigrationWarning(f"{old} moved to {new} ({value!r})"), stacklevel=3)
        return {**data, "robot": robot, "hoses": hoses}

    def _validate(self) -> None:
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError("seed", f"must be a non-negative integer, got {self.seed!r}")
        if isinstance(self.draw, bool) or not isinstance(self.draw, int) or self.draw < 0:
            raise ConfigError("draw", f"must be a non-negative integer, got {self.draw!r}")
        if self.surface not in SURFACES:
            raise ConfigError(
                "surface", f"unknown surface {self.surface!r}; choose one of {SURFACES}"
            )
        if self.hoses.count > self.connector_count():
            raise ConfigError(
                "hoses.count",
                f"{self.hoses.count} hoses need at least {self.hoses.count} connectors, "
                f"the {self.surface} has {self.connector_count()}",
            )
        c = self.camera
        check_view("camera.look_at", *self.view(), c.position_jitter + c.look_at_jitter)
        if self.surface == "table" and self.hoses.max_diameter() / 2 > self.table.socket_height:
            raise ConfigError(
                "table.socket_height",
                f"{self.table.socket_height} m is below the radius of the thickest cable "
                f"({self.hoses.max_diameter() / 2:g} m)",
            )
        release, p = self.rescue_release(), self.physics
        if release > 0 and p.rescue_strain > 0 and not release < p.rescue_strain:
            raise ConfigError(
                "physics.rescue_release",
                f"{release:g} (the {self.surface}'s where null) must be below "
                f"physics.rescue_strain ({p.rescue_strain:g})",
            )

    def view(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The camera's (position, look_at) before any jitter: ``camera.position`` and
        ``camera.look_at``, each the surface's (:data:`SURFACE_VIEWS`) where None."""
        position, look_at = SURFACE_VIEWS[self.surface]
        c = self.camera
        return (
            position if c.position is None else tuple(c.position),  # type: ignore[return-value]
            look_at if c.look_at is None else tuple(c.look_at),  # type: ignore[return-value]
        )

    def impratio(self) -> float:
        """MuJoCo's impratio: ``physics.impratio``, or the surface's where None."""
        p = self.physics.impratio
        return SURFACE_IMPRATIO[self.surface] if p is None else float(p)

    def rescue_depth(self) -> float:
        """``physics.rescue_depth``, or the surface's where None."""
        r = self.physics.rescue_depth
        return SURFACE_RESCUE_DEPTH[self.surface] if r is None else float(r)

    def rescue_residual(self) -> float:
        """``physics.rescue_residual``, or the surface's where None."""
        r = self.physics.rescue_residual
        return SURFACE_RESCUE_RESIDUAL[self.surface] if r is None else float(r)

    def rescue_release(self) -> float:
        """``physics.rescue_release``, or the surface's where None."""
        r = self.physics.rescue_release
        return SURFACE_RESCUE_RELEASE[self.surface] if r is None else float(r)

    def connector_count(self) -> int:
        """How many connectors (board) or sockets (table) the surface has."""
        return len(self.board.connectors if self.surface == "board" else self.table.connectors)


@dataclass(frozen=True)
class PerturbConfig(Config):
    """Seeded disturbance of the hoses other than the hose of interest, during actions only
    (:class:`cablesim.sim.perturb.NeighbourPerturbation`)."""

    SECTION = "perturb"

    enabled: bool = False
    hoses: tuple[int, ...] | None = None  # None: every hose but the hose of interest
    points: int = 2  # vertex bodies pulled per hose
    span: tuple[float, float] = (0.3, 0.7)  # where along the hose (fraction of its vertices)
    amplitude: tuple[float, float] = (0.01, 0.03)  # m, drawn per action and hose
    period: tuple[float, float] = (2.5, 4.0)  # s: slower than a 1 m hose swings (~1.6 s)
    stiffness: float = 120.0  # N/m
    damping: float = 3.0  # N s/m; per vertex at most its mass / timestep (perturb.stable_damping)
    max_force: float = 2.0  # N per vertex

    def __post_init__(self) -> None:
        # from JSON: lists; anything that is not a sequence of numbers is named by the checks
        if isinstance(self.hoses, list | tuple):
            hoses = tuple(int(h) if is_int(h) else h for h in self.hoses)
            object.__setattr__(self, "hoses", hoses)
        for name in ("span", "amplitude", "period"):
            value = getattr(self, name)
            if not isinstance(value, tuple | str):
                try:
                    object.__setattr__(self, name, tuple(value))
                except TypeError:
                    pass
        super().__post_init__()

    def _validate(self) -> None:
        if not isinstance(self.points, int) or self.points < 1:
            raise ConfigError("perturb.points", f"must be an integer >= 1, got {self.points!r}")
        check_range("perturb.span", self.span, 0.0, 1.0)
        check_range("perturb.amplitude", self.amplitude, 0.0)
        check_range("perturb.period", self.period, 1e-3)
        for name in ("stiffness", "max_force"):
            check_positive(f"perturb.{name}", getattr(self, name))
        check_positive("perturb.damping", self.damping, allow_zero=True)


#: Shortcuts of the simulated run's configs: name -> the dotted path below an EpisodeConfig
#: (the command-line flags ``--seed``, ``--width``, ... write the same paths).
EPISODE_SHORTCUTS: Mapping[str, str] = {
    "seed": "scene.seed",
    "draw": "scene.draw",
    "hoses": "scene.hoses.count",
    "surface": "scene.surface",
    "width": "scene.camera.width",
    "height": "scene.camera.height",
    "robot_visual": "scene.robot.visual",
    "periods": "interaction.actions.periods",
    "truth_every": "interaction.capture.truth_every",
}


@dataclass(frozen=True)
class EpisodeConfig(Config):
    """A simulated interaction: the scene (whose ``seed`` is the run's one seed: the scene and
    the ``episode``, ``perturb`` and ``grasp_retry`` streams of :mod:`cablesim.seeding`), the
    hose of interest, the interaction and the optional perturbation of the other hoses.

    ``EpisodeConfig.of(seed=3, width=160, height=120)`` sets nested fields by their shortcuts
    (:data:`EPISODE_SHORTCUTS`); ``cfg.seed`` reads ``cfg.scene.seed``."""

    SHORTCUTS = EPISODE_SHORTCUTS
    MOVED = {
        "seed": "scene.seed",
        "scene.robot.finger_contact_dmax": "scene.hoses.grip_dmax",
    }

    hose: int | None = None  # None: drawn from the seed's ``episode`` stream
    scene: SceneConfig = field(default_factory=SceneConfig)
    interaction: InteractionConfig = field(default_factory=InteractionConfig)
    perturb: PerturbConfig = field(default_factory=PerturbConfig)
    # a drawn hose of interest must cross another hose in the image (the thesis's clutter)
    clutter: bool = True
    # scene draws tried (see cablesim.sim.session) before a named failure
    max_draws: int = 8

    @property
    def seed(self) -> int:
        """The run's seed: ``scene.seed``."""
        return self.scene.seed

    def _validate(self) -> None:
        if isinstance(self.max_draws, bool) or not isinstance(self.max_draws, int):
            raise ConfigError("max_draws", f"must be an integer >= 1, got {self.max_draws!r}")
        if self.max_draws < 1:
            raise ConfigError("max_draws", f"must be an integer >= 1, got {self.max_draws!r}")
        if self.scene.surface == "table" and self.interaction.kind == "push":
            raise ConfigError(
                "interaction.kind",
                "push presses the closed hand along the approach, into the board; on the table "
                "that is into the table top: use grasp (the default) there",
            )
        if self.hose is not None and (
            isinstance(self.hose, bool)
            or not isinstance(self.hose, int)
            or not 0 <= self.hose < self.scene.hoses.count
        ):
            raise ConfigError("hose", f"{self.hose} is not one of {self.scene.hoses.count} hoses")

    @classmethod
    def _migrate(cls, data: dict[str, Any], path: str) -> dict[str, Any]:
        """Earlier layout: ``seed`` beside ``scene`` (the run's seed: the scene's own
        ``scene.seed`` was replaced by it) and ``progress`` (now an argument of
        ``simulate_episode`` and the commands' ``--quiet``)."""
        return moved_fields(
            data,
            path,
            {"seed": "scene.seed"},
            old_layout=True,
            dropped={
                "progress": "print progress with the command (no --quiet) or "
                "simulate_episode(progress=True)"
            },
        )
