"""Differential-drive motion: the course's kinematic model.

At each fixed step ``dt`` (0.05 s at 20 Hz), with ``v`` and ``omega`` the last commanded
velocities clamped to the robot's limits::

    x     += v * cos(theta) * dt
    y     += v * sin(theta) * dt
    theta += omega * dt

(explicit Euler, using the heading at the start of the step). ``theta`` is kept in
``[-pi, pi)``, REP-103 (x forward, y left, counter-clockwise positive).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


__all__ = ["RobotState", "clamp_command", "integrate", "wrap_angle"]


def wrap_angle(theta: float) -> float:
    """Return ``theta`` wrapped into ``[-pi, pi)``."""
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


def clamp_command(v: float, omega: float, max_v: float, max_omega: float) -> tuple[float, float]:
    """Clamp a velocity command to ``[-max_v, max_v]`` and ``[-max_omega, max_omega]``.

    Non-finite values are not clamped here: callers refuse them before they reach a robot.
    """
    return max(-max_v, min(max_v, v)), max(-max_omega, min(max_omega, omega))


@dataclass(slots=True)
class RobotState:
    """Pose and applied body velocity of one robot, in frame ``odom``."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    #: Applied (clamped) linear velocity, m/s: what /odom reports as twist.
    v: float = 0.0
    #: Applied (clamped) angular velocity, rad/s.
    omega: float = 0.0


def integrate(state: RobotState, v: float, omega: float, dt: float) -> None:
    """Advance ``state`` by one step of the kinematic model at velocities ``v``, ``omega``."""
    state.x += v * math.cos(state.theta) * dt
    state.y += v * math.sin(state.theta) * dt
    state.theta = wrap_angle(state.theta + omega * dt)
    state.v = v
    state.omega = omega
