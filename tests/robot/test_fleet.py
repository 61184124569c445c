from __future__ import annotations

import json
import math
from typing import Any

import pytest

from simbridge.app.config import Params, WorldSpec
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


BOX = {"walls": [[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]]}


@pytest.fixture
def setup() -> tuple[Graph, World, RobotBridge]:
    graph = Graph(wall_clock_ns=lambda: 42_000_000_007)
    spec = WorldSpec.parse(
        {**BOX, "robots": [{"name": "r1", "pose": [-1, 0, 0]}, {"name": "r2", "pose": [1, 0, 0]}]}
    )
    world = World(spec, Params())
    return graph, world, RobotBridge(graph, world)


def call(peer: RecordingPeer, graph: Graph, service: str, args: Any) -> Any:
    rosbridge_of(graph).receive(
        peer, json.dumps({"op": "call_service", "service": service, "args": args, "id": "c"}), 0.0
    )
    (reply,) = [m for m in peer.take() if m["op"] == "service_response"]
    return reply


def sub(peer: RecordingPeer, graph: Graph, topic: str) -> None:
    rosbridge_of(graph).receive(peer, json.dumps({"op": "subscribe", "topic": topic}), 0.0)


def test_each_named_robot_has_namespaced_topics_and_frames_on_shared_tf(setup: Any) -> None:
    graph, world, bridge = setup
    peer = RecordingPeer(graph)
    for topic in ("/r1/odom", "/r2/scan", "/tf", "/tf_static"):
        sub(peer, graph, topic)
    bridge.publish_static(0.0)
    world.step()
    bridge.publish(0.0)
    msgs = {m["topic"]: m["msg"] for m in peer.take()}
    odom = msgs["/r1/odom"]
    assert (odom["header"]["frame_id"], odom["child_frame_id"]) == ("r1/odom", "r1/base_link")
    assert msgs["/r2/scan"]["header"]["frame_id"] == "r2/laser"
    tf = [(t["header"]["frame_id"], t["child_frame_id"]) for t in msgs["/tf"]["transforms"]]
    assert tf == [("r1/odom", "r1/base_link"), ("r2/odom", "r2/base_link")]
    static = msgs["/tf_static"]["transforms"]
    assert [(t["header"]["frame_id"], t["child_frame_id"]) for t in static] == [
        ("r1/base_link", "r1/laser"),
        ("r2/base_link", "r2/laser"),
    ]
    assert "/odom" not in graph.topics.topics
    assert {"/r1/cmd_vel", "/r2/cmd_vel", "/r1/contact"} <= set(graph.topics.topics)


def test_cmd_vel_of_one_robot_moves_only_that_robot(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    msg = {"op": "publish", "topic": "/r2/cmd_vel", "msg": {"linear": {"x": 0.3}}}
    rosbridge_of(graph).receive(peer, json.dumps(msg), 0.0)
    assert (world.robots["r1"].cmd_v, world.robots["r2"].cmd_v) == (0.0, 0.3)


def test_spawn_creates_a_robot_with_its_topics_and_tf_static(setup: Any) -> None:
    graph, world, _ = setup
    peer, listener = RecordingPeer(graph), RecordingPeer(graph)
    reply = call(peer, graph, "/spawn", {"x": 2.0, "y": 2.0, "theta": 1.0, "name": "r3"})
    assert reply["result"] is True and reply["values"] == {"name": "r3"}
    assert (world.robots["r3"].state.x, world.robots["r3"].state.theta) == (2.0, 1.0)
    assert "/r3/odom" in graph.topics.topics and "/r3/teleport_absolute" in graph.services.services
    assert call(peer, graph, "/spawn", {"x": 3.0, "y": 3.0})["values"] == {"name": "robot1"}
    sub(listener, graph, "/tf_static")
    (latched,) = listener.take()
    frames = {t["child_frame_id"] for t in latched["msg"]["transforms"]}
    assert {"r3/laser", "robot1/laser"} <= frames


@pytest.mark.parametrize(
    ("args", "error"),
    [
        ({"x": 4.95, "y": 0.0, "name": "r3"}, "overlaps the wall"),
        ({"x": 1.1, "y": 0.0, "name": "r3"}, "overlaps another robot"),
        ({"x": 2.0, "y": 2.0, "name": "r1"}, "already exists"),
        ({"x": "a", "name": "r3"}, "field x must be a float32"),
        ({"x": 2.0, "name": "r 3"}, "not a valid ROS name"),
        ({"x": 2.0, "colour": "red"}, "does not have a field colour"),
    ],
)
def test_spawn_refuses_bad_requests_with_the_reason(setup: Any, args: Any, error: str) -> None:
    graph, world, _ = setup
    reply = call(RecordingPeer(graph), graph, "/spawn", args)
    assert reply["result"] is False and error in reply["values"]
    assert list(world.robots) == ["r1", "r2"]


def test_kill_removes_the_robot_its_topics_and_services(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    assert call(peer, graph, "/kill", {"name": "r2"})["result"] is True
    assert list(world.robots) == ["r1"]
    assert not {"/r2/odom", "/r2/scan", "/r2/cmd_vel"} & set(graph.topics.topics)
    assert "/r2/teleport_absolute" not in graph.services.services
    reply = call(peer, graph, "/kill", {"name": "r2"})
    assert reply["result"] is False and "no robot named 'r2'" in reply["values"]
    assert call(peer, graph, "/spawn", {"x": 1.0, "name": "r2"})["result"] is True


def test_teleport_moves_the_robot_and_refuses_occupied_poses(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    reply = call(peer, graph, "/r1/teleport_absolute", {"x": -2.0, "y": 1.0, "theta": math.pi})
    assert reply["result"] is True
    s = world.robots["r1"].state
    assert (s.x, s.y, s.theta) == pytest.approx((-2.0, 1.0, -math.pi))
    reply = call(peer, graph, "/r1/teleport_absolute", {"x": 1.0, "y": 0.1})
    assert reply["result"] is False and "overlaps another robot" in reply["values"]


def test_reset_puts_every_robot_back_spawned_ones_included(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    call(peer, graph, "/spawn", {"x": 2.0, "y": 2.0, "name": "r3"})
    call(peer, graph, "/r3/teleport_absolute", {"x": -3.0, "y": -3.0})
    call(peer, graph, "/r1/teleport_absolute", {"x": -3.0, "y": 3.0})
    assert call(peer, graph, "/reset", {})["result"] is True
    assert [(r.state.x, r.state.y) for r in world.robots.values()] == [
        (-1.0, 0.0),
        (1.0, 0.0),
        (2.0, 2.0),
    ]


def test_contact_is_published_each_step_and_logged_once_to_rosout(setup: Any) -> None:
    """r1 driving into r2: /r1/contact names r2; /rosout says so once per contact."""
    graph, world, bridge = setup
    peer = RecordingPeer(graph)
    sub(peer, graph, "/r1/contact")
    sub(peer, graph, "/rosout")
    world.command("r1", 0.5, 0.0)
    for _ in range(120):
        world.step()
        bridge.publish(0.0)
    msgs = peer.take()
    contacts = [m["msg"] for m in msgs if m["topic"] == "/r1/contact"]
    logs = [m["msg"]["msg"] for m in msgs if m["topic"] == "/rosout"]
    assert contacts and all(c["other"] == "r2" and c["robot"] == "r1" for c in contacts)
    assert contacts[0]["header"]["frame_id"] == "r1/odom"
    assert contacts[0]["normal"]["x"] == pytest.approx(-1.0)
    assert logs == ["robot 'r1' hit robot 'r2' at (0.90, 0.00): motion into it stopped"]
