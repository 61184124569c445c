#!/usr/bin/env python3
"""Drive to a goal position (and heading) with two PID loops at 10 Hz, over rosbridge (roslibpy).

Works unchanged against simbridge and against rosbridge on the real robot:

    pip install roslibpy          # or, in make run's venv: .venv/bin/pip install roslibpy
    python examples/pid_goto.py --url ws://127.0.0.1:9090 --goal 1.0 0.5 --heading 1.57

The gains are options (``--position-gains KP KI KD``, ``--heading-gains KP KI KD``) so that a
tuning can be graded: ``simbridge grade config/tasks/goto_position.yaml -- python
examples/pid_goto.py --position-gains 3 2 0`` (the URL and the goal come from
``SIMBRIDGE_URL`` and ``SIMBRIDGE_GOAL``, which ``simbridge grade`` sets for the command it
starts).

Reads /odom (nav_msgs/msg/Odometry), publishes /cmd_vel every 100 ms
(geometry_msgs/msg/Twist, or TwistStamped when the robot's /cmd_vel has that type):

* heading loop: angular.z = PID(wrap(bearing to goal - yaw)); once within ``--tolerance`` of
  the goal, the error is wrap(``--heading`` - yaw) instead (when a heading is given);
* position loop: linear.x = PID(distance to goal) * max(0, cos(heading error)) (no driving
  while facing away), clamped to ``--max-speed``.

Prints one JSON line at the end: ``{"reached": bool, "x", "y", "yaw", "distance_error",
"heading_error", "seconds"}``; exit code 0 when the goal was reached in time.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
import time
from collections.abc import Callable
from urllib.parse import urlparse


try:
    import roslibpy
except ImportError:  # a client library, not part of simbridge: install it where this runs
    sys.exit(
        "pid_goto.py needs roslibpy: pip install roslibpy "
        "(after `make run` in a checkout: .venv/bin/pip install roslibpy, then .venv/bin/python)"
    )


def wrap(angle: float) -> float:
    """Return ``angle`` in (-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


class PID:
    """A PID controller with output and integral limits (derivative on the error)."""

    def __init__(self, kp: float, ki: float, kd: float, limit: float) -> None:
        self.kp, self.ki, self.kd, self.limit = kp, ki, kd, limit
        self.integral = 0.0
        self.previous: float | None = None

    def update(self, error: float, dt: float) -> float:
        """Return the command for ``error`` after ``dt`` seconds."""
        self.integral += error * dt
        bound = self.limit / self.ki if self.ki else 0.0
        self.integral = max(-bound, min(bound, self.integral))  # anti-windup
        derivative = 0.0 if self.previous is None else (error - self.previous) / dt
        self.previous = error
        out = self.kp * error + self.ki * self.integral + self.kd * derivative
        return max(-self.limit, min(self.limit, out))


def velocity_publisher(ros: roslibpy.Ros, name: str = "/cmd_vel") -> Callable[[float, float], None]:
    """Return ``publish(linear, angular)`` in the type the robot expects on ``name``.

    Newer ROS 2 stacks (diff_drive_controller since Jazzy, simbridge with
    ``robot.cmd_vel_stamped``) want geometry_msgs/msg/TwistStamped; rosapi says which.
    """
    kind = ros.get_topic_type(name) or "geometry_msgs/msg/Twist"
    topic = roslibpy.Topic(ros, name, kind)
    topic.advertise()

    def publish(linear: float, angular: float) -> None:
        twist = {"linear": {"x": linear, "y": 0.0, "z": 0.0},
                 "angular": {"x": 0.0, "y": 0.0, "z": angular}}  # fmt: skip
        if kind.endswith("TwistStamped"):
            sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
            header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": "base_link"}
            twist = {"header": header, "twist": twist}
        topic.publish(roslibpy.Message(twist))

    return publish


def goal_from_env() -> list[float] | None:
    """Return the goal position ``simbridge grade`` gives its command ($SIMBRIDGE_GOAL), if any."""
    try:
        goal = json.loads(os.environ.get("SIMBRIDGE_GOAL", "null"))
        return [float(v) for v in goal["position"]]
    except (ValueError, TypeError, KeyError):
        return None


def main() -> int:
    """Run the example; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--url",
        default=os.environ.get("SIMBRIDGE_URL", "ws://127.0.0.1:9090"),
        help="rosbridge URL (default: $SIMBRIDGE_URL or ws://127.0.0.1:9090)",
    )
    parser.add_argument(
        "--goal",
        nargs=2,
        type=float,
        default=goal_from_env() or [1.0, 0.5],
        metavar=("X", "Y"),
        help="goal position (default: the position of $SIMBRIDGE_GOAL, else 1.0 0.5)",
    )
    parser.add_argument("--heading", type=float, default=None, help="final yaw, radians")
    parser.add_argument("--tolerance", type=float, default=0.05, help="metres (default 0.05)")
    parser.add_argument("--heading-tolerance", type=float, default=0.05, help="radians")
    parser.add_argument("--max-speed", type=float, default=0.3, help="m/s (default 0.3)")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds (default 30)")
    parser.add_argument(
        "--heading-gains", nargs=3, type=float, default=[2.0, 0.1, 0.1], metavar=("KP", "KI", "KD")
    )
    parser.add_argument(
        "--position-gains",
        nargs=3,
        type=float,
        default=[0.8, 0.05, 0.05],
        metavar=("KP", "KI", "KD"),
    )
    args = parser.parse_args()

    url = urlparse(args.url)
    ros = roslibpy.Ros(host=url.hostname or "127.0.0.1", port=url.port or 9090)
    ros.run(timeout=10)
    odom = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
    drive = velocity_publisher(ros)

    pose: list[float] = []
    lock = threading.Lock()
    first = threading.Event()

    def on_odom(msg: dict) -> None:
        p = msg["pose"]["pose"]
        q = p["orientation"]
        yaw = math.atan2(
            2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2)
        )
        with lock:
            pose[:] = [p["position"]["x"], p["position"]["y"], yaw]
        first.set()

    odom.subscribe(on_odom)
    if not first.wait(10):
        print(json.dumps({"reached": False, "error": "no /odom within 10 s"}))
        return 1

    heading_pid = PID(*args.heading_gains, limit=1.5)
    position_pid = PID(*args.position_gains, limit=args.max_speed)
    gx, gy = args.goal
    period = 0.1  # 10 Hz
    start = time.monotonic()
    tick = 0
    reached = False
    dist = heading_err = math.inf
    while time.monotonic() - start < args.timeout:
        with lock:
            x, y, yaw = pose
        dist = math.hypot(gx - x, gy - y)
        at_goal = dist < args.tolerance
        if at_goal and args.heading is None:
            heading_err = 0.0
            reached = True
            break
        if at_goal:
            heading_err = wrap(args.heading - yaw)
            if abs(heading_err) < args.heading_tolerance:
                reached = True
                break
            linear = 0.0
        else:
            heading_err = wrap(math.atan2(gy - y, gx - x) - yaw)
            linear = position_pid.update(dist, period) * max(0.0, math.cos(heading_err))
        angular = heading_pid.update(heading_err, period)
        drive(linear, angular)
        tick += 1
        time.sleep(max(0.0, start + tick * period - time.monotonic()))  # absolute deadlines

    drive(0.0, 0.0)
    time.sleep(0.3)  # let the stop command leave before closing
    with lock:
        x, y, yaw = pose
    result = {
        "reached": reached,
        "x": x,
        "y": y,
        "yaw": yaw,
        "distance_error": math.hypot(gx - x, gy - y),
        "heading_error": 0.0 if args.heading is None else abs(wrap(args.heading - yaw)),
        "seconds": round(time.monotonic() - start, 2),
    }
    ros.terminate()
    print(json.dumps(result), flush=True)
    return 0 if reached else 1


if __name__ == "__main__":
    sys.exit(main())
