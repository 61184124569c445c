from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.config import Params, load_world
from simbridge.graph import Graph, RobotBridge
from simbridge.graph.estop import EStop
from simbridge.sim import World
from tests.helpers import RecordingPeer


@pytest.fixture
def setup() -> tuple[Graph, World, EStop]:
    graph = Graph()
    world = World(load_world(None), Params())
    RobotBridge(graph, world)
    return graph, world, EStop(graph, world)


def call(peer: RecordingPeer, graph: Graph, service: str) -> Any:
    graph.receive(peer, json.dumps({"op": "call_service", "service": service, "id": "c"}), 0.0)
    return next(m for m in peer.take() if m.get("op") == "service_response")


def pub(peer: RecordingPeer, graph: Graph, v: float, w: float) -> None:
    msg = {"linear": {"x": v}, "angular": {"z": w}}
    graph.receive(peer, json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": msg}), 0.0)


def test_estop_halts_at_once_and_ignores_cmd_vel_until_reset(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    pub(peer, graph, 0.3, 1.0)
    world.step()
    assert world.robots[""].state.v == 0.3
    reply = call(peer, graph, "/estop")
    assert reply["result"] is True and reply["values"]["success"] is True
    assert world.robots[""].state.v == 0.0 and world.robots[""].state.omega == 0.0
    before = world.robots[""].state.x
    pub(peer, graph, 0.5, 0.0)
    for _ in range(10):
        world.step()
    assert world.robots[""].state.x == before
    call(peer, graph, "/reset")  # a world reset does not release the latch
    pub(peer, graph, 0.5, 0.0)
    world.step()
    assert world.estopped and world.robots[""].state.v == 0.0
    call(peer, graph, "/estop/reset")
    assert not world.estopped
    world.step()
    assert world.robots[""].state.v == 0.0  # stays still until the next command
    pub(peer, graph, 0.2, 0.0)
    world.step()
    assert world.robots[""].state.v == 0.2


def test_estop_state_is_latched_for_late_subscribers(setup: Any) -> None:
    graph, _, _ = setup
    caller = RecordingPeer(graph)
    call(caller, graph, "/estop")
    late = RecordingPeer(graph)
    graph.receive(late, json.dumps({"op": "subscribe", "topic": "/estop/state"}), 0.0)
    assert [m["msg"] for m in late.take()] == [{"data": True}]
    call(caller, graph, "/estop/reset")
    assert [m["msg"] for m in late.take()] == [{"data": False}]


def test_estop_refuses_request_fields(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    frame = {"op": "call_service", "service": "/estop", "args": {"bogus": 1}, "id": "x"}
    graph.receive(peer, json.dumps(frame), 0.0)
    reply = next(m for m in peer.take() if m.get("op") == "service_response")
    assert reply["result"] is False and "bogus" in reply["values"]
    assert not world.estopped
