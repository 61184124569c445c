"""The simulated world: wall segments and differential-drive robots with a LiDAR each.

A :class:`World` is deterministic given its seed and the sequence of calls: it has no clock and
no I/O. The runner calls :meth:`World.step` at the fixed rate ``params.sim.rate``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from simbridge.sim.collision import Contact, pose_clear, resolve_moves
from simbridge.sim.kinematics import RobotState, clamp_command, integrate, wrap_angle
from simbridge.sim.lidar import FloatArray, beam_angles, raycast_batch, segments_array
from simbridge.sim.parameters import (
    ParamsLike,
    RealismLike,
    RobotLike,
    WorldLike,
    check_robot_name,
    within,
)
from simbridge.sim.realism import Floor, Plant


__all__ = ["PER_ROBOT_PARAMS", "KinematicModel", "MotionModel", "Robot", "World"]

logger = logging.getLogger(__name__)

#: Command magnitude (m/s or rad/s) refused outright rather than clamped to the limits.
ABSURD_VELOCITY = 1000.0
#: Robot parameters one robot may have of its own (:meth:`World.set_robot_params`). The
#: footprint radius is shared (collisions and scans use one radius), and so is the cmd_vel type.
PER_ROBOT_PARAMS = frozenset(
    {
        "mass",
        "inertia",
        "wheel_radius",
        "wheelbase",
        "max_linear_velocity",
        "max_angular_velocity",
        "max_wheel_torque",
        "velocity_gain",
    }
)


class MotionModel(Protocol):
    """How commanded velocities move a robot during one step."""

    #: Short name shown to users (``kinematic``...).
    name: str

    def step(self, state: RobotState, v: float, omega: float, dt: float, params: RobotLike) -> None:
        """Advance ``state`` by ``dt`` toward the (already clamped) command ``v``, ``omega``."""


class KinematicModel:
    """The course's model: the commanded velocity is applied at once (no mass, no inertia)."""

    name = "kinematic"

    def step(self, state: RobotState, v: float, omega: float, dt: float, params: RobotLike) -> None:
        """Integrate the kinematic equations (see :mod:`simbridge.sim.kinematics`)."""
        integrate(state, v, omega, dt)


@dataclass(slots=True)
class Robot:
    """One robot: its name (``""`` for the single un-namespaced robot), start pose and state."""

    name: str
    start: tuple[float, float, float]
    state: RobotState = field(default_factory=RobotState)
    #: Last received command (finite, not yet clamped: limits may change at run time).
    cmd_v: float = 0.0
    cmd_omega: float = 0.0
    #: This robot's own values of :data:`PER_ROBOT_PARAMS` (a heavier robot for one group),
    #: over the shared ``params.robot``; empty: the shared parameters.
    overrides: dict[str, float] = field(default_factory=dict)
    #: The shared parameters and this robot's parameters made from them (rebuilt when the
    #: shared ones are replaced).
    cached: tuple[RobotLike, RobotLike] | None = None
    #: This robot's own realism values (names without ``realism.``) over the shared
    #: ``params.realism``: "group 3 drives the worn robot"; empty: the shared profile.
    realism_own: dict[str, object] = field(default_factory=dict)
    #: The shared realism values and this robot's made from them.
    realism_cached: tuple[RealismLike, RealismLike] | None = None
    #: Its motors, wheels and encoders while it is under a realism profile (else None: /odom
    #: is the true pose).
    plant: Plant | None = None

    def realism(self, shared: RealismLike) -> RealismLike | None:
        """Return the realism profile this robot moves under, or None (the ideal model)."""
        if not self.realism_own:
            return shared if shared.enabled else None
        if self.realism_cached is None or self.realism_cached[0] is not shared:
            self.realism_cached = (shared, shared.replace(**self.realism_own))
        own = self.realism_cached[1]
        return own if own.enabled else None

    def odometry(self) -> RobotState:
        """Return what ``/odom`` reports: the encoders' estimate under a profile, else the truth."""
        return self.state if self.plant is None else self.plant.odom

    def params(self, shared: RobotLike) -> RobotLike:
        """Return the parameters this robot moves with: ``shared`` with its overrides."""
        if not self.overrides:
            return shared
        if self.cached is None or self.cached[0] is not shared:
            own = shared.replace(**self.overrides)
            self.cached = (shared, own)
        return self.cached[1]

    def frame(self, frame: str) -> str:
        """Return the TF frame id ``frame`` of this robot (``r1/base_link`` when named)."""
        return f"{self.name}/{frame}" if self.name else frame

    def topic(self, topic: str) -> str:
        """Return this robot's topic name (``/r1/odom`` when named, else ``/odom``)."""
        return f"/{self.name}/{topic}" if self.name else f"/{topic}"

    def place(self, pose: tuple[float, float, float]) -> None:
        """Put the robot at ``pose``, stopped, with no pending command."""
        self.state = RobotState(x=pose[0], y=pose[1], theta=pose[2])
        self.cmd_v = 0.0
        self.cmd_omega = 0.0
        if self.plant is not None:
            self.plant.place(self.state)


#: Metres around the walls' bounding box where robots may still be placed (open layouts).
WORLD_MARGIN = 1.0
#: Metres around the start poses of a world without walls where robots may be placed.
OPEN_WORLD = 50.0
#: A robot without ranges kept (see World.scans).
_NO_ROW: tuple[None, None] = (None, None)


class World:
    """Walls and robots, stepped at a fixed ``dt``."""

    def __init__(self, spec: WorldLike, params: ParamsLike, *, seed: int = 0) -> None:
        #: The world file this world was built from.
        self.spec = spec
        #: Live parameters; a change applies at the next step or scan.
        self.params = params
        #: Every wall and obstacle edge, ``(N, 4)``.
        self.segments: FloatArray = segments_array(spec.segments())
        #: Robots by name.
        self.robots: dict[str, Robot] = {
            name: Robot(name, pose) for name, pose in spec.start_poses().items()
        }
        for name, own in spec.start_realism().items():
            self.robots[name].realism_own = own
        #: Robots that have had realism values of their own, and whether any robot has a plant:
        #: while neither (nor the shared profile), a step costs what it did before issue 26.
        self._own_realism = set(spec.start_realism())
        self._plants = False
        #: The world file's floor patches (their own slip, under a realism profile).
        self.floor = Floor(spec.floor)
        #: Contacts of the last step: (robot name, obstacle name or "wall", contact).
        self.contacts: list[tuple[str, str, Contact]] = []
        #: Robots whose motion an obstacle stopped (fully or partly) in the last step.
        self.touching: set[str] = set()
        #: How commands move robots.
        self.motion: MotionModel = KinematicModel()
        #: Simulated seconds since start (or the last reset).
        self.time = 0.0
        #: Robot updates that raised (each robot was reset).
        self.failures = 0
        #: Steps since start (or the last reset).
        self.steps = 0
        #: Emergency stop latched for every robot (also robots added later): commands are
        #: ignored and every robot is held still until :meth:`release_estop` (a world reset
        #: does not release it).
        self.estopped = False
        #: Robots held still by an emergency stop of their own (see :meth:`hold`).
        self.held: frozenset[str] = frozenset()
        self._seed = seed
        self._rng: np.random.Generator | None = None
        self._angles_key: tuple[int, float] | None = None
        self._angles: FloatArray = np.zeros(0)
        #: Each robot's last noiseless ranges with its laser pose, valid while the robots'
        #: positions and the LiDAR settings are :attr:`_scan_shared` (see :meth:`scans`).
        self._scan_rows: dict[str, tuple[tuple[float, float, float], FloatArray]] = {}
        self._scan_shared: tuple[object, ...] = ()
        for robot in self.robots.values():
            robot.place(robot.start)

    @property
    def rng(self) -> np.random.Generator:
        """Seeded noise source (LiDAR noise); reseeded by :meth:`reset` for repeatable runs."""
        # made on first use: numpy.random costs an idle server about 2.3 MB (issue 16), and a run
        # without noise (the default parameters) never draws from it; the draws are the same
        if self._rng is None:
            self._rng = np.random.default_rng(self._seed)
        return self._rng

    @property
    def dt(self) -> float:
        """The step length, seconds (0.05 at the default 20 Hz)."""
        return 1.0 / self.params.sim.rate

    def command(self, name: str, v: float, omega: float) -> tuple[float, float]:
        """Set a robot's velocity command; return it as clamped to the current limits.

        While the emergency stop is latched the command is dropped and ``(0, 0)`` returned.

        Raises:
            ValueError: a value is not finite (NaN or infinity never reaches the state) or is
                absurd (above :data:`ABSURD_VELOCITY`: a unit or overflow bug, not a wish).
            KeyError: no robot of that name.
        """
        if not (math.isfinite(v) and math.isfinite(omega)):
            msg = f"velocity command must be finite, got linear {v}, angular {omega}"
            raise ValueError(msg)
        if abs(v) > ABSURD_VELOCITY or abs(omega) > ABSURD_VELOCITY:
            msg = (
                f"velocity command linear {v:g}, angular {omega:g} is absurd (above "
                f"{ABSURD_VELOCITY:g}); commands within the limits are clamped to them"
            )
            raise ValueError(msg)
        robot = self.robots[name]
        if self.halted(name):
            return 0.0, 0.0
        real = robot.realism(self.params.realism)
        if real is not None:
            self._plant(robot).command(self.time, v, omega, real)
        robot.cmd_v, robot.cmd_omega = v, omega
        limits = self.robot_params(name)
        return clamp_command(v, omega, limits.max_linear_velocity, limits.max_angular_velocity)

    def step(self) -> None:
        """Advance every robot by one ``dt``; footprints never pass through walls or robots.

        Each robot's motion model proposes a move; :func:`~simbridge.sim.collision.
        resolve_moves` cuts it at the first contact (sliding along walls). A robot whose move
        was cut gets the speed it actually achieved along its heading, and the contact is
        listed in :attr:`contacts` for this step.

        A robot whose update raises, or leaves a non-finite state, is logged and put back at
        its start pose, stopped; the other robots and the loop go on.
        """
        dt = self.dt
        shared = self.params.robot
        shared_real = self.params.realism
        profiled = shared_real.enabled or bool(self._own_realism)
        if not profiled and self._plants:
            for robot in self.robots.values():
                robot.plant = None  # the ideal model again: /odom is the truth
            self._plants = False
        robots = list(self.robots.values())
        p0 = [(r.state.x, r.state.y) for r in robots]
        for i, robot in enumerate(robots):
            limits = robot.params(shared)
            if self.estopped or robot.name in self.held:
                robot.cmd_v = robot.cmd_omega = 0.0
                robot.state.v = robot.state.omega = 0.0
                if robot.plant is not None:
                    robot.plant.halt()
                continue
            real = None
            if profiled:  # else the ideal model's robots pay this test alone (bench.realism)
                real = robot.realism(shared_real)
                if real is None and robot.plant is not None:
                    robot.plant = None
            try:
                if real is not None:
                    s = robot.state
                    slip = (
                        self.floor.slip_at(s.x, s.y, real.slip) if self.floor.patches else real.slip
                    )
                    self._plant(robot).step(s, self.time, dt, limits, real, slip)
                else:
                    v, omega = clamp_command(
                        robot.cmd_v,
                        robot.cmd_omega,
                        limits.max_linear_velocity,
                        limits.max_angular_velocity,
                    )
                    self.motion.step(robot.state, v, omega, dt, limits)
                s = robot.state
                if not all(map(math.isfinite, (s.x, s.y, s.theta, s.v, s.omega))):
                    msg = f"non-finite state {s}"
                    raise FloatingPointError(msg)
            except Exception:
                logger.exception("robot '%s' failed to update: reset to its start pose", robot.name)
                robot.place(robot.start)
                p0[i] = (robot.state.x, robot.state.y)  # a reset is a jump, not a move to cut
                self.failures += 1
        self.contacts = []
        p1 = [(r.state.x, r.state.y) for r in robots]
        # robots start each step clear of each other and the walls: if none moves, none can
        # touch anything (idle robots, the common case in a class, cost no collision work)
        if p1 != p0 and (len(robots) > 1 or self.segments.shape[0]):
            start = np.array(p0, dtype=np.float64).reshape(-1, 2)
            proposed = np.array(p1, dtype=np.float64)
            final, contacts = resolve_moves(start, proposed, shared.radius, self.segments)
            for c in contacts:
                robot = robots[c.robot]
                s = robot.state
                x, y = float(final[c.robot, 0]), float(final[c.robot, 1])
                achieved = ((x - p0[c.robot][0]) * math.cos(s.theta)) + (
                    (y - p0[c.robot][1]) * math.sin(s.theta)
                )
                s.x, s.y = x, y
                s.v = achieved / dt if abs(achieved) < abs(s.v * dt) else s.v
                other = "wall" if c.other < 0 else robots[c.other].name
                self.contacts.append((robot.name, other, c))
        self.touching = {name for name, _, _ in self.contacts}
        self.time += dt
        self.steps += 1

    def _plant(self, robot: Robot) -> Plant:
        """Return robot's plant, made (at its true pose, with its command) when it has none."""
        plant = robot.plant
        if plant is None:
            own = robot.realism(self.params.realism) or self.params.realism
            plant = Plant(robot.name, robot.state, own.seed)
            plant.cmd = (robot.cmd_v, robot.cmd_omega)
            robot.plant = plant
            self._plants = True
        return plant

    def laser_pose(self, name: str) -> tuple[float, float, float]:
        """Return the pose of a robot's ``laser`` frame in ``odom`` (x, y, yaw)."""
        s = self.robots[name].state
        mx, my, myaw = self.params.lidar.mount
        c, si = math.cos(s.theta), math.sin(s.theta)
        return s.x + c * mx - si * my, s.y + si * mx + c * my, s.theta + myaw

    def angles(self) -> FloatArray:
        """Return the beam angles of the current LiDAR settings (cached)."""
        key = (self.params.lidar.rays, 0.0)
        if key != self._angles_key:
            self._angles = beam_angles(key[0], key[1])
            self._angles_key = key
        return self._angles

    def scan(self, name: str) -> npt.NDArray[np.float32]:
        """Return the LiDAR ranges of a robot as float32, in ``[range_min, range_max]``."""
        ranges: npt.NDArray[np.float32] = self.scans([name])[0]
        return ranges

    def scans(self, names: list[str]) -> npt.NDArray[np.float32]:
        """Return the LiDAR ranges of several robots at once, ``(len(names), rays)`` float32.

        Each scan sees the walls and every other robot's footprint (a disc of
        ``robot.radius``), never its own robot. All scans are cast in one batch
        (:func:`~simbridge.sim.lidar.raycast_batch`).
        """
        lidar = self.params.lidar
        radius = self.params.robot.radius
        centres_list = [(r.state.x, r.state.y) for r in self.robots.values()]
        poses_list = [self.laser_pose(n) for n in names]
        # The walls never change, so while no robot moved (nor a LiDAR setting) a robot's
        # noiseless ranges are its last ones: a parked robot's scan costs no raycast, whichever
        # robots are scanned with it (robots take turns).
        shared: tuple[object, ...] = (tuple(self.robots), tuple(centres_list))
        shared += (radius, lidar.rays, lidar.range_max)
        rows = self._scan_rows
        if shared != self._scan_shared:
            rows.clear()  # a robot moved (it is in every other robot's scan), or a setting
            self._scan_shared = shared
        stale = [k for k, name in enumerate(names) if rows.get(name, _NO_ROW)[0] != poses_list[k]]
        if stale:
            index = {n: i for i, n in enumerate(self.robots)}
            poses = np.array([poses_list[k] for k in stale], dtype=np.float64).reshape(-1, 3)
            centres = np.array(centres_list, dtype=np.float64).reshape(-1, 2)
            owners = np.array([index[names[k]] for k in stale], dtype=np.intp)
            raw = raycast_batch(
                poses[:, :2],
                poses[:, 2],
                lidar.rays,
                self.segments,
                lidar.range_max,
                circles=centres,
                circle_radius=radius,
                owners=owners,
            )
            raw.flags.writeable = False
            for j, k in enumerate(stale):
                rows[names[k]] = (poses_list[k], raw[j])
        rows_of = [rows[name][1] for name in names]
        ranges = np.stack(rows_of) if rows_of else np.zeros((0, lidar.rays))
        if lidar.noise_stddev > 0:
            ranges = ranges + self.rng.normal(0.0, lidar.noise_stddev, ranges.shape)
        if lidar.dropout > 0:
            # a ray with no echo reads as one with no wall within range
            ranges = np.where(
                self.rng.random(ranges.shape) < lidar.dropout, lidar.range_max, ranges
            )
        return np.clip(ranges, lidar.range_min, lidar.range_max).astype(np.float32)

    def estop(self) -> None:
        """Latch the emergency stop: every robot halts at once and ignores commands."""
        self.estopped = True
        for robot in self.robots.values():
            robot.cmd_v = robot.cmd_omega = 0.0
            robot.state.v = robot.state.omega = 0.0
            if robot.plant is not None:
                robot.plant.halt()

    def release_estop(self) -> None:
        """Release the emergency stop; robots stay still until the next command."""
        self.estopped = False

    def halted(self, name: str) -> bool:
        """Whether robot ``name`` is held by an emergency stop (its own or everyone's)."""
        return self.estopped or name in self.held

    def hold(self, names: frozenset[str]) -> None:
        """Hold exactly the robots ``names`` still (besides :attr:`estopped`).

        Newly held robots halt at once; robots not named are released (they stay still until
        commanded).
        """
        for name in names - self.held:
            robot = self.robots.get(name)
            if robot is not None:
                robot.cmd_v = robot.cmd_omega = 0.0
                robot.state.v = robot.state.omega = 0.0
                if robot.plant is not None:
                    robot.plant.halt()
        self.held = frozenset(names)

    def robot_params(self, name: str) -> RobotLike:
        """Return the motion parameters robot ``name`` moves with (its own, or the shared)."""
        robot = self.robots.get(name)
        return self.params.robot if robot is None else robot.params(self.params.robot)

    def set_robot_params(self, name: str, changes: dict[str, float | None]) -> RobotLike:
        """Give robot ``name`` values of its own; return the parameters it now moves with.

        ``changes`` are names of :data:`PER_ROBOT_PARAMS` (without ``robot.``), None meaning
        back to the shared value; all or nothing.

        Raises:
            KeyError: no robot of that name.
            ValueError: a name is not per-robot, or a value is out of range (nothing changes).
        """
        robot = self.robots[name]
        unknown = sorted(set(changes) - PER_ROBOT_PARAMS)
        if unknown:
            allowed = ", ".join(f"robot.{n}" for n in sorted(PER_ROBOT_PARAMS))
            msg = f"robot.{unknown[0]} is shared by every robot; a robot may have its own {allowed}"
            raise ValueError(msg)
        overrides = {**robot.overrides, **changes}
        kept = {k: v for k, v in overrides.items() if v is not None}
        try:
            own = self.params.robot.replace(**kept)
        except ValueError as err:
            raise within(err, "robot") from None
        robot.overrides = {k: getattr(own, k) for k in kept}
        robot.cached = (self.params.robot, own) if kept else None
        return own

    def set_robot_realism(self, name: str, changes: dict[str, object]) -> RealismLike:
        """Give robot ``name`` realism values of its own; return its profile (enabled or not).

        ``changes`` are :class:`~simbridge.sim.parameters.RealismLike` names (without ``realism.``),
        None meaning back to the shared value; all or nothing.

        Raises:
            KeyError: no robot of that name.
            ValueError: a name is unknown or a value out of range (nothing changes).
        """
        robot = self.robots[name]
        kept = {k: v for k, v in {**robot.realism_own, **changes}.items() if v is not None}
        try:
            own = self.params.realism.replace(**kept)
        except ValueError as err:
            raise within(err, "realism") from None
        robot.realism_own = {k: getattr(own, k) for k in kept}
        robot.realism_cached = None
        # kept after its values are cleared (a robot whose values are written back directly, as
        # the grader restores them, stays checked): a stale name costs the check, never a profile
        self._own_realism.add(name)
        if robot.plant is not None and "seed" in changes:
            robot.plant = None  # a new seed: a new generator (the plant starts at the truth)
        return own

    # -- robots at run time ----------------------------------------------------------------

    def bounds(self) -> tuple[float, float, float, float]:
        """The world's extent ``(x_min, y_min, x_max, y_max)``: where a robot may be placed.

        The box around every wall, obstacle and start pose, plus :data:`WORLD_MARGIN` (open
        layouts); a world without walls extends :data:`OPEN_WORLD` metres around its starts.
        """
        starts = np.array([p[:2] for p in self.spec.start_poses().values()], dtype=np.float64)
        if len(self.segments):
            points = np.vstack([self.segments[:, :2], self.segments[:, 2:4], starts])
            margin = WORLD_MARGIN
        else:
            points, margin = starts, OPEN_WORLD
        low = points.min(axis=0) - margin
        high = points.max(axis=0) + margin
        return float(low[0]), float(low[1]), float(high[0]), float(high[1])

    def check_pose(self, pose: tuple[float, float, float], *, ignore: str | None = None) -> None:
        """Refuse a pose outside the world or whose footprint would overlap a wall or robot.

        ``ignore`` is the robot being moved (its own footprint does not count). Other robots
        count at their current position and at their start pose (so /reset stays clear).

        Raises:
            ValueError: the pose is not finite or is not clear.
        """
        if not all(math.isfinite(v) for v in pose):
            msg = f"pose must be three finite numbers [x, y, theta], got {list(pose)}"
            raise ValueError(msg)
        x0, y0, x1, y1 = self.bounds()
        if not (x0 <= pose[0] <= x1 and y0 <= pose[1] <= y1):
            msg = (
                f"cannot place a robot at ({pose[0]:g}, {pose[1]:g}): outside the world "
                f"(x from {x0:g} to {x1:g}, y from {y0:g} to {y1:g})"
            )
            raise ValueError(msg)
        others = [
            p
            for r in self.robots.values()
            if r.name != ignore
            for p in ((r.state.x, r.state.y), (r.start[0], r.start[1]))
        ]
        why = pose_clear(
            pose[0],
            pose[1],
            self.params.robot.radius,
            self.segments,
            np.array(others, dtype=np.float64).reshape(-1, 2),
        )
        if why is not None:
            msg = f"cannot place a robot at ({pose[0]:g}, {pose[1]:g}): {why}"
            raise ValueError(msg)

    def spawn(self, name: str, pose: tuple[float, float, float]) -> Robot:
        """Add a robot at ``pose`` (also its start pose for /reset); return it.

        Raises:
            ValueError: the name is invalid or taken, or the pose is not clear.
        """
        check_robot_name(name)
        if name in self.robots:
            msg = f"a robot named '{name}' already exists; pick another name"
            raise ValueError(msg)
        self.check_pose(pose)
        start = (pose[0], pose[1], wrap_angle(pose[2]))
        robot = Robot(name, start)
        robot.place(start)
        self.robots[name] = robot
        return robot

    def remove(self, name: str) -> Robot:
        """Remove a robot; return it.

        Raises:
            KeyError: no robot of that name.
        """
        robot = self.robots.pop(name)
        self.touching.discard(name)
        self._own_realism.discard(name)
        return robot

    def teleport(self, name: str, pose: tuple[float, float, float]) -> None:
        """Move a robot to ``pose`` at once, stopped, keeping its start pose.

        Raises:
            KeyError: no robot of that name.
            ValueError: the pose is not clear.
        """
        robot = self.robots[name]
        self.check_pose(pose, ignore=name)
        robot.place((pose[0], pose[1], wrap_angle(pose[2])))

    def reset(self) -> None:
        """Put every robot back at its start pose, stopped; restart time and noise."""
        for robot in self.robots.values():
            robot.place(robot.start)
        self.contacts = []
        self.touching = set()
        self.time = 0.0
        self.steps = 0
        self._rng = None
