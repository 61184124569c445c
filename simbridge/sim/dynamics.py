"""A dynamic differential-drive model: wheel motors with a torque limit and a velocity loop.

The course's default is the kinematic model (:mod:`simbridge.sim.kinematics`): a command is
applied at once. This model makes mass and inertia matter (the bonus task perturbs them to show
payload sensitivity). Symbols: ``m`` mass (``robot.mass``), ``I`` moment of inertia about the
vertical axis (``robot.inertia``), ``r`` wheel radius, ``b`` wheelbase, ``tau_max`` the torque
limit of each motor (``robot.max_wheel_torque``), ``k`` the gain of each motor's velocity loop
(``robot.velocity_gain``, N m per m/s of wheel-speed error).

Each wheel's ground speed and its target (from the clamped command ``v*``, ``omega*``)::

    v_r = v + omega * b/2        v_r* = v* + omega* * b/2
    v_l = v - omega * b/2        v_l* = v* - omega* * b/2

Each motor's velocity loop asks for a torque proportional to its speed error, limited::

    tau_i = clamp(k * (v_i* - v_i), -tau_max, +tau_max)        F_i = tau_i / r

and the body accelerates by Newton's laws (no wheel slip, no rolling resistance)::

    dv/dt     = (F_r + F_l) / m
    domega/dt = (F_r - F_l) * (b/2) / I

Consequences a test or a student can check:

* torque-limited (large error): ``|dv/dt| = 2 tau_max / (r m)``, ``|domega/dt| = tau_max b /
  (r I)``: double the mass, half the acceleration;
* small errors: first-order approach with time constants ``T_v = r m / (2 k)`` and
  ``T_omega = 2 r I / (k b^2)``.

Integration: each step ``dt`` is split into substeps of at most :data:`MAX_SUBSTEP` seconds;
per substep the velocities are updated first (never carried past their target, so the loop
cannot oscillate numerically however small ``m`` or ``I``; within :data:`SNAP` of it they take
the target exactly, so a stopped robot reports 0), then the pose by the kinematic
equations at the new velocities (semi-implicit Euler). The reported twist is the body velocity.
"""

from __future__ import annotations

import math

from simbridge.sim.kinematics import RobotState, integrate
from simbridge.sim.parameters import RobotLike


__all__ = ["MAX_SUBSTEP", "DynamicModel"]

#: Longest integration substep, seconds.
MAX_SUBSTEP = 0.005


def _clamp(x: float, limit: float) -> float:
    return max(-limit, min(limit, x))


#: Velocity error (m/s, rad/s) below which the loop has reached its target.
SNAP = 1e-6


def _toward(value: float, rate: float, target: float, h: float) -> float:
    """Return ``value + rate * h`` without passing ``target`` (and snapped to it when close)."""
    new = value + rate * h
    if (value - target) * (new - target) < 0.0 or abs(new - target) < SNAP:
        return target
    return new


class DynamicModel:
    """Wheel motors with a torque limit and a velocity loop (equations in the module doc)."""

    name = "dynamic"

    def step(self, state: RobotState, v: float, omega: float, dt: float, params: RobotLike) -> None:
        """Advance ``state`` by ``dt`` toward the (clamped) command ``v``, ``omega``."""
        n = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
        h = dt / n
        half_b = params.wheelbase / 2.0
        k, tau_max, r = params.velocity_gain, params.max_wheel_torque, params.wheel_radius
        target_r, target_l = v + omega * half_b, v - omega * half_b
        for _ in range(n):
            wheel_r = state.v + state.omega * half_b
            wheel_l = state.v - state.omega * half_b
            force_r = _clamp(k * (target_r - wheel_r), tau_max) / r
            force_l = _clamp(k * (target_l - wheel_l), tau_max) / r
            accel = (force_r + force_l) / params.mass
            alpha = (force_r - force_l) * half_b / params.inertia
            new_v = _toward(state.v, accel, v, h)
            new_omega = _toward(state.omega, alpha, omega, h)
            integrate(state, new_v, new_omega, h)
