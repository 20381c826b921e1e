"""The catalogue of cable kinds: named presets of a simulated cable's physical and visual
parameters, with where the numbers come from.

    from cablesim.cables import CABLE_KINDS, cable_kind
    cable_kind("rope").radius              # 0.005
    SceneConfig(hoses=HoseConfig(kind="thin_wire"))          # every cable a thin wire
    HoseConfig(kinds=("rope", "garden_hose", "thin_wire"))   # one kind per cable

A kind fixes what a cable *is* (radius, bending stiffness as the rod's Young's modulus,
mass per metre, damping, friction, colours); the scene (:class:`~cablesim.sim.config.
HoseConfig`) fixes how many cables hang where and how long they are.  Every parameter of a
kind can still be overridden in the config (``hoses.radius`` and so on, None meaning "the
kind's value"); :meth:`HoseConfig.cable <cablesim.sim.config.HoseConfig.cable>` gives the
parameters a cable is built with.

The simulated cable is a MuJoCo 1D flex rod of circular section: its bending stiffness is
``E I`` with ``I = pi r^4 / 4`` and its torsional stiffness ``G J`` with ``G = E / (2 (1 +
nu))`` and ``J = pi r^4 / 2``.  A kind's ``young`` is therefore the *effective* modulus that
gives the measured bending stiffness of the whole cable at its outer radius
(``E = EI / (pi r^4 / 4)``), not the modulus of any one of its materials.
``docs/cables.md`` has the derivation of each number and its sources.  Plain data (no MuJoCo).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cablesim.errors import ConfigError
from cablesim.panda.description import FINGER_CONTACT_DMAX

RGB = tuple[float, float, float]


@dataclass(frozen=True)
class CableKind:
    """One kind of cable: every value a cable of this kind is built with."""

    name: str
    summary: str  # one line: what it is
    radius: float  # m, outer radius
    segment_length: float  # m, target rod edge length (the vertex spacing)
    young: tuple[float, float]  # Pa, effective modulus range (log-uniform per cable)
    poisson: float
    mass_per_metre: float  # kg/m
    damping: float  # N s/m on each vertex dof
    friction: float  # sliding friction coefficient
    colors: tuple[RGB, ...]  # palette; each cable draws one, jittered by ``color_jitter``
    color_jitter: float
    sources: str  # where the numbers come from (docs/cables.md has the details)
    # the surface's look (``PATTERNS``): drawn on the cable in its material frame, so it
    # moves, bends and twists with the cable and the ground-truth flow carries it exactly
    pattern: str = "solid"
    pattern_period: float = 0.03  # m: stripe spacing, marking repeat, strand lay length
    pattern_color: RGB | None = None  # None: the pattern's own contrast with the cable colour
    # each vertex's inertia times this, its weight unchanged (mass x s, gravity compensation
    # 1 - 1/s, damping x s): a soft contact gives way in proportion to force over mass, so the
    # fingers or a crossing cable press a light vertex through the table's mat; 1: as built
    # (mass scaling, as in explicit finite elements; no kind uses it: docs/cables.md)
    inertia_scale: float = 1.0
    # MuJoCo's solimp dmax of the fingers' contacts (pads and finger bodies; theirs win over
    # the cable's own) in a scene with this kind, the largest of the scene's kinds: a contact
    # gives way under force by about (1 - dmax) times force over the pressed mass, so a light
    # vertex sinks into a soft pad and creeps out under it (docs/cables.md, "Table, rope")
    grip_dmax: float = FINGER_CONTACT_DMAX

    def bending_stiffness(self) -> tuple[float, float]:
        """EI range (N m^2) the ``young`` range gives at ``radius``."""
        inertia = math.pi * self.radius**4 / 4
        return self.young[0] * inertia, self.young[1] * inertia

    def line(self) -> str:
        """One line: the name, then the parameters (``cablesim cables``)."""
        ei = self.bending_stiffness()
        return (
            f"{self.name:<17} diameter {2e3 * self.radius:.1f} mm  "
            f"EI {ei[0]:.2g}-{ei[1]:.2g} N m^2  (E {self.young[0]:.3g}-{self.young[1]:.3g} Pa)  "
            f"{1e3 * self.mass_per_metre:.0f} g/m  friction {self.friction:g}  "
            f"damping {self.damping:g} N s/m  segment {1e3 * self.segment_length:.0f} mm  "
            f"{self.pattern}  {len(self.colors)} colours"
            + (f"  inertia x{self.inertia_scale:g}" if self.inertia_scale != 1 else "")
            + (f"  grip dmax {self.grip_dmax:g}" if self.grip_dmax != FINGER_CONTACT_DMAX else "")
            + f": {self.summary}"
        )


def _grey(v: float) -> RGB:
    return (v, v, v)


#: The surface patterns a cable can wear (``CableKind.pattern``, ``hoses.pattern``), each
#: drawn by :mod:`cablesim.sim.patterns` in the cable's material frame.
PATTERNS: dict[str, str] = {
    "solid": "one colour (the hard case for flow: nothing to track along the cable)",
    "stripes": "rings of the pattern colour across the cable, one per period (a third wide)",
    "marking": "a printed dash along one side, 0.6 of a period long, once per period",
    "twisted": "three helical strand grooves, one lay length per period (a laid rope)",
    "braided": "two strands each way, crossing helices (a braided sleeve or rope)",
}


def check_pattern(name: str, field: str) -> str:
    """``name`` if it is a pattern; a ConfigError naming ``field`` and the choices otherwise."""
    if name not in PATTERNS:
        raise ConfigError(field, f"unknown pattern {name!r} (one of: {', '.join(PATTERNS)})")
    return name


def pattern_color(pattern: str, rgb: RGB, override: RGB | None = None) -> RGB:
    """The colour ``pattern`` is drawn in on a cable of colour ``rgb``: ``override`` if given;
    a darker shade of the cable's colour for strands (the shadow between them); otherwise a
    contrasting one (dark on a light cable, light on a dark one), like print on a sheath."""
    if override is not None:
        return override
    r, g, b = rgb
    if pattern in ("twisted", "braided"):
        return (0.45 * r, 0.45 * g, 0.45 * b)
    if 0.3 * r + 0.59 * g + 0.11 * b > 0.45:
        return (0.25 * r, 0.25 * g, 0.25 * b)
    return (0.75 + 0.25 * r, 0.75 + 0.25 * g, 0.75 + 0.25 * b)


GARDEN_HOSE = CableKind(
    name="garden_hose",
    summary="15 mm PVC garden hose (the thesis's robot experiments: 15.4 mm hoses on a board)",
    radius=0.0075,
    segment_length=0.03,
    young=(2e6, 8e6),
    poisson=0.3,
    mass_per_metre=0.15,
    damping=0.02,
    friction=0.9,
    colors=(
        (0.85, 0.20, 0.15),
        (0.15, 0.55, 0.20),
        (0.15, 0.35, 0.80),
        (0.95, 0.75, 0.10),
        (0.10, 0.10, 0.10),
        (0.90, 0.45, 0.10),
        (0.55, 0.20, 0.65),
        (0.85, 0.85, 0.85),
    ),
    color_jitter=0.06,
    sources="cablesim's default hose (SPEC section 9; thesis: 15.4 mm hoses); PVC hose "
    "of 15/10 mm: 0.12-0.14 kg/m, EI 0.01-0.04 N m^2 (soft PVC 5-20 MPa): the default "
    "(EI 0.005-0.02) is on the soft side and stays as the thesis's simulated hose",
)

ELECTRICAL_CABLE = CableKind(
    name="electrical_cable",
    summary="7 mm PVC-sheathed mains power cable (H05VV-F 3G1.5 class), black, grey or white",
    radius=0.0035,
    segment_length=0.02,
    young=(1e7, 5e7),
    poisson=0.4,
    mass_per_metre=0.08,
    damping=0.01,
    friction=0.45,
    colors=(_grey(0.06), _grey(0.12), _grey(0.45), _grey(0.62), _grey(0.9), _grey(0.95)),
    color_jitter=0.02,
    sources="PVC multicore datasheets (3x1.5 mm^2: 6.2 mm, 64 kg/km; 3x2.5 mm^2: 7.2 mm, "
    "93 kg/km); EI 1.2e-3-5.9e-3 N m^2 estimated from PVC sheath and insulation moduli "
    "(10-60 MPa), checked against MuJoCo's demo cable (EI 2e-3); PVC on wood 0.3-0.6",
    pattern="marking",
    pattern_period=0.05,
)

THIN_WIRE = CableKind(
    name="thin_wire",
    summary="2 mm PVC-insulated stranded hook-up wire (0.75-1.5 mm^2), in wiring colours",
    radius=0.001,
    segment_length=0.02,
    young=(5e7, 4e8),
    poisson=0.4,
    mass_per_metre=0.01,
    damping=0.002,
    friction=0.4,
    colors=(
        (0.80, 0.08, 0.06),
        _grey(0.05),
        (0.10, 0.25, 0.75),
        (0.90, 0.80, 0.10),
        (0.10, 0.55, 0.15),
        _grey(0.92),
        (0.95, 0.55, 0.10),
        (0.45, 0.25, 0.10),
    ),
    color_jitter=0.04,
    sources="stranded PVC wire tables (1.0 mm^2: 1.8 mm, 1.5 mm^2: 2.2 mm; UL1007 18 AWG "
    "about 10 g/m); EI 3.9e-5-3.1e-4 N m^2 from the strands bending on their own "
    "(n E_cu pi d^4 / 64) plus the insulation; stranded, not solid core (which yields)",
)

ROPE = CableKind(
    name="rope",
    summary="10 mm three-strand polyester rope: soft in bending, no spring-back",
    radius=0.005,
    segment_length=0.02,
    young=(2e5, 2e6),
    poisson=0.3,
    mass_per_metre=0.065,
    damping=0.015,
    friction=0.5,
    colors=(
        (0.86, 0.82, 0.70),
        _grey(0.93),
        (0.15, 0.25, 0.60),
        (0.75, 0.15, 0.12),
        (0.20, 0.45, 0.25),
        (0.55, 0.45, 0.30),
    ),
    color_jitter=0.04,
    sources="polyester rope tables (10 mm: 65 g/m, engineeringtoolbox); EI 1e-4-1e-3 N m^2 "
    "estimated (fibres slipping: 2e-5, twist and friction raise it 10-100x); capstan tests "
    "of polyester rope on timber 0.36-0.37, rough twisted rope about 0.5; lay length of "
    "three-strand rope about 3.5 diameters",
    pattern="twisted",
    pattern_period=0.035,
    # the pads' contact 10x stiffer than the hand's default: at 0.99 a 65 g/m rope lying on
    # the table creeps down out of the pads at the stroke reversals (docs/cables.md)
    grip_dmax=0.999,
)

#: Every kind, by name (the registry ``--cable`` and ``hoses.kind`` choose from).
CABLE_KINDS: dict[str, CableKind] = {
    k.name: k for k in (GARDEN_HOSE, ELECTRICAL_CABLE, THIN_WIRE, ROPE)
}
DEFAULT_KIND = GARDEN_HOSE.name


def cable_kind(name: str, field: str = "hoses.kind") -> CableKind:
    """The kind called ``name``; a ConfigError naming ``field`` and the choices otherwise."""
    try:
        return CABLE_KINDS[name]
    except (KeyError, TypeError):
        raise ConfigError(
            field, f"unknown cable kind {name!r} (one of: {', '.join(CABLE_KINDS)})"
        ) from None
