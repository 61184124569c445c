"""A client's publish through the graph: /cmd_vel to the robot, a topic to client subscribers.

What one ``publish`` op costs the server from the frame to its effect, on the in-process graph
(no sockets): :meth:`Graph.receive <simbridge.graph.Graph.receive>` of one JSON frame, with a
:class:`~simbridge.app.guard.Guard` installed as the server has it (its rate limit set out
of the way). Rows:

* ``/cmd_vel``: a full ``geometry_msgs/Twist`` to the default robot (session, admission, the
  robot's subscriber, ``World.command``);
* ``/chatter x10``: a ``std_msgs/String`` to 10 client subscribers (encoded once, queued 10
  times);
* ``bad payload``: a ``/cmd_vel`` whose ``linear.x`` is a string, refused with a ``status``.

Median microseconds per op. Uses only what the graph had before issue 12 too, so
``python -m bench quick --baseline DIR`` runs it against an older checkout's ``simbridge``.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Hashable
from typing import Any

from bench.encoding import _time
from simbridge.app.build import guard_graph
from simbridge.app.config import Params, load_world
from simbridge.app.guard import Guard
from simbridge.app.settings import ServerSettings, budgets
from simbridge.graph import Graph
from simbridge.graph.access import Access
from simbridge.robot.bridge import RobotBridge
from simbridge.rosbridge.front import Rosbridge
from simbridge.sim import World


class _Peer:
    """A connected client without a socket: it counts what it is sent."""

    def __init__(self, front: Rosbridge, label: str) -> None:
        self.session = front.new_session()
        self.label = label
        self.sent = 0
        front.add_peer(self)

    @property
    def access(self) -> Access:
        return self.session.access

    def send(self, frame: Any, key: Hashable | None = None, limit: int = 0) -> None:
        self.sent += 1


def _frame(topic: str, msg: dict[str, Any], op_type: str | None = None) -> str:
    op: dict[str, Any] = {"op": "publish", "topic": topic, "msg": msg}
    if op_type is not None:
        op["type"] = op_type
    return json.dumps(op)


def _cases() -> dict[str, Callable[[], None]]:
    settings = ServerSettings(publish_rate=1e9, publish_burst=1_000_000_000)
    graph = Graph()
    world = World(load_world(None), Params())
    RobotBridge(graph, world)
    guard = Guard(graph, settings, robots=lambda: world.robots.keys())
    guard_graph(graph, guard)
    front = Rosbridge(graph, *budgets(settings), authenticator=guard)
    sender = _Peer(front, "sender")
    for k in range(10):
        peer = _Peer(front, f"listener {k}")
        sub = {"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String"}
        front.receive(peer, json.dumps(sub), 0.0)
    twist = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}
    cmd = _frame("/cmd_vel", twist, "geometry_msgs/msg/Twist")
    chatter = _frame("/chatter", {"data": "hello world"}, "std_msgs/msg/String")
    bad = _frame("/cmd_vel", {"linear": {"x": "fast"}}, "geometry_msgs/msg/Twist")
    now = [0.0]

    def send(frame: str) -> Callable[[], None]:
        def run() -> None:
            now[0] += 0.001
            front.receive(sender, frame, now[0])

        return run

    send(cmd)()  # first use: registries, the implicit advertisement
    robot = world.robots[""]
    if (robot.cmd_v, robot.cmd_omega, sender.sent) != (0.2, 0.5, 0):
        raise RuntimeError("the /cmd_vel publish did not reach the robot")
    return {"/cmd_vel": send(cmd), "/chatter x10": send(chatter), "bad payload": send(bad)}


def main() -> int:
    print("publish: one client publish op through the graph (median, microseconds per op)")
    print(f"{'case':<14} {'us/op':>8}")
    for label, run in _cases().items():
        print(f"{label:<14} {_time(run) * 1e6:>8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
