"""Step and path metrics from a trace, and the rubric's verdict (pure)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.grading.metrics import Trace, clearance, evaluate, resolve_goal, score
from simbridge.grading.task import Goal, Threshold, WallGoal


def heading_trace(overshoot: float, dt: float = 0.05, seconds: float = 6.0) -> Trace:
    """A second-order-like heading step to pi/2 whose first peak is ``overshoot`` of it."""
    zeta = -math.log(overshoot) / math.sqrt(math.pi**2 + math.log(overshoot) ** 2)
    wn = 4.0
    wd = wn * math.sqrt(1 - zeta**2)
    trace = Trace()
    for k in range(int(seconds / dt) + 1):
        t = k * dt
        y = 1 - math.exp(-zeta * wn * t) * (
            math.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * math.sin(wd * t)
        )
        trace.add(t, 0.0, 0.0, math.pi / 2 * y, 1.0)
    return trace


def test_overshoot_rise_and_settling_of_a_known_step_response() -> None:
    metrics, response = score(Goal(heading=math.pi / 2), heading_trace(0.2))
    assert metrics["overshoot_pct"] == pytest.approx(20.0, abs=0.5)
    assert 0.2 < metrics["rise_time_s"] < 0.6
    # 2 % band of a zeta = 0.456, wn = 4 response: about 4 / (zeta wn) = 2.2 s
    assert 1.5 < metrics["settling_time_s"] < 2.6
    assert metrics["steady_state_error"] < 0.01
    assert response["ys"] == pytest.approx(math.pi / 2)


def test_a_response_that_ends_outside_the_band_has_no_settling_time() -> None:
    trace = Trace()
    for k in range(20):
        trace.add(k * 0.05, 0.0, 0.0, 0.5 * k / 19, 1.0)  # reaches a third of the step
    metrics, _ = score(Goal(heading=1.5), trace)
    assert metrics["settling_time_s"] is None
    assert metrics["rise_time_s"] is None
    assert metrics["time_to_goal_s"] is None
    passed, lines = evaluate({"settling_time_s": Threshold(max=4)}, metrics)
    assert not passed
    assert lines[0]["text"] == "settling_time_s not reached (needs <= 4)"


def test_heading_is_unwrapped_across_pi() -> None:
    trace = Trace()
    for k in range(41):  # from 170 degrees to 190 (-170) degrees
        a = math.radians(170 + k * 0.5)
        trace.add(k * 0.05, 0.0, 0.0, math.atan2(math.sin(a), math.cos(a)), 1.0)
    for k in range(41, 70):  # held there
        trace.add(k * 0.05, 0.0, 0.0, math.radians(-170), 1.0)
    metrics, _ = score(Goal(heading=math.radians(-170)), trace)
    assert metrics["overshoot_pct"] == 0.0
    assert metrics["steady_state_error"] < 1e-6


def test_position_path_time_to_goal_collisions_and_waypoints() -> None:
    trace = Trace()
    for k in range(21):
        x = min(1.1, k * 0.1)
        trace.add(k * 0.5, x, 0.0, 0.0, 0.5)
        trace.touch(k in (3, 4, 9))
    metrics, _ = score(Goal(position=(1.0, 0.0)), trace)
    assert metrics["overshoot_pct"] == pytest.approx(10.0)
    assert metrics["time_to_goal_s"] == pytest.approx(5.0)  # within 0.05 m from x = 1.0
    assert metrics["path_length_m"] == pytest.approx(1.1)
    assert metrics["collisions"] == 2
    way, _ = score(Goal(waypoints=[(0.5, 0.0), (1.0, 0.0)], tolerance=0.01), trace)
    assert way["time_to_goal_s"] == pytest.approx(5.0)
    assert way["overshoot_pct"] is None


def test_goal_in_the_start_frame_and_clearance_to_walls() -> None:
    goal = resolve_goal(Goal(position=(1.0, 0.0)), (2.0, 1.0, math.pi / 2), "start")
    assert goal.position == pytest.approx((2.0, 2.0))
    walls = np.array([[0.0, -1.0, 0.0, 1.0]])
    assert clearance(0.5, 0.0, 0.1, walls) == pytest.approx(0.4)
    assert clearance(0.5, 3.0, 0.1, walls) == pytest.approx(math.hypot(0.5, 2.0) - 0.1)


def test_a_wall_goal_measures_the_distance_from_the_walls_line() -> None:
    trace = Trace()
    for k in range(60):  # east along y = -2 + d, d from 0.9 m down to 0.5 m in 2 s, then held
        d = max(0.5, 0.9 - 0.2 * k * 0.05)
        trace.add(k * 0.05, -2.5 + 0.01 * k, -2.0 + d, 0.0, d - 0.105)
    goal = Goal(wall=WallGoal(segment=(-3.0, -2.0, 3.0, -2.0), distance=0.5), tolerance=0.035)
    metrics, response = score(goal, trace)
    assert response["y0"] == pytest.approx(0.9) and response["ys"] == 0.5
    assert metrics["overshoot_pct"] == 0.0
    assert metrics["time_to_goal_s"] == pytest.approx(1.85)  # within 3.5 cm: d = 0.53
    assert metrics["settling_time_s"] == pytest.approx(2.0)  # within 2 % of 0.4 m: d = 0.50
    assert metrics["min_clearance_m"] == pytest.approx(0.395)
