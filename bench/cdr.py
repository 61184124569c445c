"""CDR encoding of the messages ROS 2 gets (Zenoh, DDS) beside their JSON, per message.

``python -m bench cdr``: 30 robots' /odom, /scan and /tf (one ``tf2_msgs/TFMessage`` of 30
transforms) as the bridge builds them in one step, each serialized to CDR by simbridge's
compiled codec (:class:`simbridge.msgs.cdr.CdrWriter`, what the ROS 2 links send) and to JSON
by orjson (:func:`simbridge.msgs.message.encode_json`, what a rosbridge client gets): the CPU
time of one message (this thread's, the least of 7 batches: the machine is shared), the ratio
CDR / JSON, and what a step's 46 messages cost each way (``bench dds outward`` compares the
server's CPU of the two wires). Before / after a change: ``python -m bench cdr --baseline DIR``.

These are warm figures (the same message encoded over and over); in the server each message
is encoded once, with cold caches, and costs several times more, on both sides.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from bench.encoding import _time
from simbridge.app.config import Params, WorldSpec
from simbridge.graph import Graph
from simbridge.msgs.cdr import CdrWriter
from simbridge.msgs.message import encode_json
from simbridge.robot.bridge import RobotBridge
from simbridge.sim import World


ROBOTS = 30
#: (topic, type): what one step publishes per robot, and the /tf of all of them.
TOPICS = (
    ("/r1/odom", "nav_msgs/msg/Odometry"),
    ("/r1/scan", "sensor_msgs/msg/LaserScan"),
    ("/tf", "tf2_msgs/msg/TFMessage"),
)


def messages() -> dict[str, Any]:
    """One step's /r1/odom, /r1/scan and /tf of a 30-robot world, as the bridge builds them."""
    side = 6
    robots = [
        {"name": f"r{k + 1}", "pose": [1.0 * (k % side), 1.0 * (k // side), 0.0]}
        for k in range(ROBOTS)
    ]
    spec = WorldSpec.parse({"name": "cdr", "walls": [[-2, -2, 8, -2]], "robots": robots})
    graph = Graph()
    world = World(spec, Params())
    bridge = RobotBridge(graph, world)
    captured: dict[str, Any] = {}
    for name, _type in TOPICS:
        topic = graph.topics.topics[name]
        topic.internal.append(("bench", lambda msg, _src, n=name: captured.setdefault(n, msg)))
    for robot in world.robots:
        world.command(robot, 0.2, 0.1)
    world.step()
    bridge.publish(0.0)
    return captured


def cpu_time(fn: Callable[[], object]) -> float:
    """This thread's CPU seconds per call: the least of 7 batches of 0.02 s or more."""
    return _time(fn, min_time=0.02, clock=time.thread_time, pick=min)


def main() -> int:
    msgs = messages()
    writer = CdrWriter(Graph().registry)
    print("cdr: one message to CDR (simbridge's codec) and to JSON (orjson), CPU us per message")
    print(f"{'topic':<9} {'CDR us':>8} {'JSON us':>8} {'CDR/JSON':>9} {'CDR B':>6} {'JSON B':>7}")
    per_step = {"/r1/odom": ROBOTS, "/r1/scan": ROBOTS // 2, "/tf": 1}
    step_cdr = step_json = 0.0
    for name, typename in TOPICS:
        msg = msgs[name]
        cdr = cpu_time(lambda msg=msg, t=typename: writer.serialize(t, msg))
        js = cpu_time(lambda msg=msg: encode_json(msg))
        size_cdr, size_json = len(writer.serialize(typename, msg)), len(encode_json(msg))
        print(
            f"{name:<9} {cdr * 1e6:>8.2f} {js * 1e6:>8.2f} {cdr / js:>8.2f}x "
            f"{size_cdr:>6} {size_json:>7}"
        )
        step_cdr += per_step[name] * cdr
        step_json += per_step[name] * js
    print(
        f"a step ({ROBOTS} /odom, {ROBOTS // 2} /scan, 1 /tf): CDR {step_cdr * 1e6:.1f} us, "
        f"JSON {step_json * 1e6:.1f} us, CDR/JSON {step_cdr / step_json:.2f}x"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
