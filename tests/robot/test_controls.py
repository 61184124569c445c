from __future__ import annotations

import json
from typing import Any

from websockets.asyncio.client import connect

from simbridge.app.build import guard_graph
from simbridge.app.config import Params, load_world
from simbridge.app.guard import Guard
from simbridge.app.settings import ServerSettings
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.controls import WorldControls
from simbridge.sim import World
from tests.conftest import AppFactory
from tests.helpers import ROOT, RecordingPeer, recv_until, rosbridge_of, send_json, ws_url


ADMIN = "the-admin-token"
TOKENS = {"token-for-r3-cccc": "r3"}


def setup() -> tuple[Graph, Guard, World]:
    graph = Graph()
    world = World(load_world(ROOT / "config" / "worlds" / "classroom.yaml"), Params())
    RobotBridge(graph, world)
    WorldControls(graph, world)
    settings = ServerSettings(client_tokens=TOKENS, admin_token=ADMIN)
    guard = Guard(graph, settings, robots=world.robots.keys)
    guard_graph(graph, guard)
    rosbridge_of(graph, guard)
    return graph, guard, world


def call(graph: Graph, peer: RecordingPeer, service: str, args: dict[str, Any]) -> Any:
    frame = {"op": "call_service", "service": service, "args": args, "id": "c"}
    rosbridge_of(graph).receive(peer, json.dumps(frame), 0.0)
    return next(m for m in peer.take() if m.get("op") == "service_response")


def client(graph: Graph, guard: Guard, token: str) -> RecordingPeer:
    peer = RecordingPeer(graph, token=token)
    guard.peer_connected(peer)
    return peer


def test_an_admin_rosbridge_client_switches_the_motion_model_and_sets_a_robots_values() -> None:
    graph, guard, world = setup()
    admin = client(graph, guard, ADMIN)
    reply = call(graph, admin, "/simbridge/motion_model", {"name": "dynamic"})
    assert reply["result"] is True and world.motion.name == "dynamic"
    assert json.loads(reply["values"]["reason"]) == {"motion_model": "dynamic"}
    changes = json.dumps({"robot.mass": 3.0, "realism.enabled": True})
    reply = call(graph, admin, "/simbridge/robot_params", {"name": "r3", "value": changes})
    assert reply["result"] is True, reply
    assert json.loads(reply["values"]["reason"])["own"] == {
        "robot.mass": 3.0,
        "realism.enabled": True,
    }
    assert world.robots["r3"].overrides == {"mass": 3.0}


def test_the_controls_refuse_bad_requests_with_the_reason_and_change_nothing() -> None:
    graph, guard, world = setup()
    admin = client(graph, guard, ADMIN)
    reply = call(graph, admin, "/simbridge/motion_model", {"name": "warp"})
    assert reply["result"] is False and "unknown motion model 'warp'" in reply["values"]
    for args, why in (
        ({"name": "r9", "value": '{"robot.mass": 3.0}'}, "no robot 'r9'"),
        ({"name": "r3", "value": "not json"}, "expected {"),
        ({"name": "r3", "value": '{"lidar.range_max": 3.0}'}, "only robot.* and realism.*"),
        ({"name": "r3", "value": '{"realism.enabled": true, "robot.mass": -1}'}, "robot r3:"),
    ):
        reply = call(graph, admin, "/simbridge/robot_params", args)
        assert reply["result"] is False and why in reply["values"], (args, reply)
    assert world.motion.name == "kinematic"
    assert not world.robots["r3"].overrides and not world.robots["r3"].realism_own


def test_a_students_token_is_refused_the_controls_by_name() -> None:
    graph, guard, world = setup()
    student = client(graph, guard, "token-for-r3-cccc")
    for service, args in (
        ("/simbridge/motion_model", {"name": "dynamic"}),
        ("/simbridge/robot_params", {"name": "r3", "value": '{"robot.mass": 3.0}'}),
    ):
        reply = call(graph, student, service, args)
        assert reply["result"] is False and "administrative" in reply["values"]
        assert service in reply["values"]
    assert world.motion.name == "kinematic" and not world.robots["r3"].overrides


async def test_over_the_socket_the_admin_token_sets_a_robots_values_and_a_students_is_refused(
    make_app: AppFactory,
) -> None:
    """A real server: the WebSocket clients send what roslibjs sends; /admin sees the change."""
    world = ROOT / "config" / "worlds" / "classroom.yaml"
    app = await make_app(world=world, admin_token=ADMIN, client_tokens=TOKENS)
    args = {"name": "r3", "value": '{"robot.mass": 3.0}'}
    frame = {"op": "call_service", "service": "/simbridge/robot_params", "args": args, "id": "p"}
    async with connect(f"{ws_url(app)}/?token=token-for-r3-cccc") as student:
        await send_json(student, frame)
        reply = await recv_until(student, lambda m: m.get("op") == "service_response")
    assert reply["result"] is False and "/simbridge/robot_params" in reply["values"]
    assert "administrative" in reply["values"] and not app.world.robots["r3"].overrides
    async with connect(f"{ws_url(app)}/?token={ADMIN}") as admin:
        await send_json(admin, frame)
        reply = await recv_until(admin, lambda m: m.get("op") == "service_response")
    assert reply["result"] is True, reply
    assert json.loads(reply["values"]["reason"]) == {"robot": "r3", "own": {"robot.mass": 3.0}}
    assert app.world.robots["r3"].overrides == {"mass": 3.0}
