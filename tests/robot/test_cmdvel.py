from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.app.config import Params, RobotParams, SafetyParams, WorldSpec
from simbridge.errors import ServiceError
from simbridge.graph import Graph
from simbridge.robot.bridge import ROBOT_NODE, RobotBridge
from simbridge.robot.cmdvel import TWIST, TWIST_STAMPED, command_type, convert_twist, twist_of
from simbridge.robot.safety import Safety
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


def make(stamped: bool, **safety: Any) -> tuple[Graph, World, Safety]:
    graph = Graph()
    params = Params(robot=RobotParams(cmd_vel_stamped=stamped), safety=SafetyParams(**safety))
    world = World(WorldSpec(), params)
    RobotBridge(graph, world)
    safety = Safety(graph, world)
    graph.watch(safety)
    return graph, world, safety


def send(peer: RecordingPeer, graph: Graph, op: dict[str, Any], now: float = 0.0) -> None:
    rosbridge_of(graph).receive(peer, json.dumps(op), now)


STAMPED = {
    "header": {"stamp": {"sec": 5, "nanosec": 0}, "frame_id": "base_link"},
    "twist": {"linear": {"x": 0.3}, "angular": {"z": 0.5}},
}


def test_cmd_vel_is_twist_by_default() -> None:
    graph, world, _ = make(stamped=False)
    assert graph.topics.topics["/cmd_vel"].type == TWIST
    peer = RecordingPeer(graph)
    send(peer, graph, {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.3}}})
    assert world.robots[""].cmd_v == 0.3


def test_stamped_parameter_makes_cmd_vel_twist_stamped_and_the_robot_reads_its_twist() -> None:
    graph, world, _ = make(stamped=True)
    assert graph.topics.topics["/cmd_vel"].type == TWIST_STAMPED
    peer = RecordingPeer(graph)
    send(peer, graph, {"op": "advertise", "topic": "/cmd_vel", "type": TWIST_STAMPED})
    send(peer, graph, {"op": "publish", "topic": "/cmd_vel", "msg": STAMPED})
    assert (world.robots[""].cmd_v, world.robots[""].cmd_omega) == (0.3, 0.5)
    assert peer.take() == []


def test_stamped_cmd_vel_refuses_a_twist_publisher_with_the_type_it_expects() -> None:
    graph, world, _ = make(stamped=True)
    peer = RecordingPeer(graph)
    send(peer, graph, {"op": "advertise", "topic": "/cmd_vel", "type": TWIST, "id": "a"})
    [reply] = peer.take()
    assert f"already established with type {TWIST_STAMPED}" in reply["msg"]
    send(peer, graph, {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.3}}})
    assert "linear" in peer.take()[0]["msg"]  # not a TwistStamped field: refused, said why
    assert world.robots[""].cmd_v == 0.0


def test_spawned_robots_get_the_stamped_type_too() -> None:
    graph, world, _ = make(stamped=True)
    peer = RecordingPeer(graph)
    args = {"x": 1.0, "y": 1.0, "theta": 0.0, "name": "r1"}
    send(peer, graph, {"op": "call_service", "service": "/spawn", "args": args, "id": "s"})
    assert peer.take()[0]["result"] is True
    assert graph.topics.topics["/r1/cmd_vel"].type == TWIST_STAMPED
    send(peer, graph, {"op": "publish", "topic": "/r1/cmd_vel", "msg": STAMPED})
    assert world.robots["r1"].cmd_v == 0.3


def test_watchdog_counts_stamped_commands() -> None:
    graph, world, safety = make(stamped=True, cmd_vel_timeout=0.5)
    peer = RecordingPeer(graph)
    for k in range(10):  # commands every 0.1 s keep it going
        send(peer, graph, {"op": "publish", "topic": "/cmd_vel", "msg": STAMPED}, k * 0.1)
        safety.tick(k * 0.1)
    assert world.robots[""].cmd_v == 0.3 and safety.stops == 0
    safety.tick(1.5)
    assert world.robots[""].cmd_v == 0.0 and safety.stops == 1


@pytest.mark.parametrize("value", [True, False])
def test_stamped_parameter_is_refused_at_run_time_saying_why(value: bool) -> None:
    graph, world, _ = make(stamped=False)
    with pytest.raises(ServiceError, match=r"read-only at run time.*startup only"):
        graph.params.set(ROBOT_NODE, {"robot.cmd_vel_stamped": value})
    assert graph.topics.topics["/cmd_vel"].type == TWIST
    assert world.params.robot.cmd_vel_stamped is False


def test_convert_twist_between_twist_and_twist_stamped() -> None:
    twist = {"linear": {"x": 0.2}, "angular": {"z": 0.1}}
    stamped = convert_twist(twist, "geometry_msgs/Twist", TWIST_STAMPED, (3, 4))
    assert stamped == {
        "header": {"stamp": {"sec": 3, "nanosec": 4}, "frame_id": "base_link"},
        "twist": twist,
    }
    assert convert_twist(stamped, TWIST_STAMPED, TWIST, (0, 0)) == twist
    assert convert_twist(twist, TWIST, TWIST, (0, 0)) is twist
    assert convert_twist(twist, "std_msgs/msg/String", TWIST, (0, 0)) is twist
    assert twist_of(stamped) == twist_of(twist) == twist


def test_commands_take_the_target_type_only_between_twist_kinds() -> None:
    assert command_type("geometry_msgs/Twist", TWIST_STAMPED) == TWIST_STAMPED
    assert command_type(TWIST, None) == command_type(TWIST, "") == TWIST
    assert command_type("std_msgs/msg/Float64", TWIST) == "std_msgs/msg/Float64"
