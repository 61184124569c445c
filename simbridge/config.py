"""Settings of simbridge: robot and LiDAR parameters, world files, server options.

Everything is validated once, at startup, by the settings records of :mod:`simbridge.schema`
(declared fields with bounds and descriptions). A bad file fails fast with a
:class:`~simbridge.errors.ConfigError` whose text names the file, the key and the fix, e.g.
``params file 'pi.yaml': robot.mass: must be greater than 0 (got -1)``; a record made in code
(``RobotParams(mass=-1)``) raises :class:`ValidationError` (a ``ValueError``) naming the field.

Files are read with ``yaml.safe_load`` (YAML 1.1: quote ``"off"``/``"no"`` in shipped files);
PyYAML is imported only when a file is read: the defaults (:func:`load_params` and
:func:`load_world` without a path) are built from :data:`DEFAULT_WORLD` and the records' own
defaults, which tests/test_config.py keeps equal to the bundled files.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, TypeGuard

from simbridge.errors import ConfigError
from simbridge.schema import Bounds, Record, ValidationError, converter, setting


__all__ = [
    "DEFAULT_WORLD",
    "Count",
    "Environment",
    "FloorPatch",
    "LidarParams",
    "NamedRobotSpec",
    "Params",
    "Port",
    "Rate",
    "RealismParams",
    "RobotParams",
    "RobotSpec",
    "SafetyParams",
    "Seconds",
    "ServerSettings",
    "SimParams",
    "ValidationError",
    "WorldSpec",
    "check_numbers",
    "check_ros2_role",
    "default_params_path",
    "default_world_path",
    "finite_number",
    "load_client_tokens",
    "load_params",
    "load_world",
    "parse_value",
    "resource_dir",
    "server_settings",
]


def resource_dir(name: str) -> Path:
    """Return the directory of a bundled resource folder (``static`` or ``config``).

    An installed wheel carries them inside the package (``simbridge/static``); a source
    checkout keeps them at the repository root, next to the package.
    """
    packaged = Path(str(resources.files("simbridge"))) / name
    if packaged.is_dir():
        return packaged
    return Path(__file__).resolve().parent.parent / name


def default_params_path() -> Path:
    """Return the path of the bundled ``pi4b_params.yaml``."""
    return resource_dir("config") / "pi4b_params.yaml"


def default_world_path() -> Path:
    """Return the path of the bundled default world."""
    return resource_dir("config") / "worlds" / "default.yaml"


def finite_number(value: object) -> TypeGuard[int | float]:
    """Whether ``value`` is a finite number: an int or a float (not a bool), not NaN or infinite.

    The one check for numbers from files, parameters and service requests (JSON has no NaN,
    but Python's parser and YAML's ``.nan`` do). An int too large for a float is not finite.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


class RobotParams(Record):
    """Differential-drive robot: the course's Raspberry Pi 4B platform defaults."""

    mass: float = setting(default=1.5, gt=0, le=1000, description="chassis mass, kg")
    wheel_radius: float = setting(
        default=0.033, gt=0, le=1, description="wheel radius, m (not the 0.066 m diameter)"
    )
    wheelbase: float = setting(
        default=0.160, gt=0, le=5, description="distance between drive wheels, m"
    )
    inertia: float = setting(
        default=0.0075,
        gt=0,
        le=1000,
        description="moment of inertia about the vertical axis, kg m^2",
    )
    max_linear_velocity: float = setting(
        default=0.5, gt=0, le=20, description="linear-velocity limit on /cmd_vel, m/s"
    )
    max_angular_velocity: float = setting(
        default=2.5, gt=0, le=50, description="angular-velocity limit on /cmd_vel, rad/s"
    )
    radius: float = setting(
        default=0.105, gt=0, le=5, description="footprint radius for drawing, m"
    )
    max_wheel_torque: float = setting(
        default=0.05,
        gt=0,
        le=100,
        description="dynamic model: torque limit of each wheel motor, N m",
    )
    velocity_gain: float = setting(
        default=0.25,
        gt=0,
        le=1000,
        description="dynamic model: wheel velocity-loop gain, N m per m/s of wheel-speed error",
    )
    cmd_vel_stamped: bool = setting(
        default=False,
        description="cmd_vel is geometry_msgs/msg/TwistStamped instead of Twist (as "
        "diff_drive_controller expects since Jazzy); startup only: set it in the params file",
    )


class LidarParams(Record):
    """A 2D LiDAR like the RPLIDAR A1 (REP-117 ranges)."""

    rays: int = setting(default=360, ge=1, le=8192, description="rays per revolution")
    range_min: float = setting(default=0.12, ge=0, description="minimum range, m")
    range_max: float = setting(default=3.5, gt=0, le=1000, description="maximum range, m")
    rate: float = setting(default=10.0, gt=0, le=100, description="scans per second, Hz")
    mount: tuple[float, float, float] = setting(
        default=(0.0, 0.0, 0.0), description="x, y, yaw of frame 'laser' in 'base_link'"
    )
    noise_stddev: float = setting(
        default=0.0, ge=0, le=1, description="Gaussian range noise, m (0 = exact ranges)"
    )
    dropout: float = setting(
        default=0.0,
        ge=0,
        le=1,
        description="fraction of rays that return no echo (read as range_max; 0 = every ray)",
    )

    def check(self) -> None:
        """Check that the minimum range is below the maximum."""
        if self.range_min >= self.range_max:
            msg = f"range_min ({self.range_min}) must be below range_max ({self.range_max})"
            raise ValueError(msg)


# -- the sim-to-real gap (issue 26): one plain parameter group, every value "off" by default --


class RealismParams(Record):
    """A robot as the real one behaves: motor lag, deadband, slip, geometry, encoders.

    Off by default (``enabled: false``, and every value at its "exact" setting): ``/odom`` is
    then the true pose, as the course's kinematic model has it. Equations:
    :mod:`simbridge.sim.realism`.
    """

    enabled: bool = setting(
        default=False,
        description="simulate the real robot with the values below (false: the ideal model, "
        "/odom = the true pose)",
    )
    cmd_latency: float = setting(
        default=0.0,
        ge=0,
        le=2,
        description="a command takes effect this long after it arrives, s",
    )
    motor_time_constant: float = setting(
        default=0.0,
        ge=0,
        le=5,
        description="each wheel's speed follows its command as a first-order lag of this "
        "time constant, s (0 = at once)",
    )
    deadband: float = setting(
        default=0.0,
        ge=0,
        le=1,
        description="a wheel commanded slower than this does not turn, m/s",
    )
    wheel_speed_scale: float = setting(
        default=1.0,
        gt=0,
        le=2,
        description="each wheel's steady speed per commanded speed (1 = exact; "
        "simbridge fit estimates it)",
    )
    slip: float = setting(
        default=0.0,
        ge=0,
        le=1,
        description="mean fraction of wheel travel lost to slip (floor patches have their own)",
    )
    slip_stddev: float = setting(
        default=0.0,
        ge=0,
        le=1,
        description="spread of the slip fraction, drawn per wheel and step (seeded)",
    )
    wheel_radius_left: float = setting(
        default=0.0,
        ge=0,
        le=1,
        description="true left wheel radius, m (0 = robot.wheel_radius); odometry keeps "
        "robot.wheel_radius",
    )
    wheel_radius_right: float = setting(
        default=0.0,
        ge=0,
        le=1,
        description="true right wheel radius, m (0 = robot.wheel_radius)",
    )
    wheelbase: float = setting(
        default=0.0,
        ge=0,
        le=5,
        description="true wheelbase, m (0 = robot.wheelbase); odometry keeps robot.wheelbase",
    )
    encoder_ticks: int = setting(
        default=0,
        ge=0,
        le=1_000_000,
        description="encoder ticks per wheel revolution; /odom integrates whole ticks (0 = exact)",
    )
    seed: int = setting(
        default=0,
        ge=0,
        le=2**32 - 1,
        description="seed of the slip draws: the same seed and commands give the same run",
    )


# -- end of the sim-to-real block -----------------------------------------------------------


class SimParams(Record):
    """Simulation loop settings."""

    rate: float = setting(default=20.0, gt=0, le=1000, description="kinematics and /odom rate, Hz")


class SafetyParams(Record):
    """Server-side safety of the robots (``config/classroom_params.yaml`` turns all of it on)."""

    cmd_vel_timeout: float = setting(
        default=0.0,
        ge=0,
        le=3600,
        description="stop a robot after this many seconds without /cmd_vel (0 = off: the "
        "robot keeps its last command, as the course describes)",
    )
    stop_on_disconnect: bool = setting(
        default=False, description="stop a robot when the client that last commanded it disconnects"
    )
    stop_on_lost_link: bool = setting(
        default=True,
        description="stop a robot when the client that last commanded it is lost: gone without "
        "closing its connection itself (killed, crashed, unreachable, its page closed)",
    )


class Params(Record):
    """The whole parameter file (``config/pi4b_params.yaml``)."""

    robot: RobotParams = setting(default_factory=RobotParams)
    lidar: LidarParams = setting(default_factory=LidarParams)
    sim: SimParams = setting(default_factory=SimParams)
    safety: SafetyParams = setting(default_factory=SafetyParams)
    realism: RealismParams = setting(default_factory=RealismParams)

    def flat(self) -> dict[str, Any]:
        """Return every setting under its dotted name (``robot.mass``): ROS 2 parameters."""
        out: dict[str, Any] = {}
        for section in type(self).settings():
            for key, value in getattr(self, section).as_dict().items():
                out[f"{section}.{key}"] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_flat(cls, flat: dict[str, Any]) -> Params:
        """Build and validate settings from dotted names (the inverse of :meth:`flat`).

        Raises:
            ValidationError: a value is out of range or the combination is invalid (a
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
        for section, spec in cls.settings().items():
            assert isinstance(spec.kind, type) and issubclass(spec.kind, Record)
            out[section] = spec.kind
        return out

    @classmethod
    def describe(cls) -> dict[str, str]:
        """Return a one-line description of every dotted setting (from its declaration)."""
        return {
            f"{section}.{key}": spec.description
            for section, record in cls.sections().items()
            for key, spec in record.settings().items()
        }

    @classmethod
    def bounds(cls) -> dict[str, Bounds]:
        """Return the declared bounds of every dotted setting (empty ones for the unbounded)."""
        return {
            f"{section}.{key}": spec.bounds
            for section, record in cls.sections().items()
            for key, spec in record.settings().items()
        }


class RobotSpec(Record):
    """A robot of a world file: its start pose (x, y, theta), used at start and by /reset."""

    pose: tuple[float, float, float] = setting(default=(0.0, 0.0, 0.0), description="x, y, theta")
    #: This robot's own realism values over the parameters' ``realism`` (issue 26): the
    #: values given here are its own (``{enabled: true, motor_time_constant: 0.2}``).
    realism: RealismParams | None = None


#: A robot name usable as a ROS namespace: ``r1``, ``alice``, ``team_3``.
ROBOT_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def check_robot_name(name: object) -> str:
    """Return ``name`` if it is a valid robot name (a ROS namespace token).

    Raises:
        ValueError: it is not.
    """
    if not isinstance(name, str) or not ROBOT_NAME.match(name):
        msg = (
            f"robot name {name!r} is not a valid ROS name: use a letter then letters, "
            "digits or '_' (e.g. r1, alice, team_3)"
        )
        raise ValueError(msg)
    return name


def check_ros2_role(role: object) -> str | None:
    """Return ``role`` if it is a ROS 2 peers' role or None (``ServerSettings.ros2_role``).

    Raises:
        ValueError: it is not.
    """
    if role is None or role in ("none", "robots", "admin"):
        return role
    if isinstance(role, str) and role.startswith("robot:"):
        check_robot_name(role.removeprefix("robot:"))
        return role
    msg = f"{role!r} is not a ROS 2 role: use none, robot:NAME, robots or admin"
    raise ValueError(msg)


class NamedRobotSpec(RobotSpec):
    """A robot of a ``robots:`` list: its name (its topic namespace) and start pose."""

    name: str = setting(before=check_robot_name, description="the robot's topic namespace")


def check_numbers(value: Any, count: int, what: str) -> list[float]:
    """Return ``value`` as ``count`` floats, or raise ``ValueError`` saying what was ``what``.

    The checks of a world file's walls, points and poses (and a task's), for ``before=``.
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


def _walls(value: Any) -> Any:
    if not isinstance(value, list):
        msg = "must be a list of segments [x1, y1, x2, y2]"
        raise ValueError(msg)
    for i, seg in enumerate(value):
        try:
            check_numbers(seg, 4, "[x1, y1, x2, y2]")
        except ValueError as err:
            raise ValidationError.one(str(err), f"[{i}]") from None
    return value


def _polygons(value: Any) -> Any:
    if not isinstance(value, list):
        msg = "must be a list of polygons, each a list of [x, y] points"
        raise ValueError(msg)
    for i, poly in enumerate(value):
        if not isinstance(poly, list) or len(poly) < 2:
            raise ValidationError.one("needs at least 2 points [x, y]", f"[{i}]")
        for j, pt in enumerate(poly):
            try:
                check_numbers(pt, 2, "[x, y]")
            except ValueError as err:
                raise ValidationError.one(str(err), f"[{i}][{j}]") from None
    return value


class Box(Record):
    """An axis-aligned (or rotated) rectangular obstacle."""

    center: tuple[float, float]
    size: tuple[float, float]
    yaw: float = 0.0


class Circle(Record):
    """A round obstacle (a pillar), approximated by a regular polygon for raycasting."""

    center: tuple[float, float]
    radius: float = setting(gt=0)
    segments: int = setting(default=24, ge=6, le=256)


def _floor_polygon(value: Any) -> Any:
    if not isinstance(value, list) or len(value) < 3:
        msg = "must be a list of at least 3 corners [x, y]"
        raise ValueError(msg)
    for j, pt in enumerate(value):
        try:
            check_numbers(pt, 2, "[x, y]")
        except ValueError as err:
            raise ValidationError.one(str(err), f"[{j}]") from None
    return value


class FloorPatch(Record):
    """A patch of floor with its own slip (a rug, a ramp): a polygon in the world frame."""

    name: str = setting(default="", max_length=200, description="shown to people")
    polygon: list[tuple[float, float]] = setting(
        before=_floor_polygon, description="corners [x, y], at least 3"
    )
    slip: float = setting(
        ge=0, le=1, description="fraction of wheel travel lost to slip on this patch"
    )


class StaticFrame(Record):
    """A fixed transform ``parent -> child`` published on ``/tf_static`` (REP-105 frame names).

    ``pose`` is ``[x, y, yaw]`` (metres, radians: the 2D case) or ``[x, y, z, roll, pitch,
    yaw]`` as ``static_transform_publisher`` takes them.
    """

    parent: str = setting(min_length=1, max_length=200)
    child: str = setting(min_length=1, max_length=200)
    pose: list[float] = setting(default_factory=lambda: [0.0, 0.0, 0.0], before=_frame_pose)

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
    walls: list[tuple[float, float, float, float]] = setting(default_factory=list, before=_walls)
    boxes: list[Box] = setting(default_factory=list)
    circles: list[Circle] = setting(default_factory=list)
    polygons: list[list[tuple[float, float]]] = setting(default_factory=list, before=_polygons)
    robot: RobotSpec = setting(default_factory=RobotSpec)
    #: Named robots (``/r1/odom``...); ``None`` means the single un-namespaced ``robot``.
    robots: list[NamedRobotSpec] | None = None
    #: Fixed frames published on /tf_static (``{parent: world, child: turtle1, pose: [...]}``).
    frames: list[StaticFrame] = setting(default_factory=list, max_length=1000)
    #: Start the ROS tutorial nodes (talker, listener, add_two_ints, fibonacci), as
    #: ``--demo-nodes`` does.
    demo_nodes: bool = False
    #: Floor patches with their own slip, for robots under a realism profile (issue 26).
    floor: list[FloorPatch] = setting(default_factory=list, max_length=1000)

    def check(self) -> None:
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
            return
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


#: Value types of the server settings. Each bound is written once, here, and holds alike for
#: ``ServerSettings(...)``, the command line and the ``SIMBRIDGE_*`` environment variables.
#: A TCP port; 0 picks a free one.
Port = Annotated[int, Bounds(ge=0, le=65535)]
Count = Annotated[int, Bounds(gt=0)]
Seconds = Annotated[float, Bounds(gt=0)]
Rate = Annotated[float, Bounds(gt=0)]
LogLevel = Literal["debug", "info", "warning", "error"]


def _foxglove_scope(value: Any) -> Any:
    """The access of a Foxglove port: ``admin``, ``*`` or a robot name."""
    if (
        value is None
        or value in ("admin", "*")
        or (isinstance(value, str) and ROBOT_NAME.match(value))
    ):
        return value
    msg = f"{value!r} is not an access: give 'admin', '*' or a robot name (e.g. r1)"
    raise ValueError(msg)


class ServerSettings(Record, frozen=True):
    """Network and limit settings of one simbridge process (command-line options).

    Validated like the files: ``ServerSettings(stall_timeout=-5)`` raises
    :class:`ValidationError` naming the field; :func:`server_settings` says they are settings.
    Frozen: validated once, never changed.
    """

    host: str = "0.0.0.0"
    port: Port = 9090
    http_port: Port | None = 8080
    #: Largest incoming WebSocket message, bytes (rosbridge's max_message_size is 10 MB).
    max_message_size: Count = 10_000_000
    #: Pending outgoing bytes per client before the oldest queued messages are dropped.
    max_queue_bytes: Count = 8_000_000
    #: Pending messages per subscription when the client asked for queue_length 0.
    default_queue_length: Count = 100
    #: Seconds a service call may wait for a client provider when the call gives no timeout.
    service_timeout: Seconds = 5.0
    #: WebSocket keepalive ping interval and timeout, seconds (None disables).
    ping_interval: Seconds | None = 20.0
    ping_timeout: Seconds | None = 20.0
    #: Token the instructor's /admin needs for every change (None: every change is refused).
    admin_token: str | None = None
    #: Stamp headers with simulated time (``/clock``) instead of the wall clock.
    use_sim_time: bool = False
    #: Start the ROS tutorial nodes (also ``demo_nodes: true`` in the world file).
    demo_nodes: bool = False
    # -- reliability and security (docs/security.md); admin_token above also guards the
    # administrative ROS services (when it is None they are open: a laptop on its own) --
    #: Connected WebSocket clients at most; one more is refused with HTTP 503.
    max_clients: Count = 200
    #: Open connections of the HTTP port at most (page, /healthz, /admin); when all are busy
    #: one more is refused with 503, else the longest-idle keep-alive one is closed for it.
    max_http_connections: Count = 256
    #: Open connections of the HTTP port from one client address (an IPv6 address: its /64)
    #: at most, by the same rule. A request with the admin token is never refused for want of
    #: room, whatever fills the pool (docs/security.md, "HTTP").
    max_http_connections_per_address: Count = 16
    #: Subscribed topic spellings per client at most.
    max_subscriptions: Count = 200
    #: Advertised topics, services and actions per client at most.
    max_advertisements: Count = 100
    #: Budgets of what one client may make the server hold (docs/security.md), and what all
    #: clients together may (``global_*``). Subscribe ids over every topic, and on one topic:
    max_subscribe_ids: Count = 1_000
    max_ids_per_subscription: Count = 100
    global_subscribe_ids: Count = 20_000
    #: Advertise ids over every topic.
    max_advertise_ids: Count = 1_000
    global_advertise_ids: Count = 20_000
    #: Calls waiting for a client provider, and the longest wait (seconds; ``timeout: 0`` too).
    max_pending_calls: Count = 100
    global_pending_calls: Count = 2_000
    max_call_timeout: Seconds = 60.0
    #: Incomplete fragmented messages per client; their bytes (UTF-8) are bounded per client
    #: by max_message_size and for all clients by global_fragment_bytes.
    max_fragment_sets: Count = 16
    global_fragment_bytes: Count = 40_000_000
    #: Length of one frame (or reassembled fragmented message) of a client without the admin
    #: token, at most max_message_size; longer ones are refused before parsing.
    max_frame_bytes: Count = 1_000_000
    #: JSON values in one frame (or reassembled fragmented message) of a client without the
    #: admin token, each object counting 32 and each array 4; more are refused before parsing
    #: (one frame is handled in one go).
    max_frame_values: Count = 100_000
    #: Bytes of latched messages (JSON) a client's publishes leave on the server.
    max_latched_bytes: Count = 16_000_000
    global_latched_bytes: Count = 64_000_000
    #: ``status`` refusals per client per second (one per cause per second); the rest counted.
    statuses_per_second: Count = 10
    #: Share of the loop's time one client's incoming frames may take (0.25: a quarter).
    client_work_share: float = setting(default=0.25, gt=0, le=1)
    #: Sustained ``publish`` ops per second per client, and the burst allowed above it.
    publish_rate: Rate = 200.0
    publish_burst: Count = 400
    #: Sustained incoming WebSocket messages per second per client, and the burst.
    message_rate: Rate = 1000.0
    message_burst: Count = 2000
    #: Seconds a client may go without reading while messages wait for it; then it is
    #: disconnected (None: never).
    stall_timeout: Seconds | None = 30.0
    #: Seconds a connection that owes a token (no ``?token=`` on a server that requires one)
    #: has to authenticate with the ``auth`` op; then it is closed.
    auth_timeout: Seconds = 5.0
    #: Connections that owe a token, at most at once (their own pool: they never take the
    #: slots of ``max_clients`` that authenticated students need).
    max_unauthenticated: Count = 20
    #: TF requests (``/republish_tfs`` topics and ``/tf2_web_republisher`` goals) per client.
    tf_requests_per_client: Count = 10
    #: Transforms a second (frames x rate) one client's TF requests may send, and all clients'.
    tf_transforms_per_client: Rate = 1000.0
    tf_transforms_total: Rate = 10000.0
    #: Longest ``timeout`` of a ``/republish_tfs`` topic without subscribers, seconds.
    tf_max_timeout: Seconds = 60.0
    # -- issue 29: what a client makes the server hold, in length, count and age, and what one
    # token's connections may take together (docs/security.md, "Ids, goals, answers, latches
    # and tokens") --
    #: Length of an op's ``id`` (characters of a string, digits of an integer): ids are kept
    #: (subscriptions, advertisements, calls, goals) and echoed; a longer one is refused.
    max_id_length: Count = 1_000
    #: Goals of one client in flight, and of all clients; the longest a goal to an action that
    #: a client serves may wait for its result, seconds (then it is aborted).
    max_pending_goals: Count = 100
    global_pending_goals: Count = 2_000
    max_goal_timeout: Seconds = 600.0
    #: Names (parameters, prefixes) in one request to a node's parameter services: each answer
    #: is bounded before it is built.
    max_parameter_names: Count = 1_000
    #: E-stop latches kept at once; past it, a stop of robots that are held already is
    #: answered without a new latch (a stop of a robot that is not held always latches).
    max_estop_latches: Count = 200
    #: WebSocket connections of one token at once; they share one ``client_work_share``. The
    #: connections of a token with admin rights are not counted in ``max_clients``.
    max_connections_per_token: Count = 20
    #: Client tokens (query parameter ``?token=``): token -> scope. A scope is ``"*"`` (any
    #: topic) or a robot name (publish only under ``/<name>/``). Empty: no client tokens.
    client_tokens: dict[str, str] = setting(default_factory=dict)
    #: rosauth shared secret for the ``auth`` op (None: the op is refused).
    auth_secret: str | None = None
    #: Seconds of clock difference an ``auth`` op's ``t`` may have (rosauth's allowed_time_delta).
    auth_time_delta: Seconds = 5.0
    #: Allowed ``Origin`` headers of WebSocket upgrades (None: any; browsers only send one).
    allowed_origins: tuple[str, ...] | None = None
    #: TLS certificate chain and private key (PEM): serve wss:// and https://.
    certfile: str | None = None
    keyfile: str | None = None
    # -- ROS 2 peers (--zenoh; docs/security.md "ROS 2 peers") --
    #: The access of whatever reaches the graph from ROS 2: ``"none"`` (it reads; it may not
    #: drive, call administrative services or another robot's), ``"robot:NAME"`` (robot NAME,
    #: as that student's token), ``"robots"`` (every robot, no administration) or
    #: ``"admin"``; None: as a client without a token, and ``"none"`` in class mode (client
    #: tokens or a rosauth secret set).
    ros2_role: str | None = setting(default=None, before=check_ros2_role)
    #: Bytes of one Zenoh sample (message, request or reply) at most; bigger ones are dropped.
    zenoh_max_sample_bytes: Count = 1_000_000
    #: Bytes of Zenoh samples waiting for the event loop at most (past it, the oldest are dropped).
    zenoh_inbox_bytes: Count = 16_000_000
    #: Liveliness tokens of other processes (their nodes, topics, services) kept at most.
    zenoh_max_remote_tokens: Count = 20_000
    # -- ROS 2 over DDS (--dds, the [dds] extra; docs/dds.md) --
    #: Bytes of one DDS sample from another participant at most; bigger ones are dropped.
    dds_max_sample_bytes: Count = 1_000_000
    #: Bytes of DDS samples waiting for the event loop at most (past it, new ones are dropped).
    dds_inbox_bytes: Count = 16_000_000
    #: Writers and readers of other participants kept at most (each) from DDS discovery.
    dds_max_remote_endpoints: Count = 20_000
    # -- the Foxglove WebSocket protocol (the [foxglove] extra; README "Foxglove, Lichtblick and
    # PlotJuggler") --
    #: Port of the Foxglove WebSocket protocol (``foxglove.sdk.v1``) beside rosbridge (None: off).
    foxglove_port: Port | None = None
    #: Access of every client of the Foxglove port: ``admin``, ``*`` or a robot name. The
    #: protocol carries no token, so with client tokens or a rosauth secret (a class) the port
    #: stays closed unless this opens it; without them, None gives what a rosbridge client
    #: without a token gets.
    foxglove_scope: str | None = setting(default=None, before=_foxglove_scope)
    #: Connections of the Foxglove port at most (the SDK has no cap of its own: simbridge closes
    #: each one past it, the newest first, within a tick of seeing it; see docs/security.md).
    foxglove_max_clients: Count = 200
    # -- grading (simbridge.grading): tasks, and the journal of the class's attempts --
    #: The results journal (JSON lines, appended, read back at start); None: results are
    #: kept in memory only. The runs' bags go beside it, in ``<name>-bags/``.
    results_file: str | None = None
    #: Directory of the instructor's task files (``*.yaml``); None: the bundled config/tasks.
    tasks_dir: str | None = None
    #: Attempts one robot may have in the results (each is kept with its response, ~15 kB);
    #: past it a start is refused naming this setting.
    grading_max_attempts: Count = 200

    def check(self) -> None:
        """Check that a Foxglove port in a class was opened on purpose (``foxglove_scope``)."""
        if self.foxglove_port is not None and self.auth_required and self.foxglove_scope is None:
            msg = (
                "foxglove_port: the Foxglove protocol carries no token, so in a class (client "
                "tokens or an auth secret) the port stays closed; open it for every Foxglove "
                "client with foxglove_scope (--foxglove-scope admin, * or a robot name)"
            )
            raise ValueError(msg)

    @property
    def auth_required(self) -> bool:
        """Whether clients must authenticate (a client token or a rosauth MAC)."""
        return bool(self.client_tokens) or self.auth_secret is not None


def server_settings(**values: Any) -> ServerSettings:
    """Return validated :class:`ServerSettings`.

    Raises:
        ConfigError: a value is out of its bounds or of the wrong type, or a name is unknown;
            the text names each (``settings: stall_timeout: must be greater than 0 (got -5)``).
    """
    try:
        return ServerSettings(**values)
    except ValidationError as err:
        raise ConfigError(f"settings: {err}") from None


def parse_value(kind: Any, text: str) -> Any:
    """Return ``text`` as a value of ``kind`` (:data:`Port`, :data:`Count`, :data:`Seconds`...).

    Raises:
        ValidationError: the text is not such a value (a ``ValueError``); the message says why,
            in the words of the settings' own errors (``must be greater than 0 (got '-5')``).
    """
    return converter(kind)(text)


class Environment(Record, frozen=True):
    """The ``SIMBRIDGE_*`` environment variables of the ``simbridge`` command, validated.

    Each field is the variable without its prefix, lower-cased (``SIMBRIDGE_MAX_CLIENTS`` ->
    ``max_clients``); unset or empty variables are None (the option's default applies). The
    command line wins over the environment.
    """

    host: str | None = None
    port: Port | None = None
    http_port: Port | None = None
    world: str | None = None
    params: str | None = None
    client_tokens: str | None = None
    auth_secret_file: str | None = None
    allowed_origins: str | None = None
    certfile: str | None = None
    keyfile: str | None = None
    max_clients: Count | None = None
    max_http_connections: Count | None = None
    max_http_connections_per_address: Count | None = None
    max_message_size: Count | None = None
    stall_timeout: Seconds | None = None
    ping_interval: Seconds | None = None
    admin_token: str | None = None
    use_sim_time: bool | None = None
    demo_nodes: bool | None = None
    no_sim: bool | None = None
    zenoh: bool | None = None
    dds: bool | None = None
    ros2_role: str | None = None
    record: str | None = None
    log_level: LogLevel | None = None
    foxglove_port: Port | None = None
    foxglove_scope: str | None = None
    foxglove_max_clients: Count | None = None
    results: str | None = None
    tasks: str | None = None

    @classmethod
    def read(cls, environ: Mapping[str, str]) -> Environment:
        """Validate the variables of ``environ`` (e.g. ``os.environ``) that this command reads.

        Raises:
            ConfigError: a variable's value is invalid; the text names the variable, the value
                and the bound, e.g. ``environment variable SIMBRIDGE_STALL_TIMEOUT: must be
                greater than 0 (got '-5')``.
        """
        values = {
            name: environ[f"SIMBRIDGE_{name.upper()}"]
            for name in cls.settings()
            if environ.get(f"SIMBRIDGE_{name.upper()}", "").strip()
        }
        try:
            return cls.parse(values)
        except ValidationError as err:
            text = err.describe(lambda loc: f"environment variable SIMBRIDGE_{loc.upper()}")
            raise ConfigError(text) from None


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
    (tests/test_config.py keeps them equal), so they need no YAML parser.

    Raises:
        ConfigError: the file is missing, not YAML, or a key or value is invalid.
    """
    if path is None:
        return Params()
    p = Path(path)
    data = _read_yaml(p, "params")
    try:
        return Params.parse(data)
    except ValidationError as err:
        raise ConfigError(f"params file '{p}': {err}") from None


def load_world(path: Path | str | None = None) -> WorldSpec:
    """Load and validate a world file; ``None``: the default world (:data:`DEFAULT_WORLD`).

    The default world is the bundled ``worlds/default.yaml`` (tests/test_config.py keeps them
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
    except ValidationError as err:
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
