from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.app.config import Params, load_world
from simbridge.app.guard import Guard
from simbridge.app.settings import ServerSettings
from simbridge.errors import ProtocolError
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.rosbridge import Refusal, ops as o
from simbridge.rosbridge.admission import Call, Publication, Response
from simbridge.sim import World
from tests.helpers import ROOT, RecordingPeer, rosbridge_of


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
        graph = Graph(settings=settings)
        if guarded:
            rosbridge_of(graph, Guard(graph, settings))
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
    rosbridge_of(graph, guard)
    r1 = RecordingPeer(graph, token="r1-token-aaaa")
    guard.connect(r1)  # its access from its token, as on connect
    assert op(r1, graph, op="publish", topic="r1/cmd_vel", msg=TWIST) == []
    assert (world.robots["r1"].cmd_v, world.robots["r1"].cmd_omega) == (0.2, 0.5)
    out = op(r1, graph, op="publish", topic="/r2/cmd_vel", msg=TWIST)
    assert errors(out) == [
        "publish /r2/cmd_vel: not allowed; this connection may only use names under /r1/ "
        "(its robot)"
    ]
    assert world.robots["r2"].cmd_v == 0.0
    assert "/r2/cmd_vel" not in r1.session.advertisements


def test_a_call_is_admitted_with_its_service_and_its_request_validated() -> None:
    """The service table receives a complete request: list args zipped, defaults filled."""
    graph = Graph()
    peer = RecordingPeer(graph)
    graph.add_service("/add", "example_interfaces/srv/AddTwoInts", "/n", lambda r: {"sum": 0})
    call = rosbridge_of(graph).admission.admit(peer, o.CallService("add", args=[1]), 0.0)
    assert isinstance(call, Call) and call.service is graph.services.services["/add"]
    assert call.request == {"a": 1, "b": 0}


def test_a_call_with_a_bad_request_or_to_no_service_is_refused_before_any_table() -> None:
    """Refused in admission: the provider never hears of it, nothing waits, the caller is told."""
    graph = Graph()
    provider, caller = RecordingPeer(graph), RecordingPeer(graph)
    advertise = {"op": "advertise_service", "service": "/add"}
    op(provider, graph, **advertise, type="example_interfaces/AddTwoInts")
    with pytest.raises(Refusal, match=r"Message type .* does not have a field c") as refused:
        rosbridge_of(graph).admission.admit(
            caller, o.CallService("/add", args={"c": 1}, id="x"), 0.0
        )
    assert (refused.value.op, refused.value.target, refused.value.op_id) == (
        "call_service",
        "/add",
        "x",
    )
    (answer,) = op(caller, graph, op="call_service", service="/add", args={"c": 1}, id="x")
    assert answer["op"] == "service_response" and answer["result"] is False
    (answer,) = op(caller, graph, op="call_service", service="/none", id="y")
    assert answer["values"] == "Service /none does not exist" and answer["result"] is False
    assert provider.take() == [] and graph.services.pending == {}
    assert caller.session.pending_calls == 0


def test_a_providers_answers_are_admitted_validated_for_the_calls_it_serves() -> None:
    """service_response: read and checked before routing."""
    graph = Graph()
    provider, caller, other = RecordingPeer(graph), RecordingPeer(graph), RecordingPeer(graph)
    op(
        provider,
        graph,
        op="advertise_service",
        service="/add",
        type="example_interfaces/AddTwoInts",
    )
    op(caller, graph, op="call_service", service="/add", args={"a": 1, "b": 2}, id="c")
    (forwarded,) = provider.take()
    answer = o.ServiceResponse("/add", values={}, id=forwarded["id"], result=True)
    with pytest.raises(ProtocolError, match="from a client that does not provide it"):
        rosbridge_of(graph).admission.admit(other, answer, 0.0)
    response = rosbridge_of(graph).admission.admit(provider, answer, 0.0)
    assert isinstance(response, Response) and response.ok and response.values == {"sum": 0}
    bad = o.ServiceResponse("/add", values={"total": 3}, id=forwarded["id"], result=True)
    response = rosbridge_of(graph).admission.admit(provider, bad, 0.0)
    assert isinstance(response, Response) and not response.ok
    assert response.values.startswith("service provider sent an invalid response")
    assert caller.take() == [] and len(graph.services.pending) == 1  # nothing routed yet
