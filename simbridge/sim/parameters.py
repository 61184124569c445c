"""What the simulator reads of its parameters: plain attributes, whoever declares them.

The simulator imports no settings framework: it takes any objects with these attributes (the
settings records of :mod:`simbridge.app.config` have them, validated; a test may pass its own).
``replace`` returns a changed copy and raises ``ValueError`` for a refused value (an error
with a ``within(key)`` method, as the settings' own, gets its paths put under ``key``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any, Protocol, Self


__all__ = [
    "ROBOT_NAME",
    "FloorPatchLike",
    "LidarLike",
    "ParamsLike",
    "RealismLike",
    "RobotLike",
    "SimLike",
    "WorldLike",
    "check_robot_name",
    "within",
]

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


def within(err: ValueError, key: str) -> ValueError:
    """Return ``err`` with its paths under ``key`` (``mass`` -> ``robot.mass``) if it has any."""
    under = getattr(err, "within", None)
    out = under(key) if callable(under) else None
    return out if isinstance(out, ValueError) else ValueError(f"{key}: {err}")


class RobotLike(Protocol):
    """A differential-drive robot's parameters (SI units)."""

    mass: float
    wheel_radius: float
    wheelbase: float
    inertia: float
    max_linear_velocity: float
    max_angular_velocity: float
    radius: float
    max_wheel_torque: float
    velocity_gain: float

    def replace(self, **changes: Any) -> Self:
        """Return a copy with ``changes`` (``ValueError`` for a refused one)."""
        ...


class LidarLike(Protocol):
    """A 2D LiDAR's parameters (REP-117 ranges)."""

    rays: int
    range_min: float
    range_max: float
    mount: tuple[float, float, float]
    noise_stddev: float
    dropout: float


class RealismLike(Protocol):
    """A realism profile: motor lag, deadband, slip, geometry, encoders (:mod:`.realism`)."""

    enabled: bool
    cmd_latency: float
    motor_time_constant: float
    deadband: float
    wheel_speed_scale: float
    slip: float
    slip_stddev: float
    wheel_radius_left: float
    wheel_radius_right: float
    wheelbase: float
    encoder_ticks: int
    seed: int

    def replace(self, **changes: Any) -> Self:
        """Return a copy with ``changes`` (``ValueError`` for a refused one)."""
        ...


class SimLike(Protocol):
    """The loop's parameters."""

    rate: float


class ParamsLike(Protocol):
    """The parameter groups the simulator reads."""

    @property
    def robot(self) -> RobotLike:
        """The robot group."""
        ...

    @property
    def lidar(self) -> LidarLike:
        """The lidar group."""
        ...

    @property
    def sim(self) -> SimLike:
        """The sim group."""
        ...

    @property
    def realism(self) -> RealismLike:
        """The realism group."""
        ...


class FloorPatchLike(Protocol):
    """A patch of floor with its own slip: a polygon in the world frame."""

    @property
    def polygon(self) -> Sequence[tuple[float, float]]:
        """The polygon values."""
        ...

    slip: float


class WorldLike(Protocol):
    """A world: its wall segments, robots at start and floor patches."""

    @property
    def floor(self) -> Sequence[FloorPatchLike]:
        """The floor values."""
        ...

    def segments(self) -> list[tuple[float, float, float, float]]:
        """Every wall and obstacle edge as ``(x1, y1, x2, y2)``."""
        ...

    def start_poses(self) -> dict[str, tuple[float, float, float]]:
        """The robots at start by name (``""``: the single un-namespaced robot)."""
        ...

    def start_realism(self) -> dict[str, dict[str, object]]:
        """Each robot's own realism values (robots without: absent)."""
        ...
