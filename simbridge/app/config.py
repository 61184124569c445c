"""Robot and LiDAR parameters and world files: the records, and reading them from YAML.

Everything is validated once, at startup, by pydantic models (records of
:class:`~simbridge.app.settings.Record`: declared fields with bounds and descriptions). A bad
file fails fast with a :class:`~simbridge.errors.ConfigError` whose text names the file, the key
and the fix, e.g. ``params file 'pi.yaml': robot.mass: must be greater than 0 (got -1)``; a
record made in code (``RobotParams(mass=-1)``) raises
:class:`~simbridge.app.settings.SettingsError` (a ``ValueError``) naming the field.

Files are read with ``yaml.safe_load`` (YAML 1.1: quote ``"off"``/``"no"`` in shipped files);
PyYAML is imported only when a file is read: the defaults (:func:`load_params` and
:func:`load_world` without a path) are built from :data:`DEFAULT_WORLD` and the records' own
defaults, which tests/app/test_config.py keeps equal to the bundled files.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Self

from annotated_types import Ge, Gt, Le, Lt
from pydantic import BeforeValidator, Field, model_validator

from simbridge.app.settings import Float, Int, Record, SettingsError
from simbridge.errors import ConfigError
from simbridge.msgs.convert import finite_number
from simbridge.sim.parameters import check_robot_name


if TYPE_CHECKING:
    from simbridge.graph.params import Bounds
    from simbridge.sim.world import World


__all__ = [
    "DEFAULT_WORLD",
    "FloorPatch",
    "LidarParams",
    "NamedRobotSpec",
    "Params",
    "RealismParams",
    "RobotParams",
    "RobotSpec",
    "SafetyParams",
    "SimParams",
    "WorldSpec",
    "check_numbers",
    "default_params_path",
    "default_world_path",
    "load_client_tokens",
    "load_params",
    "load_world",
    "resource_dir",
    "world_params",
    "world_spec",
]


def resource_dir(name: str) -> Path:
    """Return the directory of a bundled resource folder (``static`` or ``config``).

    An installed wheel carries them inside the package (``simbridge/static``); a source
    checkout keeps them at the repository root, next to the package.
    """
    packaged = Path(str(resources.files("simbridge"))) / name
    if packaged.is_dir():
        return packaged
    return packaged.parent.parent / name


def default_params_path() -> Path:
    """Return the path of the bundled ``pi4b_params.yaml``."""
    return resource_dir("config") / "pi4b_params.yaml"


def default_world_path() -> Path:
    """Return the path of the bundled default world."""
    return resource_dir("config") / "worlds" / "default.yaml"


class RobotParams(Record):
    """Differential-drive robot: the course's Raspberry Pi 4B platform defaults."""

    mass: Float = Field(1.5, gt=0, le=1000, description="chassis mass, kg")
    wheel_radius: Float = Field(
        0.033, gt=0, le=1, description="wheel radius, m (not the 0.066 m diameter)"
    )
    wheelbase: Float = Field(0.160, gt=0, le=5, description="distance between drive wheels, m")
    inertia: Float = Field(
        0.0075,
        gt=0,
        le=1000,
        description="moment of inertia about the vertical axis, kg m^2",
    )
    max_linear_velocity: Float = Field(
        0.5, gt=0, le=20, description="linear-velocity limit on /cmd_vel, m/s"
    )
    max_angular_velocity: Float = Field(
        2.5, gt=0, le=50, description="angular-velocity limit on /cmd_vel, rad/s"
    )
    radius: Float = Field(0.105, gt=0, le=5, description="footprint radius for drawing, m")
    max_wheel_torque: Float = Field(
        0.05,
        gt=0,
        le=100,
        description="dynamic model: torque limit of each wheel motor, N m",
    )
    velocity_gain: Float = Field(
        0.25,
        gt=0,
        le=1000,
        description="dynamic model: wheel velocity-loop gain, N m per m/s of wheel-speed error",
    )
    cmd_vel_stamped: bool = Field(
        False,
        description="cmd_vel is geometry_msgs/msg/TwistStamped instead of Twist (as "
        "diff_drive_controller expects since Jazzy); startup only: set it in the params file",
    )


class LidarParams(Record):
    """A 2D LiDAR like the RPLIDAR A1 (REP-117 ranges)."""

    rays: Int = Field(360, ge=1, le=8192, description="rays per revolution")
    range_min: Float = Field(0.12, ge=0, description="minimum range, m")
    range_max: Float = Field(3.5, gt=0, le=1000, description="maximum range, m")
    rate: Float = Field(10.0, gt=0, le=100, description="scans per second, Hz")
    mount: tuple[Float, Float, Float] = Field(
        (0.0, 0.0, 0.0), description="x, y, yaw of frame 'laser' in 'base_link'"
    )
    noise_stddev: Float = Field(
        0.0, ge=0, le=1, description="Gaussian range noise, m (0 = exact ranges)"
    )
    dropout: Float = Field(
        0.0,
        ge=0,
        le=1,
        description="fraction of rays that return no echo (read as range_max; 0 = every ray)",
    )

    @model_validator(mode="after")
    def _ranges(self) -> Self:
        """Check that the minimum range is below the maximum."""
        if self.range_min >= self.range_max:
            msg = f"range_min ({self.range_min}) must be below range_max ({self.range_max})"
            raise ValueError(msg)
        return self


# -- the sim-to-real gap (issue 26): one plain parameter group, every value "off" by default --


class RealismParams(Record):
    """A robot as the real one behaves: motor lag, deadband, slip, geometry, encoders.

    Off by default (``enabled: false``, and every value at its "exact" setting): ``/odom`` is
    then the true pose, as the course's kinematic model has it. Equations:
    :mod:`simbridge.sim.realism`.
    """

    enabled: bool = Field(
        False,
        description="simulate the real robot with the values below (false: the ideal model, "
        "/odom = the true pose)",
    )
    cmd_latency: Float = Field(
        0.0,
        ge=0,
        le=2,
        description="a command takes effect this long after it arrives, s",
    )
    motor_time_constant: Float = Field(
        0.0,
        ge=0,
        le=5,
        description="each wheel's speed follows its command as a first-order lag of this "
        "time constant, s (0 = at once)",
    )
    deadband: Float = Field(
        0.0,
        ge=0,
        le=1,
        description="a wheel commanded slower than this does not turn, m/s",
    )
    wheel_speed_scale: Float = Field(
        1.0,
        gt=0,
        le=2,
        description="each wheel's steady speed per commanded speed (1 = exact; "
        "simbridge fit estimates it)",
    )
    slip: Float = Field(
        0.0,
        ge=0,
        le=1,
        description="mean fraction of wheel travel lost to slip (floor patches have their own)",
    )
    slip_stddev: Float = Field(
        0.0,
        ge=0,
        le=1,
        description="spread of the slip fraction, drawn per wheel and step (seeded)",
    )
    wheel_radius_left: Float = Field(
        0.0,
        ge=0,
        le=1,
        description="true left wheel radius, m (0 = robot.wheel_radius); odometry keeps "
        "robot.wheel_radius",
    )
    wheel_radius_right: Float = Field(
        0.0,
        ge=0,
        le=1,
        description="true right wheel radius, m (0 = robot.wheel_radius)",
    )
    wheelbase: Float = Field(
        0.0,
        ge=0,
        le=5,
        description="true wheelbase, m (0 = robot.wheelbase); odometry keeps robot.wheelbase",
    )
    encoder_ticks: Int = Field(
        0,
        ge=0,
        le=1_000_000,
        description="encoder ticks per wheel revolution; /odom integrates whole ticks (0 = exact)",
    )
    seed: Int = Field(
        0,
        ge=0,
        le=2**32 - 1,
        description="seed of the slip draws: the same seed and commands give the same run",
    )


# -- end of the sim-to-real block -----------------------------------------------------------


class SimParams(Record):
    """Simulation loop settings."""

    rate: Float = Field(20.0, gt=0, le=1000, description="kinematics and /odom rate, Hz")


class SafetyParams(Record):
    """Server-side safety of the robots (``config/classroom_params.yaml`` turns all of it on)."""

    cmd_vel_timeout: Float = Field(
        0.0,
        ge=0,
        le=3600,
        description="stop a robot after this many seconds without /cmd_vel (0 = off: the "
        "robot keeps its last command, as the course describes)",
    )
    stop_on_disconnect: bool = Field(
        False, description="stop a robot when the client that last commanded it disconnects"
    )
    stop_on_lost_link: bool = Field(
        True,
        description="stop a robot when the client that last commanded it is lost: gone without "
        "closing its connection itself (killed, crashed, unreachable, its page closed)",
    )


class Params(Record):
    """The whole parameter file (``config/pi4b_params.yaml``)."""

    robot: RobotParams = Field(default_factory=RobotParams)
    lidar: LidarParams = Field(default_factory=LidarParams)
    sim: SimParams = Field(default_factory=SimParams)
    safety: SafetyParams = Field(default_factory=SafetyParams)
    realism: RealismParams = Field(default_factory=RealismParams)

    def flat(self) -> dict[str, Any]:
        """Return every setting under its dotted name (``robot.mass``): ROS 2 parameters."""
        out: dict[str, Any] = {}
        for section in type(self).model_fields:
            for key, value in getattr(self, section).as_dict().items():
                out[f"{section}.{key}"] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_flat(cls, flat: dict[str, Any]) -> Params:
        """Build and validate settings from dotted names (the inverse of :meth:`flat`).

        Raises:
            SettingsError: a value is out of range or the combination is invalid (a
                ``ValueError``; the text names each dotted setting and why).
        """
        nested: dict[str, dict[str, Any]] = {}
        for name, value in flat.items():
            section, _, key = name.partition(".")
            nested.setdefault(section, {})[key] = value
        return cls.parse(nested)

    @classmethod
    def sections(cls) -> dict[str, type[Record]]:
        """Return the record class of each section (``robot`` -> :class:`RobotParams`)."""
        out: dict[str, type[Record]] = {}
        for section, info in cls.model_fields.items():
            assert isinstance(info.annotation, type) and issubclass(info.annotation, Record)
            out[section] = info.annotation
        return out

    @classmethod
    def describe(cls) -> dict[str, str]:
        """Return a one-line description of every dotted setting (from its declaration)."""
        return {
            f"{section}.{key}": info.description or ""
            for section, record in cls.sections().items()
            for key, info in record.model_fields.items()
        }

    @classmethod
    def bounds(cls) -> dict[str, Bounds]:
        """Return the declared bounds of every dotted setting (empty ones for the unbounded)."""
        from simbridge.graph.params import Bounds  # here: simbridge.graph imports these records

        out: dict[str, Bounds] = {}
        for section, record in cls.sections().items():
            for key, info in record.model_fields.items():
                found: dict[str, float] = {}
                for m in info.metadata:
                    for kind, name in ((Gt, "gt"), (Ge, "ge"), (Lt, "lt"), (Le, "le")):
                        if isinstance(m, kind):
                            found[name] = getattr(m, name)
                out[f"{section}.{key}"] = Bounds(**found)
        return out


class RobotSpec(Record):
    """A robot of a world file: its start pose (x, y, theta), used at start and by /reset."""

    pose: tuple[Float, Float, Float] = Field((0.0, 0.0, 0.0), description="x, y, theta")
    #: This robot's own realism values over the parameters' ``realism`` (issue 26): the
    #: values given here are its own (``{enabled: true, motor_time_constant: 0.2}``).
    realism: RealismParams | None = None


class NamedRobotSpec(RobotSpec):
    """A robot of a ``robots:`` list: its name (its topic namespace) and start pose."""

    name: Annotated[str, BeforeValidator(check_robot_name)] = Field(
        description="the robot's topic namespace"
    )


def check_numbers(value: Any, count: int, what: str) -> list[float]:
    """Return ``value`` as ``count`` floats, or raise ``ValueError`` saying what was ``what``.

    The checks of a world file's walls, points and poses (and a task's), before their types.
    """
    if not isinstance(value, Sequence) or isinstance(value, str):
        msg = f"is {value!r}, not a list; expected {what}"
        raise ValueError(msg)
    if len(value) != count:
        msg = f"has {len(value)} numbers, expected {what}"
        raise ValueError(msg)
    out = []
    for x in value:
        if not finite_number(x):
            msg = f"{x!r} is not a finite number; expected {what}"
            raise ValueError(msg)
        out.append(float(x))
    return out


def _frame_pose(value: Any) -> list[float]:
    count = len(value) if isinstance(value, list) else 0
    return check_numbers(
        value, 6 if count == 6 else 3, "[x, y, yaw] or [x, y, z, roll, pitch, yaw]"
    )


def _numbers(count: int, what: str) -> BeforeValidator:
    """A check of ``count`` finite numbers (``what``: how the fix reads, ``[x, y]``)."""
    return BeforeValidator(lambda value: check_numbers(value, count, what))


def _corners(least: int) -> Callable[[Any], Any]:
    """A check of a polygon's length (each point is a :data:`Point`)."""

    def check(value: Any) -> Any:
        if not isinstance(value, list) or len(value) < least:
            msg = f"must be a list of at least {least} corners [x, y] (got {value!r})"
            raise ValueError(msg)
        return value

    return check


#: A wall segment, a point of a polygon.
Segment = Annotated[tuple[Float, Float, Float, Float], _numbers(4, "[x1, y1, x2, y2]")]
Point = Annotated[tuple[Float, Float], _numbers(2, "[x, y]")]


class Box(Record):
    """An axis-aligned (or rotated) rectangular obstacle."""

    center: tuple[Float, Float]
    size: tuple[Float, Float]
    yaw: Float = 0.0


class Circle(Record):
    """A round obstacle (a pillar), approximated by a regular polygon for raycasting."""

    center: tuple[Float, Float]
    radius: Float = Field(gt=0)
    segments: Int = Field(24, ge=6, le=256)


class FloorPatch(Record):
    """A patch of floor with its own slip (a rug, a ramp): a polygon in the world frame."""

    name: str = Field("", max_length=200, description="shown to people")
    polygon: Annotated[list[Point], BeforeValidator(_corners(3))] = Field(
        description="corners [x, y], at least 3"
    )
    slip: Float = Field(
        ge=0, le=1, description="fraction of wheel travel lost to slip on this patch"
    )


class StaticFrame(Record):
    """A fixed transform ``parent -> child`` published on ``/tf_static`` (REP-105 frame names).

    ``pose`` is ``[x, y, yaw]`` (metres, radians: the 2D case) or ``[x, y, z, roll, pitch,
    yaw]`` as ``static_transform_publisher`` takes them.
    """

    parent: str = Field(min_length=1, max_length=200)
    child: str = Field(min_length=1, max_length=200)
    pose: Annotated[list[Float], BeforeValidator(_frame_pose)] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0]
    )

    def xyz_rpy(self) -> tuple[float, float, float, float, float, float]:
        """Return the pose as (x, y, z, roll, pitch, yaw)."""
        p = self.pose
        if len(p) == 3:
            return (p[0], p[1], 0.0, 0.0, 0.0, p[2])
        return (p[0], p[1], p[2], p[3], p[4], p[5])


class WorldSpec(Record):
    """A world file: walls and obstacles as line segments, and the robot's start pose.

    The minimal form is ``walls: [[x1, y1, x2, y2], ...]`` plus ``robot: {pose: [x, y, th]}``.
    ``boxes``, ``circles`` and ``polygons`` are conveniences turned into segments.
    """

    name: str = "world"
    walls: list[Segment] = Field(default_factory=list)
    boxes: list[Box] = Field(default_factory=list)
    circles: list[Circle] = Field(default_factory=list)
    polygons: list[Annotated[list[Point], BeforeValidator(_corners(2))]] = Field(
        default_factory=list
    )
    robot: RobotSpec = Field(default_factory=RobotSpec)
    #: Named robots (``/r1/odom``...); ``None`` means the single un-namespaced ``robot``.
    robots: list[NamedRobotSpec] | None = None
    #: Fixed frames published on /tf_static (``{parent: world, child: turtle1, pose: [...]}``).
    frames: list[StaticFrame] = Field(default_factory=list, max_length=1000)
    #: Start the ROS tutorial nodes (talker, listener, add_two_ints, fibonacci), as
    #: ``--demo-nodes`` does.
    demo_nodes: bool = False
    #: Floor patches with their own slip, for robots under a realism profile (issue 26).
    floor: list[FloorPatch] = Field(default_factory=list, max_length=1000)

    @model_validator(mode="after")
    def _frames_and_robots(self) -> Self:
        """Check frames (one parent each), robots (``robot`` or ``robots``, unique names)."""
        children: set[str] = set()
        for i, f in enumerate(self.frames):
            child = f.child.lstrip("/")
            if child == f.parent.lstrip("/"):
                msg = f"frames[{i}]: parent and child are both '{child}'"
                raise ValueError(msg)
            if child in children:
                msg = f"frames[{i}]: frame '{child}' has two parents; each child frame once"
                raise ValueError(msg)
            children.add(child)
        if self.robots is None:
            return self
        if "robot" in self.given:
            msg = (
                "give either 'robot:' (one robot, un-namespaced topics) or 'robots:' "
                "(named robots, /NAME/odom...), not both"
            )
            raise ValueError(msg)
        seen: set[str] = set()
        for i, r in enumerate(self.robots):
            if r.name in seen:
                msg = f"robots[{i}]: name '{r.name}' is used twice; robot names must be unique"
                raise ValueError(msg)
            seen.add(r.name)
        return self

    def start_poses(self) -> dict[str, tuple[float, float, float]]:
        """Return the robots at start by name (``""`` for the single un-namespaced robot)."""
        if self.robots is None:
            return {"": self.robot.pose}
        return {r.name: r.pose for r in self.robots}

    def start_realism(self) -> dict[str, dict[str, object]]:
        """Return each robot's own realism values given in the file (robots without: absent)."""
        specs: list[tuple[str, RobotSpec]] = (
            [("", self.robot)] if self.robots is None else [(r.name, r) for r in self.robots]
        )
        return {
            name: {k: getattr(spec.realism, k) for k in spec.realism.given}
            for name, spec in specs
            if spec.realism is not None and spec.realism.given
        }

    def without_robots(self) -> WorldSpec:
        """Return this world with no robot at all (``--no-sim``: the bridge alone)."""
        kept = {name: getattr(self, name) for name in self.given if name != "robot"}
        return WorldSpec(**{**kept, "robots": []})

    def segments(self) -> list[tuple[float, float, float, float]]:
        """Return every wall and obstacle edge as a segment ``(x1, y1, x2, y2)``."""
        segs = [(w[0], w[1], w[2], w[3]) for w in self.walls]
        for box in self.boxes:
            hw, hh = box.size[0] / 2, box.size[1] / 2
            c, s = math.cos(box.yaw), math.sin(box.yaw)
            corners = [
                (box.center[0] + c * dx - s * dy, box.center[1] + s * dx + c * dy)
                for dx, dy in ((-hw, -hh), (hw, -hh), (hw, hh), (-hw, hh))
            ]
            segs.extend(_ring(corners))
        for circle in self.circles:
            n = circle.segments
            pts = [
                (
                    circle.center[0] + circle.radius * math.cos(2 * math.pi * k / n),
                    circle.center[1] + circle.radius * math.sin(2 * math.pi * k / n),
                )
                for k in range(n)
            ]
            segs.extend(_ring(pts))
        for poly in self.polygons:
            pts = [(float(p[0]), float(p[1])) for p in poly]
            segs.extend(_ring(pts) if len(pts) > 2 else [(*pts[0], *pts[1])])
        return segs


#: The default world, as ``config/worlds/default.yaml`` has it (comments there): a 6 m x 4 m
#: room with a few obstacles and a corridor leading east out of it.
DEFAULT_WORLD: dict[str, Any] = {
    "name": "default",
    "walls": [
        [-3.0, -2.0, 3.0, -2.0],
        [-3.0, -2.0, -3.0, 2.0],
        [-3.0, 2.0, 3.0, 2.0],
        [3.0, 2.0, 3.0, 0.5],
        [3.0, -0.5, 3.0, -2.0],
        [3.0, 0.5, 6.0, 0.5],
        [3.0, -0.5, 6.0, -0.5],
        [6.0, -0.5, 6.0, 0.5],
        [0.5, -2.0, 0.5, -1.0],
    ],
    "boxes": [
        {"center": [1.5, 1.0], "size": [0.6, 0.4]},
        {"center": [-1.2, 1.2], "size": [0.4, 0.8], "yaw": 0.3},
    ],
    "circles": [{"center": [-1.5, -1.0], "radius": 0.3}],
    "robot": {"pose": [0.0, 0.0, 0.0]},
}


def _ring(points: list[tuple[float, float]]) -> list[tuple[float, float, float, float]]:
    return [(*points[k], *points[(k + 1) % len(points)]) for k in range(len(points))]


def _read_yaml(path: Path, kind: str) -> dict[str, Any]:
    import yaml  # here, not at the top: a run without a file does not load PyYAML (issue 16)

    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        msg = f"{kind} file '{path}': cannot be read ({err.strerror}); check the path"
        raise ConfigError(msg) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        msg = f"{kind} file '{path}': is not valid YAML: {err}"
        raise ConfigError(msg) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        msg = (
            f"{kind} file '{path}': top level must be a mapping of keys, got {type(data).__name__}"
        )
        raise ConfigError(msg)
    return data


def load_params(path: Path | str | None = None) -> Params:
    """Load and validate a parameter file; ``None``: the Pi 4B platform defaults.

    The defaults are :class:`Params`' own, the values of the bundled ``pi4b_params.yaml``
    (tests/app/test_config.py keeps them equal), so they need no YAML parser.

    Raises:
        ConfigError: the file is missing, not YAML, or a key or value is invalid.
    """
    if path is None:
        return Params()
    p = Path(path)
    data = _read_yaml(p, "params")
    try:
        return Params.parse(data)
    except SettingsError as err:
        raise ConfigError(f"params file '{p}': {err}") from None


def load_world(path: Path | str | None = None) -> WorldSpec:
    """Load and validate a world file; ``None``: the default world (:data:`DEFAULT_WORLD`).

    The default world is the bundled ``worlds/default.yaml`` (tests/app/test_config.py keeps them
    equal), built without a YAML parser.

    Raises:
        ConfigError: the file is missing, not YAML, or a key or value is invalid.
    """
    if path is None:
        return WorldSpec.parse(DEFAULT_WORLD)
    p = Path(path)
    data = _read_yaml(p, "world")
    data.setdefault("name", p.stem)
    try:
        return WorldSpec.parse(data)
    except SettingsError as err:
        raise ConfigError(f"world file '{p}': {err}") from None


def load_client_tokens(path: Path | str) -> dict[str, str]:
    """Load a client-token file: ``tokens: {TOKEN: SCOPE}``.

    A scope is a robot name (publish only under ``/<robot>/``), ``"*"`` (every topic) or
    ``"admin"`` (every topic and administrative services).

    Raises:
        ConfigError: the file is missing or malformed, or a token is too short to be secret.
    """
    p = Path(path)
    data = _read_yaml(p, "client tokens")
    tokens = data.get("tokens")
    extra = sorted(set(data) - {"tokens"})
    if extra:
        msg = f"client tokens file '{p}': {extra[0]}: unknown key (expected only 'tokens')"
        raise ConfigError(msg)
    if not isinstance(tokens, dict) or not tokens:
        msg = f"client tokens file '{p}': tokens: must be a mapping TOKEN: SCOPE (robot name)"
        raise ConfigError(msg)
    out: dict[str, str] = {}
    for token, scope in tokens.items():
        shown = str(token)[:4] + "..."
        if not isinstance(token, str) or len(token) < 8:
            msg = (
                f"client tokens file '{p}': tokens: {shown}: a token must be a quoted string "
                "of at least 8 characters"
            )
            raise ConfigError(msg)
        if not isinstance(scope, str) or not scope or not _SCOPE.match(scope):
            msg = (
                f"client tokens file '{p}': tokens.{shown}: scope {scope!r} must be a robot "
                "name, '*' or 'admin'"
            )
            raise ConfigError(msg)
        out[token] = scope
    return out


_SCOPE = re.compile(r"^(\*|[A-Za-z_][A-Za-z0-9_]*)$")


def world_params(world: World) -> Params:
    """Return the :class:`Params` a world moves with (the simulator sees only what it reads)."""
    params = world.params
    assert isinstance(params, Params), "a World built from simbridge's parameter records"
    return params


def world_spec(world: World) -> WorldSpec:
    """Return the :class:`WorldSpec` a world was built from."""
    spec = world.spec
    assert isinstance(spec, WorldSpec), "a World built from a simbridge world file"
    return spec
