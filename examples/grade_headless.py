"""Controllers for ``simbridge grade --headless``: the PID lab's loops on a headless Simulation.

    simbridge grade config/tasks/heading_step.yaml --headless \
        --controller examples/grade_headless.py:heading
    simbridge grade config/tasks/goto_position.yaml --headless \
        --controller examples/grade_headless.py:goto

Each factory is called once, with the robot at the task's start pose, as ``NAME(sim, robot,
goal)`` (``goal``: the task's goal in world coordinates) and returns the function the grader
calls before every simulation step. They read the robot's own /odom, as a ROS node would, and
publish /cmd_vel at 10 Hz (every other 20 Hz step). Gains come from the environment
(``KP``, ``KI``, ``KD``) so that one file grades several tunings.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any


def _gains(kp: float, ki: float, kd: float) -> tuple[float, float, float]:
    env = os.environ
    return float(env.get("KP", kp)), float(env.get("KI", ki)), float(env.get("KD", kd))


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _yaw(odom: dict[str, Any]) -> float:
    q = odom["pose"]["pose"]["orientation"]
    return math.atan2(2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2))


class PID:
    """The PID of the page's lab (anti-windup: no integration while saturated)."""

    def __init__(self, kp: float, ki: float, kd: float, limit: float) -> None:
        self.kp, self.ki, self.kd, self.limit = kp, ki, kd, limit
        self.integral = 0.0
        self.previous: float | None = None

    def update(self, error: float, dt: float) -> float:
        """Return the command for ``error`` after ``dt`` seconds."""
        derivative = 0.0 if self.previous is None else (error - self.previous) / dt
        self.previous = error
        out = self.kp * error + self.ki * (self.integral + error * dt) + self.kd * derivative
        if abs(out) < self.limit:
            self.integral += error * dt
        return max(-self.limit, min(self.limit, out))


def _loop(sim: Any, robot: str, control: Callable[[dict[str, Any]], tuple[float, float]]):
    ns = f"/{robot}" if robot else ""
    odom = sim.subscribe(f"{ns}/odom", maxlen=1)
    steps = [0]

    def step() -> None:
        steps[0] += 1
        if steps[0] % 2 or odom.latest is None:  # 10 Hz on 20 Hz steps
            return
        v, w = control(odom.latest)
        sim.publish(f"{ns}/cmd_vel", {"linear": {"x": v}, "angular": {"z": w}})

    return step


def heading(sim: Any, robot: str, goal: dict[str, Any]) -> Callable[[], None]:
    """Turn on the spot to ``goal["heading"]``."""
    pid = PID(*_gains(3.0, 0.1, 0.05), limit=2.5)
    return _loop(sim, robot, lambda m: (0.0, pid.update(_wrap(goal["heading"] - _yaw(m)), 0.1)))


def goto(sim: Any, robot: str, goal: dict[str, Any]) -> Callable[[], None]:
    """Drive to ``goal["position"]`` (the page's position mode)."""
    pid = PID(*_gains(0.8, 0.0, 0.05), limit=0.3)
    gx, gy = goal["position"]

    def control(m: dict[str, Any]) -> tuple[float, float]:
        p = m["pose"]["pose"]["position"]
        dx, dy = gx - p["x"], gy - p["y"]
        bearing = _wrap(math.atan2(dy, dx) - _yaw(m)) if math.hypot(dx, dy) > 0.03 else 0.0
        v = pid.update(math.hypot(dx, dy), 0.1) * max(0.0, math.cos(bearing))
        return v, max(-2.5, min(2.5, 2.0 * bearing))

    return _loop(sim, robot, control)
