"""Scoring a run: step-response and path metrics from the true pose, and the rubric's verdict.

Pure functions over a :class:`Trace` (the robot's true pose each step, from the controller's
first command, ``t = 0``). Each goal gives a *response*, a scalar with a step from ``y0`` to
``ys``, and an *error*, how far the robot is from the goal:

=============  =========================================  ======================================
goal           response ``y``                             error
=============  =========================================  ======================================
heading        yaw, unwrapped (rad); ``ys = y0 +          ``|wrap(heading - yaw)|``
               wrap(heading - y0)``
position       distance travelled along the start->goal   distance to the goal
               line (m); ``ys`` = its length
wall           distance from the wall's line (m);         ``|distance - goal distance|``
               ``ys`` = the goal distance
waypoints      (none: no single step)                     distance to the next waypoint
=============  =========================================  ======================================

The metrics (the usual control-course definitions):

* ``overshoot_pct``: the largest excursion of ``y`` past ``ys``, in % of ``|ys - y0|``;
* ``rise_time_s``: from the first time ``y`` reaches 10 % of the step to the first time it
  reaches 90 % (None: it never did);
* ``settling_time_s``: the time after which ``y`` stays within 2 % of the step around ``ys``
  (None: it was outside the band at the end);
* ``steady_state_error``: the mean error over the last second of the run;
* ``time_to_goal_s``: the first time the error is within the goal's tolerance (waypoints: each
  in turn; None: never);
* ``path_length_m``, ``min_clearance_m`` (the footprint's edge to the nearest wall),
  ``collisions`` (contacts begun).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from simbridge.grading.task import Goal, Task, Threshold, WallGoal


__all__ = [
    "BAND",
    "Trace",
    "clearance",
    "evaluate",
    "resolve_goal",
    "score",
    "thresholds",
    "wrap",
]

#: The settling band, a fraction of the step.
BAND = 0.02
#: Seconds at the end of a run the steady-state error is averaged over.
STEADY_WINDOW = 1.0


def wrap(angle: float) -> float:
    """Return ``angle`` in (-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


def resolve_goal(goal: Goal, start: tuple[float, float, float], frame: str) -> Goal:
    """Return ``goal`` in world coordinates (``frame == "start"``: given in the start's frame)."""
    if frame != "start":
        return goal
    x0, y0, th = start
    c, s = math.cos(th), math.sin(th)

    def point(p: tuple[float, float]) -> tuple[float, float]:
        return (x0 + c * p[0] - s * p[1], y0 + s * p[0] + c * p[1])

    if goal.heading is not None:
        return goal.replace(heading=wrap(th + goal.heading))
    if goal.position is not None:
        return goal.replace(position=point(goal.position))
    if goal.waypoints is not None:
        return goal.replace(waypoints=[point(p) for p in goal.waypoints])
    assert goal.wall is not None
    x1, y1, x2, y2 = goal.wall.segment
    seg = (*point((x1, y1)), *point((x2, y2)))
    return goal.replace(wall=WallGoal(segment=seg, distance=goal.wall.distance))


def clearance(x: float, y: float, radius: float, segments: np.ndarray) -> float:
    """Return the distance from a footprint of ``radius`` at ``(x, y)`` to the nearest segment."""
    if segments.shape[0] == 0:
        return math.inf
    a = segments[:, 0:2]
    d = segments[:, 2:4] - a
    p = np.array([x, y])
    length2 = np.maximum((d * d).sum(axis=1), 1e-18)
    u = np.clip(((p - a) * d).sum(axis=1) / length2, 0.0, 1.0)
    nearest = a + d * u[:, None]
    return float(np.sqrt(((nearest - p) ** 2).sum(axis=1)).min()) - radius


def _line_distance(x: float, y: float, seg: tuple[float, float, float, float]) -> float:
    x1, y1, x2, y2 = seg
    dx, dy = x2 - x1, y2 - y1
    return abs(dx * (y - y1) - dy * (x - x1)) / math.hypot(dx, dy)


@dataclass
class Trace:
    """The true pose of one robot at each step of a run (``t`` from the first command)."""

    t: list[float] = field(default_factory=list)
    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    #: Yaw, unwrapped (no jump at +-pi).
    theta: list[float] = field(default_factory=list)
    #: The footprint's distance to the nearest wall at each step.
    clearance: list[float] = field(default_factory=list)
    #: Contacts begun (a step touching after one that did not).
    collisions: int = 0
    _touching: bool = False

    def add(self, t: float, x: float, y: float, theta: float, clear: float) -> None:
        """Add one step's pose."""
        if self.theta:
            theta = self.theta[-1] + wrap(theta - self.theta[-1])
        self.t.append(t)
        self.x.append(x)
        self.y.append(y)
        self.theta.append(theta)
        self.clearance.append(clear)

    def touch(self, touching: bool) -> None:
        """Note whether the robot touched an obstacle in this step."""
        if touching and not self._touching:
            self.collisions += 1
        self._touching = touching


def _response(goal: Goal, trace: Trace) -> tuple[list[float], float, float, list[float]]:
    """Return ``(response, y0, ys, error)`` of ``trace`` for ``goal`` (see the module)."""
    xs, ys_, th = trace.x, trace.y, trace.theta
    if goal.heading is not None:
        y0 = th[0]
        target = y0 + wrap(goal.heading - y0)
        return list(th), y0, target, [abs(wrap(goal.heading - a)) for a in th]
    if goal.position is not None:
        gx, gy = goal.position
        sx, sy = xs[0], ys_[0]
        length = math.hypot(gx - sx, gy - sy)
        ux, uy = ((gx - sx) / length, (gy - sy) / length) if length > 1e-9 else (1.0, 0.0)
        along = [(x - sx) * ux + (y - sy) * uy for x, y in zip(xs, ys_, strict=True)]
        error = [math.hypot(gx - x, gy - y) for x, y in zip(xs, ys_, strict=True)]
        return along, 0.0, length, error
    if goal.wall is not None:
        seg, d = goal.wall.segment, goal.wall.distance
        dist = [_line_distance(x, y, seg) for x, y in zip(xs, ys_, strict=True)]
        return dist, dist[0], d, [abs(v - d) for v in dist]
    assert goal.waypoints is not None
    points = goal.waypoints
    k = 0
    error = []
    for x, y in zip(xs, ys_, strict=True):
        while k < len(points) - 1 and math.hypot(points[k][0] - x, points[k][1] - y) <= goal.reach:
            k += 1
        error.append(math.hypot(points[k][0] - x, points[k][1] - y))
    return [], 0.0, 0.0, error


def _first(ts: list[float], flags: list[bool]) -> float | None:
    return next((t for t, f in zip(ts, flags, strict=True) if f), None)


def score(goal: Goal, trace: Trace) -> tuple[dict[str, Any], dict[str, Any]]:
    """Return ``(metrics, response)`` of a run.

    ``metrics``: the values (None where undefined); ``response``: the response signal with its
    step (``t``, ``y``, ``y0``, ``ys``, ``band``, ``unit``) and the error.
    """
    t = trace.t
    if not t:
        metrics: dict[str, Any] = dict.fromkeys(
            (
                "overshoot_pct",
                "rise_time_s",
                "settling_time_s",
                "steady_state_error",
                "time_to_goal_s",
                "min_clearance_m",
            )
        )
        metrics.update(path_length_m=0.0, collisions=trace.collisions)
        return metrics, {"t": [], "y": [], "y0": 0.0, "ys": 0.0, "band": 0.0, "unit": ""}
    y, y0, ys, error = _response(goal, trace)
    step = ys - y0
    band = BAND * abs(step)
    overshoot = rise = settling = None
    if y and abs(step) > 1e-9:
        sign = 1.0 if step > 0 else -1.0
        peak = max((v - ys) * sign for v in y)
        overshoot = max(0.0, 100.0 * peak / abs(step))
        progress = [(v - y0) / step for v in y]
        t10 = _first(t, [p >= 0.1 for p in progress])
        t90 = _first(t, [p >= 0.9 for p in progress])
        rise = t90 - t10 if t10 is not None and t90 is not None else None
        outside = [i for i, v in enumerate(y) if abs(v - ys) > band]
        if not outside:
            settling = 0.0
        elif outside[-1] < len(y) - 1:
            settling = t[outside[-1] + 1]
    elif y:
        overshoot, rise, settling = 0.0, 0.0, 0.0
    reach = goal.reach
    if goal.waypoints is not None:
        done = [False] * len(t)
        k = 0
        for i, (x, yy) in enumerate(zip(trace.x, trace.y, strict=True)):
            while (
                k < len(goal.waypoints)
                and math.hypot(goal.waypoints[k][0] - x, goal.waypoints[k][1] - yy) <= reach
            ):
                k += 1
            done[i] = k == len(goal.waypoints)
        to_goal = _first(t, done)
    else:
        to_goal = _first(t, [e <= reach for e in error])
    window = [e for ti, e in zip(t, error, strict=True) if ti >= t[-1] - STEADY_WINDOW]
    path = sum(
        math.hypot(trace.x[i] - trace.x[i - 1], trace.y[i] - trace.y[i - 1])
        for i in range(1, len(t))
    )
    clear = min(trace.clearance) if trace.clearance else None
    metrics = {
        "overshoot_pct": _round(overshoot, 2),
        "rise_time_s": _round(rise, 3),
        "settling_time_s": _round(settling, 3),
        "steady_state_error": _round(sum(window) / len(window), 4),
        "time_to_goal_s": _round(to_goal, 3),
        "path_length_m": _round(path, 4),
        "min_clearance_m": None if clear is None or math.isinf(clear) else _round(clear, 4),
        "collisions": trace.collisions,
    }
    unit = "rad" if goal.heading is not None else "m"
    response = {"t": t, "y": y, "y0": y0, "ys": ys, "band": band, "unit": unit, "error": error}
    return metrics, response


def _round(value: float | None, digits: int) -> float | None:
    return None if value is None else round(value, digits)


def evaluate(
    rubric: dict[str, Threshold], metrics: dict[str, Any]
) -> tuple[bool, list[dict[str, Any]]]:
    """Return ``(passed, lines)``: each rubric line with the metric's value and its verdict.

    A metric that is undefined for the run (None: never rose, never settled, never reached
    the goal) fails its line.
    """
    lines = []
    for name, th in rubric.items():
        value = metrics.get(name)
        ok = value is not None
        why = []
        if th.max is not None:
            why.append(f"<= {th.max:g}")
            ok = ok and value is not None and value <= th.max
        if th.min is not None:
            why.append(f">= {th.min:g}")
            ok = ok and value is not None and value >= th.min
        shown = "not reached" if value is None else f"{value:g}"
        lines.append(
            {
                "metric": name,
                "value": value,
                "max": th.max,
                "min": th.min,
                "passed": bool(ok),
                "text": f"{name} {shown} (needs {' and '.join(why)})",
            }
        )
    return all(line["passed"] for line in lines), lines


def thresholds(task: Task) -> dict[str, dict[str, float | None]]:
    """Return the rubric as plain data: ``{metric: {"max": ..., "min": ...}}``."""
    return {name: {"max": th.max, "min": th.min} for name, th in task.rubric.items()}
