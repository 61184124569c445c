from __future__ import annotations

import json
from typing import Any

from simbridge.app.build import guard_graph
from simbridge.app.config import Params, load_world
from simbridge.app.guard import Guard
from simbridge.app.settings import ServerSettings
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.estop import EStop
from simbridge.robot.roles import Roles
from simbridge.sim import World
from tests.helpers import ROOT, RecordingPeer, rosbridge_of


TOKENS = {"token-for-r3-cccc": "r3"}


def setup(**settings: Any) -> tuple[Graph, Guard, World]:
    graph = Graph()
    world = World(load_world(ROOT / "config" / "worlds" / "classroom.yaml"), Params())
    RobotBridge(graph, world)
    estop = EStop(graph, world)
    graph.watch(estop)
    Roles(graph, world, estop)
    guard = Guard(graph, ServerSettings(**settings), robots=world.robots.keys)
    guard_graph(graph, guard)
    rosbridge_of(graph, guard)
    return graph, guard, world


def access(graph: Graph, guard: Guard, token: str | None) -> Any:
    peer = RecordingPeer(graph, token=token)
    guard.peer_connected(peer)
    frame = {"op": "call_service", "service": "/simbridge/access", "id": "a"}
    rosbridge_of(graph).receive(peer, json.dumps(frame), 0.0)
    return next(m for m in peer.take() if m.get("op") == "service_response")


def test_access_tells_a_student_its_robot_and_that_it_is_not_admin() -> None:
    graph, guard, world = setup(client_tokens=TOKENS, admin_token="the-admin-token")
    world.set_robot_params("r3", {"mass": 3.0})
    world.set_robot_realism("r3", {"enabled": True})
    reply = access(graph, guard, "token-for-r3-cccc")
    info = json.loads(reply["values"]["message"])
    assert info["robots"] == ["r3"] and info["admin"] is False and info["any_robot"] is False
    assert info["client"].endswith("(r3's token)")
    assert info["robot_info"]["r3"]["mass"] == 3.0 and info["robot_info"]["r3"]["own_params"]
    assert info["robot_info"]["r3"]["realism"]
    assert info["robot_info"]["r1"]["mass"] == 1.5 and not info["robot_info"]["r1"]["realism"]
    assert info["robot_info"]["r3"]["start"] == [-2.0, 1.0, 0.0]
    assert info["motion_model"] == "kinematic" and info["estop"]["held"] == []
    admin = json.loads(access(graph, guard, "the-admin-token")["values"]["message"])
    assert admin["admin"] is True and admin["robots"] == ["r1", "r2", "r3", "r4"]


def test_access_is_refused_without_a_token_where_one_is_needed() -> None:
    graph, guard, _ = setup(client_tokens=TOKENS)
    reply = access(graph, guard, None)
    assert reply["result"] is False and "not authenticated" in reply["values"]
