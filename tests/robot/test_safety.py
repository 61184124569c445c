from __future__ import annotations

import json
from typing import Any

from simbridge.app.config import Params, SafetyParams, WorldSpec
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.safety import Safety
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


def make(**safety: Any) -> tuple[Graph, World, Safety]:
    graph = Graph()
    world = World(WorldSpec(), Params(safety=SafetyParams(**safety)))
    RobotBridge(graph, world)
    safety = Safety(graph, world)
    graph.watch(safety)
    return graph, world, safety


def drive(graph: Graph, peer: RecordingPeer, x: Any, now: float) -> None:
    msg = {"linear": {"x": x}, "angular": {"z": 0.0}}
    rosbridge_of(graph).receive(
        peer, json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": msg}), now
    )


def test_watchdog_is_off_by_default_the_robot_keeps_its_last_command() -> None:
    graph, world, safety = make()
    peer = RecordingPeer(graph)
    drive(graph, peer, 0.3, 0.0)
    for k in range(200):
        safety.tick(k * 0.05)
    assert world.robots[""].cmd_v == 0.3 and safety.stops == 0


def test_watchdog_stops_a_robot_after_the_timeout_without_commands() -> None:
    graph, world, safety = make(cmd_vel_timeout=0.5)
    peer = RecordingPeer(graph)
    drive(graph, peer, 0.3, 0.0)
    safety.tick(0.0)
    for k in range(1, 10):  # commands every 0.1 s keep it going
        drive(graph, peer, 0.3, k * 0.1)
        safety.tick(k * 0.1)
    assert world.robots[""].cmd_v == 0.3
    safety.tick(1.35)
    assert world.robots[""].cmd_v == 0.3  # 0.45 s since the last command
    safety.tick(1.45)
    assert world.robots[""].cmd_v == 0.0 and safety.stops == 1


def test_refused_non_finite_commands_do_not_feed_the_watchdog() -> None:
    graph, world, safety = make(cmd_vel_timeout=0.5)
    peer = RecordingPeer(graph)
    drive(graph, peer, 0.3, 0.0)
    safety.tick(0.0)
    for k in range(1, 10):
        rosbridge_of(graph).receive(
            peer,
            '{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":NaN}}}',
            k * 0.1,
        )
        safety.tick(k * 0.1)
    assert world.robots[""].cmd_v == 0.0


def test_stop_on_disconnect_stops_only_the_robot_of_the_client_that_left() -> None:
    graph, world, safety = make(stop_on_disconnect=True)
    driver, other = RecordingPeer(graph), RecordingPeer(graph)
    drive(graph, driver, 0.2, 0.0)
    rosbridge_of(graph).remove_peer(other)
    assert world.robots[""].cmd_v == 0.2
    rosbridge_of(graph).remove_peer(driver)
    assert world.robots[""].cmd_v == 0.0 and safety.stops == 1


def test_disconnect_leaves_the_robot_moving_when_the_option_is_off() -> None:
    graph, world, _ = make()
    driver = RecordingPeer(graph)
    drive(graph, driver, 0.2, 0.0)
    rosbridge_of(graph).remove_peer(driver)
    assert world.robots[""].cmd_v == 0.2


def test_a_lost_commander_stops_its_robot_by_default_a_closed_one_does_not() -> None:
    """Lost (no close frame): nobody is left to stop the robot. Closed: the course's robot."""
    graph, world, safety = make()
    driver, other = RecordingPeer(graph), RecordingPeer(graph)
    drive(graph, driver, 0.2, 0.0)
    rosbridge_of(graph).remove_peer(other, lost=True)  # not the one whose command the robot follows
    assert world.robots[""].cmd_v == 0.2
    rosbridge_of(graph).remove_peer(driver, lost=True)
    assert world.robots[""].cmd_v == 0.0 and safety.stops == 1
    driver = RecordingPeer(graph)
    drive(graph, driver, 0.2, 1.0)
    rosbridge_of(graph).remove_peer(driver)
    assert world.robots[""].cmd_v == 0.2 and safety.stops == 1
    graph, world, safety = make(stop_on_lost_link=False)
    driver = RecordingPeer(graph)
    drive(graph, driver, 0.2, 0.0)
    rosbridge_of(graph).remove_peer(driver, lost=True)
    assert world.robots[""].cmd_v == 0.2


def test_a_removed_robot_is_forgotten_and_its_topic_can_go() -> None:
    graph = Graph()
    spec = WorldSpec.parse(
        {"robots": [{"name": "r1", "pose": [0, 0, 0]}, {"name": "r2", "pose": [1, 0, 0]}]}
    )
    world = World(spec, Params(safety=SafetyParams(cmd_vel_timeout=0.5)))
    bridge = RobotBridge(graph, world)
    safety = Safety(graph, world)
    graph.watch(safety)
    bridge.on_robot_removed.append(safety.forget)
    world.remove("r2")
    bridge.remove_robot("r2")
    assert "/r2/cmd_vel" not in graph.topics.topics
    safety.tick(0.0)
    assert "/r2/cmd_vel" not in graph.topics.topics and "/r1/cmd_vel" in graph.topics.topics


def test_watchdog_times_a_command_from_its_arrival_not_from_the_next_tick() -> None:
    """A command that arrives between ticks is stale a timeout after it arrived.

    Timed from the tick after it, the stop came up to a timeout and two ticks after the
    command (bench hostile: 600 ms for a 0.5 s timeout under load).
    """
    graph, world, safety = make(cmd_vel_timeout=0.5)
    peer = RecordingPeer(graph)
    safety.tick(0.0)
    drive(graph, peer, 0.3, 0.04)  # 10 ms before the tick at 0.05
    for k in range(1, 11):  # ticks 0.05 .. 0.50: 0.46 s since the command at most
        safety.tick(k * 0.05)
    assert world.robots[""].cmd_v == 0.3
    safety.tick(0.55)  # 0.51 s since the command (0.50 since the tick that saw it)
    assert world.robots[""].cmd_v == 0.0 and safety.stops == 1
