from __future__ import annotations

import math

import pytest

from simbridge.app.config import RobotParams
from simbridge.sim import DynamicModel, RobotState


def run(params: RobotParams, v: float, w: float, steps: int, dt: float = 0.05) -> RobotState:
    state = RobotState()
    model = DynamicModel()
    for _ in range(steps):
        model.step(state, v, w, dt, params)
    return state


def test_torque_limited_acceleration_is_2_tau_over_r_m() -> None:
    """A large step saturates both motors: dv/dt = 2 tau_max / (r m); double m, half of it."""
    p = RobotParams()
    a = 2 * p.max_wheel_torque / (p.wheel_radius * p.mass)
    assert run(p, 0.5, 0.0, 1).v == pytest.approx(a * 0.05)
    heavy = p.replace(mass=2 * p.mass)
    assert run(heavy, 0.5, 0.0, 1).v == pytest.approx(a * 0.05 / 2)


def test_torque_limited_angular_acceleration_is_tau_b_over_r_i() -> None:
    p = RobotParams(max_angular_velocity=50)
    alpha = p.max_wheel_torque * p.wheelbase / (p.wheel_radius * p.inertia)
    assert run(p, 0.0, 40.0, 1, dt=0.01).omega == pytest.approx(alpha * 0.01)


def test_small_error_approaches_target_with_time_constant_r_m_over_2k() -> None:
    p = RobotParams()
    tv = p.wheel_radius * p.mass / (2 * p.velocity_gain)
    state = RobotState(v=0.4)
    DynamicModel().step(state, 0.5, 0.0, tv, p)  # unsaturated: error 0.1 m/s < tau_max/k
    # one time constant removes 1 - 1/e of the error (semi-implicit 5 ms substeps: within 3 %)
    assert 0.5 - state.v == pytest.approx(0.1 / math.e, rel=0.03)


def test_reaches_and_holds_the_command_without_overshoot_even_when_very_light() -> None:
    for mass, inertia in ((1.5, 0.0075), (0.01, 1e-5)):
        p = RobotParams(mass=mass, inertia=inertia)
        state, model = RobotState(), DynamicModel()
        seen = []
        for _ in range(40):
            model.step(state, 0.5, 2.0, 0.05, p)
            seen.append((state.v, state.omega))
        assert all(v <= 0.5 and w <= 2.0 for v, w in seen)
        assert seen == sorted(seen)  # monotonic approach: no numerical oscillation
        assert seen[-1] == pytest.approx((0.5, 2.0))


def test_pose_follows_the_body_velocity() -> None:
    s = run(RobotParams(), 0.3, 0.0, 60)
    assert s.v == pytest.approx(0.3)
    assert s.y == 0.0 and 0.3 * 3.0 - 0.1 < s.x < 0.3 * 3.0
