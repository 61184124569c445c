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

from simbridge.config import Params, RobotParams, WorldSpec
from simbridge.sim.kinematics import RobotState, clamp_command, integrate
from simbridge.sim.lidar import FloatArray, beam_angles, raycast, segments_array


__all__ = ["KinematicModel", "MotionModel", "Robot", "World"]

logger = logging.getLogger(__name__)

#: Command magnitude (m/s or rad/s) refused outright rather than clamped to the limits.
ABSURD_VELOCITY = 1000.0


class MotionModel(Protocol):
    """How commanded velocities move a robot during one step."""

    #: Short name shown to users (``kinematic``...).
    name: str

    def step(
        self, state: RobotState, v: float, omega: float, dt: float, params: RobotParams
    ) -> None:
        """Advance ``state`` by ``dt`` toward the (already clamped) command ``v``, ``omega``."""


class KinematicModel:
    """The course's model: the commanded velocity is applied at once (no mass, no inertia)."""

    name = "kinematic"

    def step(
        self, state: RobotState, v: float, omega: float, dt: float, params: RobotParams
    ) -> None:
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


class World:
    """Walls and robots, stepped at a fixed ``dt``."""

    def __init__(self, spec: WorldSpec, params: Params, *, seed: int = 0) -> None:
        #: The world file this world was built from.
        self.spec = spec
        #: Live parameters; a change applies at the next step or scan.
        self.params = params
        #: Every wall and obstacle edge, ``(N, 4)``.
        self.segments: FloatArray = segments_array(spec.segments())
        #: Robots by name.
        self.robots: dict[str, Robot] = {"": Robot("", spec.robot.pose)}
        #: How commands move robots.
        self.motion: MotionModel = KinematicModel()
        #: Simulated seconds since start (or the last reset).
        self.time = 0.0
        #: Robot updates that raised (each robot was reset).
        self.failures = 0
        #: Steps since start (or the last reset).
        self.steps = 0
        #: Seeded noise source (LiDAR noise); reseeded by reset for repeatable runs.
        self._seed = seed
        self.rng = np.random.default_rng(seed)
        self._angles_key: tuple[int, float] | None = None
        self._angles: FloatArray = np.zeros(0)
        for robot in self.robots.values():
            robot.place(robot.start)

    @property
    def dt(self) -> float:
        """The step length, seconds (0.05 at the default 20 Hz)."""
        return 1.0 / self.params.sim.rate

    def command(self, name: str, v: float, omega: float) -> tuple[float, float]:
        """Set a robot's velocity command; return it as clamped to the current limits.

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
        robot.cmd_v, robot.cmd_omega = v, omega
        limits = self.params.robot
        return clamp_command(v, omega, limits.max_linear_velocity, limits.max_angular_velocity)

    def step(self) -> None:
        """Advance every robot by one ``dt``.

        A robot whose update raises, or leaves a non-finite state, is logged and put back at
        its start pose, stopped; the other robots and the loop go on.
        """
        dt = self.dt
        limits = self.params.robot
        for robot in self.robots.values():
            try:
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
                self.failures += 1
        self.time += dt
        self.steps += 1

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
        lidar = self.params.lidar
        lx, ly, lyaw = self.laser_pose(name)
        ranges = raycast(lx, ly, lyaw, self.angles(), self.segments, lidar.range_max)
        if lidar.noise_stddev > 0:
            ranges = ranges + self.rng.normal(0.0, lidar.noise_stddev, ranges.shape[0])
        return np.clip(ranges, lidar.range_min, lidar.range_max).astype(np.float32)

    def reset(self) -> None:
        """Put every robot back at its start pose, stopped; restart time and noise."""
        for robot in self.robots.values():
            robot.place(robot.start)
        self.time = 0.0
        self.steps = 0
        self.rng = np.random.default_rng(self._seed)
