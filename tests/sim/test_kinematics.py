from __future__ import annotations

import math

import pytest

from simbridge.sim.kinematics import RobotState, clamp_command, integrate, wrap_angle


def test_integrate_follows_the_course_equations_with_the_heading_at_step_start() -> None:
    """X += v cos(theta) dt; y += v sin(theta) dt; theta += omega dt."""
    s = RobotState(x=1.0, y=-2.0, theta=0.3)
    integrate(s, 0.4, 0.7, 0.05)
    assert s.x == pytest.approx(1.0 + 0.4 * math.cos(0.3) * 0.05)
    assert s.y == pytest.approx(-2.0 + 0.4 * math.sin(0.3) * 0.05)
    assert s.theta == pytest.approx(0.3 + 0.7 * 0.05)
    assert (s.v, s.omega) == (0.4, 0.7)


def test_straight_line_for_two_seconds_at_20_hz_covers_v_times_t() -> None:
    """40 steps of 0.05 s at 0.3 m/s advance x by 0.6 m exactly."""
    s = RobotState()
    for _ in range(40):
        integrate(s, 0.3, 0.0, 0.05)
    assert s.x == pytest.approx(0.6)
    assert s.y == 0.0


def test_heading_stays_wrapped_into_minus_pi_to_pi() -> None:
    """A full turn and a half leaves theta in [-pi, pi)."""
    s = RobotState()
    for _ in range(300):
        integrate(s, 0.0, 2.0, 0.05)
    assert -math.pi <= s.theta < math.pi
    assert s.theta == pytest.approx(wrap_angle(30.0))


def test_clamp_command_limits_both_directions() -> None:
    """Commands are clamped to +-max, inside values pass unchanged."""
    assert clamp_command(2.0, -9.0, 0.5, 2.5) == (0.5, -2.5)
    assert clamp_command(-2.0, 9.0, 0.5, 2.5) == (-0.5, 2.5)
    assert clamp_command(0.1, 0.2, 0.5, 2.5) == (0.1, 0.2)


@pytest.mark.parametrize(
    ("angle", "wrapped"),
    [(0.0, 0.0), (math.pi, -math.pi), (-math.pi, -math.pi), (3 * math.pi, -math.pi)],
)
def test_wrap_angle_maps_onto_half_open_interval(angle: float, wrapped: float) -> None:
    """wrap_angle returns the equivalent angle in [-pi, pi)."""
    assert wrap_angle(angle) == pytest.approx(wrapped)
