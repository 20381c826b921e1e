"""Typed, seeded, printable configuration of a simulated task-board scene.

Frame conventions (world, metres): table top at z = 0, x from the robot towards the board,
z up.  The board's front face is the plane x = ``board.x``; connectors stick out of it towards
-x.  ``SceneConfig.validate()`` raises ``ConfigError`` naming the first impossible field.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cablesim.config import Config, check_positive, check_range
from cablesim.errors import ConfigError
from cablesim.panda.description import PARK_QPOS
from cablesim.panda.visuals import check_visual

BACKGROUNDS = ("wood", "bushes", "cables", "solid")

# Default connector layout on the board: (y, z) of each male connector, two rows of five.
DEFAULT_CONNECTORS: tuple[tuple[float, float], ...] = tuple(
    (y, z) for z in (0.86, 0.62) for y in (-0.30, -0.15, 0.0, 0.15, 0.30)
)


@dataclass
class BoardConfig:
    """The vertical task board with male garden-hose connectors."""

    x: float = 0.62  # front face of the board
    width: float = 0.9  # along y
    height: float = 1.0  # along z, from the table top
    thickness: float = 0.02
    background: str = "wood"  # one of BACKGROUNDS
    solid_rgb: tuple[float, float, float] = (0.55, 0.55, 0.58)  # used by "solid"
    connectors: tuple[tuple[float, float], ...] = DEFAULT_CONNECTORS
    connector_length: float = 0.06  # how far a male connector sticks out of the board

    def validate(self) -> None:
        if self.background not in BACKGROUNDS:
            raise ConfigError(
                "board.background",
                f"unknown background {self.background!r}; choose one of {BACKGROUNDS}",
            )
        for name in ("width", "height", "thickness", "connector_length"):
            check_positive(f"board.{name}", getattr(self, name))
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


@dataclass
class HoseConfig:
    """Ranges from which each hose's properties are drawn (seeded)."""

    count: int = 4
    length: tuple[float, float] = (0.6, 1.5)
    radius: float = 0.0075  # 15 mm thick
    segment_length: float = 0.03  # target edge length; vertex count follows from the length
    young: tuple[float, float] = (2e6, 8e6)  # Pa, bending/twist stiffness of the rod
    poisson: float = 0.3
    mass_per_metre: float = 0.15  # kg/m
    damping: float = 0.02  # N s/m on each hose vertex dof (air drag, internal losses)
    both_ends_probability: float = 0.75  # else attached at one end and hanging free
    colors: tuple[tuple[float, float, float], ...] = (
        (0.85, 0.20, 0.15),
        (0.15, 0.55, 0.20),
        (0.15, 0.35, 0.80),
        (0.95, 0.75, 0.10),
        (0.10, 0.10, 0.10),
        (0.90, 0.45, 0.10),
        (0.55, 0.20, 0.65),
        (0.85, 0.85, 0.85),
    )
    color_jitter: float = 0.06
    friction: float = 0.9
    # cross-section of the rod: "circle" of ``radius`` (default), or "box" of half-sizes
    # ``section_size`` (a flat ribbon), which MuJoCo draws in the rod's material frame, so its
    # twist shows in the image (the twist check of the ground-truth flow uses one)
    section: str = "circle"
    section_size: tuple[float, float] = (0.0075, 0.0075)

    def validate(self) -> None:
        if not isinstance(self.count, int) or not 1 <= self.count <= 8:
            raise ConfigError("hoses.count", f"1 to 8 hoses are supported, got {self.count!r}")
        check_range("hoses.length", self.length, lo=1e-9)
        if self.length[0] <= 0:
            raise ConfigError("hoses.length", f"lengths must be positive, got {self.length}")
        check_positive("hoses.radius", self.radius)
        check_positive("hoses.segment_length", self.segment_length)
        if self.segment_length < 2 * self.radius:
            raise ConfigError(
                "hoses.segment_length", f"{self.segment_length} is shorter than the hose diameter"
            )
        check_range("hoses.young", self.young, lo=1e-9)
        if not 0 <= self.poisson < 0.5:
            raise ConfigError("hoses.poisson", f"must be in [0, 0.5), got {self.poisson}")
        check_positive("hoses.mass_per_metre", self.mass_per_metre)
        check_positive("hoses.damping", self.damping, allow_zero=True)
        if not 0 <= self.both_ends_probability <= 1:
            raise ConfigError("hoses.both_ends_probability", "must be in [0, 1]")
        if not self.colors:
            raise ConfigError("hoses.colors", "need at least one colour")
        if self.section not in ("circle", "box"):
            raise ConfigError("hoses.section", f"must be 'circle' or 'box', got {self.section!r}")
        if self.section == "box":
            if len(self.section_size) != 2 or min(self.section_size) <= 0:
                raise ConfigError(
                    "hoses.section_size", f"need two positive half-sizes, got {self.section_size}"
                )
            if abs(min(self.section_size) - self.radius) > 1e-12:
                raise ConfigError(
                    "hoses.section_size",
                    f"the smaller half-size {min(self.section_size)} must equal hoses.radius "
                    f"{self.radius} (MuJoCo collides a box rod as a capsule of that radius)",
                )


@dataclass
class CameraConfig:
    """A fixed RGB-D camera modelled on an Intel RealSense D456.

    The D456 colour sensor sees about 90 x 65 degrees at 1280x800 (16:10); its 4:3 modes crop
    the sides.  The default 640x480 is the speed/detail compromise (perception at the thesis's
    ~408x552 scale runs in real time on a CPU); any size up to 1280x720 works: ``fovy`` is kept,
    the horizontal field follows from the aspect ratio.
    """

    width: int = 640
    height: int = 480
    fovy: float = 58.0  # degrees, vertical field of view
    position: tuple[float, float, float] = (-0.42, 0.0, 0.62)
    look_at: tuple[float, float, float] = (0.62, 0.0, 0.46)
    position_jitter: float = 0.0  # metres, uniform per axis (randomised camera pose)
    look_at_jitter: float = 0.0
    depth_noise: bool = False
    depth_noise_std_per_m2: float = 0.0015  # RealSense-like: sigma = k * z^2
    near: float = 0.05
    far: float = 5.0

    def validate(self) -> None:
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
        if not 0 < self.near < self.far:
            raise ConfigError("camera.near", "need 0 < near < far")


@dataclass
class RobotConfig:
    """Where the Panda stands on the table (its base must stay out of the camera's view)."""

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

    def validate(self) -> None:
        if len(self.base_position) != 3:
            raise ConfigError("robot.base_position", "expected (x, y, z)")
        if len(self.park_qpos) != 7:
            raise ConfigError("robot.park_qpos", f"expected 7 joint angles, got {self.park_qpos}")
        if not isinstance(self.hand_board, bool):
            raise ConfigError("robot.hand_board", f"must be true or false, got {self.hand_board!r}")
        if self.hand_board and not self.enabled:
            raise ConfigError("robot.hand_board", "a board in the hand needs the robot (enabled)")
        check_visual(self.visual, "robot.visual")


@dataclass
class LightConfig:
    """Lighting: the camera's headlight and a directional key light.  ``jitter`` > 0 draws,
    from the seed's ``lighting`` stream, a brightness factor in [1 - jitter, 1 + jitter] for
    each light and turns the key light by up to ``jitter`` radians (randomised datasets); 0
    keeps the fixed lighting."""

    ambient: float = 0.35  # headlight
    diffuse: float = 0.35  # headlight
    key: float = 0.55  # directional key light (diffuse)
    jitter: float = 0.0

    def validate(self) -> None:
        for name in ("ambient", "diffuse", "key"):
            check_positive(f"light.{name}", getattr(self, name), allow_zero=True)
        check_positive("light.jitter", self.jitter, allow_zero=True)
        if self.jitter >= 1:
            raise ConfigError("light.jitter", f"must be < 1, got {self.jitter}")


@dataclass
class PhysicsConfig:
    timestep: float = 0.004
    settle_speed: float = 0.001  # m/s: settled when every hose vertex is slower than this
    settle_max_time: float = 20.0  # simulated seconds before giving up
    settle_check_every: float = 0.1
    gravity: float = -9.81
    cache: bool = True  # cache the settled state per config (see cablesim.sim.settle)

    def validate(self) -> None:
        if not 0 < self.timestep <= 0.016:
            raise ConfigError("physics.timestep", f"must be in (0, 0.016] s, got {self.timestep}")
        check_positive("physics.settle_speed", self.settle_speed)
        check_positive("physics.settle_max_time", self.settle_max_time)
        check_positive("physics.settle_check_every", self.settle_check_every)


@dataclass
class SceneConfig(Config):
    """Everything that defines a scene; ``seed`` draws the random parts."""

    seed: int = 0
    board: BoardConfig = field(default_factory=BoardConfig)
    hoses: HoseConfig = field(default_factory=HoseConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    light: LightConfig = field(default_factory=LightConfig)

    def validate(self) -> SceneConfig:
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError("seed", f"must be a non-negative integer, got {self.seed!r}")
        self.board.validate()
        self.hoses.validate()
        self.camera.validate()
        self.robot.validate()
        self.physics.validate()
        self.light.validate()
        if self.hoses.count > len(self.board.connectors):
            raise ConfigError(
                "hoses.count",
                f"{self.hoses.count} hoses need at least {self.hoses.count} connectors, "
                f"the board has {len(self.board.connectors)}",
            )
        return self
