from __future__ import annotations

import json
from typing import Any

from simbridge.app.build import guard_graph
from simbridge.app.config import Params, load_world
from simbridge.app.guard import Guard
from simbridge.app.settings import ServerSettings
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.admission import Publication
from simbridge.sim import World
from tests.helpers import ROOT, RecordingPeer, graph_for, rosbridge_of


TWIST = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}


def op(peer: RecordingPeer, graph: Graph, now: float = 0.0, **fields: Any) -> list[Any]:
    rosbridge_of(graph).receive(peer, json.dumps(fields), now)
    return peer.take()


def errors(messages: list[Any]) -> list[str]:
    return [m["msg"] for m in messages if m.get("op") == "status" and m["level"] == "error"]


def test_a_publish_is_admitted_once_with_its_topic_type_and_completed_message() -> None:
    """The handler gets what admission decided: no second lookup, conversion or type check."""
    graph = Graph()
    peer = RecordingPeer(graph)
    op(peer, graph, op="advertise", topic="/v", type="geometry_msgs/Vector3")
    (publish,) = peer.session.parse(json.dumps({"op": "publish", "topic": "v", "msg": {}}), 0.0)
    assert isinstance(publish, o.Publish)
    admitted = rosbridge_of(graph).admission.admit(peer, publish, 0.0)
    assert isinstance(admitted, Publication)
    assert admitted.topic is graph.topics.topics["/v"]
    assert admitted.type == "geometry_msgs/msg/Vector3"
    assert admitted.msg == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_a_refused_publish_changes_nothing() -> None:
    """A bad payload or a conflicting type is refused before the client holds anything."""
    graph = Graph()
    peer = RecordingPeer(graph)
    out = op(peer, graph, op="publish", topic="/v", type="geometry_msgs/Vector3", msg={"w": 1})
    assert errors(out) == ["Message type geometry_msgs/msg/Vector3 does not have a field w"]
    assert "/v" not in graph.topics.topics
    assert peer.session.advertisements == {} and peer.session.advertise_ids == 0
    op(peer, graph, op="advertise", topic="/s", type="std_msgs/String")
    ids = peer.session.advertise_ids
    out = op(peer, graph, op="publish", topic="/s", type="std_msgs/Int32", msg={"data": 1})
    assert errors(out) == [
        "Tried to register topic /s with type std_msgs/msg/Int32 but it is already "
        "established with type std_msgs/msg/String"
    ]
    assert peer.session.advertise_ids == ids
    assert graph.topics.topics["/s"].type == "std_msgs/msg/String"


def test_access_rules_apply_once_a_guard_is_installed() -> None:
    """Without a guard every client is trusted (no publish rate); with one, the rate holds."""
    settings = ServerSettings(publish_rate=1.0, publish_burst=2)
    for guarded in (False, True):
        graph = graph_for(settings)
        if guarded:
            guard = Guard(graph, settings)
            guard_graph(graph, guard)
            rosbridge_of(graph, guard)
        sender, listener = RecordingPeer(graph), RecordingPeer(graph)
        op(listener, graph, op="subscribe", topic="/n", type="std_msgs/Int32")
        for k in range(4):
            op(sender, graph, now=0.0, op="publish", topic="/n", msg={"data": k})
        received = [m["msg"]["data"] for m in listener.take()]
        assert received == ([0, 1] if guarded else [0, 1, 2, 3])
        assert rosbridge_of(graph).admission.guarded is guarded


def test_cmd_vel_reaches_its_robot_and_another_robots_client_is_refused_by_scope() -> None:
    """Socket -> session -> admission -> graph -> robot; a scope refusal never reaches it."""
    graph = Graph()
    world = World(load_world(ROOT / "config" / "worlds" / "classroom.yaml"), Params())
    RobotBridge(graph, world)
    settings = ServerSettings(client_tokens={"r1-token-aaaa": "r1"})
    guard = Guard(graph, settings, robots=world.robots.keys)
    guard_graph(graph, guard)
    rosbridge_of(graph, guard)
    r1 = RecordingPeer(graph, token="r1-token-aaaa")
    guard.peer_connected(r1)  # its access from its token, as on connect
    assert op(r1, graph, op="publish", topic="r1/cmd_vel", msg=TWIST) == []
    assert (world.robots["r1"].cmd_v, world.robots["r1"].cmd_omega) == (0.2, 0.5)
    out = op(r1, graph, op="publish", topic="/r2/cmd_vel", msg=TWIST)
    assert errors(out) == [
        "publish /r2/cmd_vel: not allowed; this connection may only use names under /r1/ "
        "(its robot)"
    ]
    assert world.robots["r2"].cmd_v == 0.0
    assert "/r2/cmd_vel" not in r1.session.advertisements
