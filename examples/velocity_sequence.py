#!/usr/bin/env python3
"""Send a fixed velocity sequence to /cmd_vel at 10 Hz (roslibpy): the validation exercise.

Run it once against the simulation and once against the real robot, each while recording
(``simbridge record``), then compare the two recordings::

    simbridge record --url ws://127.0.0.1:9090 -o sim /odom /cmd_vel &
    python examples/velocity_sequence.py --url ws://127.0.0.1:9090
    kill -INT %1
    # ... the same against ws://robot.local:9090 into -o real ...
    simbridge compare sim/sim.mcap real/real.mcap --plot compare.html

The sequence (``--sequence FILE``: a YAML list of ``[seconds, linear, angular]``) defaults to
:data:`SEQUENCE`: 1 s still, then a square of side about 0.6 m driven at 0.2 m/s, then still.
Every segment is published at 10 Hz (absolute deadlines); a zero command ends the run.
Prints one JSON line: ``{"segments": N, "messages": M, "seconds": S}``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from urllib.parse import urlparse


try:
    import roslibpy
    import yaml
except ImportError:  # client libraries, not part of simbridge: install them where this runs
    sys.exit(
        "velocity_sequence.py needs roslibpy and PyYAML: pip install roslibpy pyyaml "
        "(after `make run` in a checkout: .venv/bin/pip install roslibpy, then .venv/bin/python)"
    )


#: ``(seconds, linear m/s, angular rad/s)``: still, then four sides and four quarter turns.
SEQUENCE: list[tuple[float, float, float]] = [
    (1.0, 0.0, 0.0),
    *[(3.0, 0.2, 0.0), (math.pi / 2 / 0.5, 0.0, 0.5)] * 4,
    (1.0, 0.0, 0.0),
]


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


def main() -> int:
    """Run the example; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", default="ws://127.0.0.1:9090", help="rosbridge URL")
    parser.add_argument("--sequence", help="YAML list of [seconds, linear, angular]")
    parser.add_argument("--rate", type=float, default=10.0, help="Hz (default 10)")
    args = parser.parse_args()
    sequence = SEQUENCE
    if args.sequence:
        with open(args.sequence, encoding="utf-8") as f:
            sequence = [tuple(map(float, seg)) for seg in yaml.safe_load(f)]

    url = urlparse(args.url)
    ros = roslibpy.Ros(host=url.hostname or "127.0.0.1", port=url.port or 9090)
    ros.run(timeout=10)
    drive = velocity_publisher(ros)

    period = 1.0 / args.rate
    start = time.monotonic()
    tick = 0
    for seconds, linear, angular in sequence:
        for _ in range(round(seconds * args.rate)):
            drive(linear, angular)
            tick += 1
            time.sleep(max(0.0, start + tick * period - time.monotonic()))
    drive(0.0, 0.0)
    time.sleep(0.3)  # let the stop command leave before closing
    ros.terminate()
    summary = {"segments": len(sequence), "messages": tick + 1, "seconds": time.monotonic() - start}
    print(json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
