from __future__ import annotations

import itertools
import json
import math
from typing import Any

import pytest

from simbridge.app.config import Params, WorldSpec, load_world
from simbridge.graph import Graph
from simbridge.graph.paramservices import install_parameter_services
from simbridge.graph.rosapi import install_rosapi
from simbridge.robot.bridge import RobotBridge
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


@pytest.fixture
def setup() -> tuple[Graph, World, RobotBridge]:
    graph = Graph(wall_clock_ns=lambda: 42_000_000_007)
    world = World(load_world(None), Params())
    return graph, world, RobotBridge(graph, world)


def sub(peer: RecordingPeer, graph: Graph, topic: str) -> None:
    rosbridge_of(graph).receive(peer, json.dumps({"op": "subscribe", "topic": topic}), 0.0)


def pub(peer: RecordingPeer, graph: Graph, topic: str, msg: Any) -> None:
    rosbridge_of(graph).receive(
        peer, json.dumps({"op": "publish", "topic": topic, "msg": msg}), 0.0
    )


def test_odom_carries_pose_quaternion_and_applied_twist(setup: Any) -> None:
    """/odom: frames odom/base_link, w = cos(theta/2), z = sin(theta/2), clamped twist."""
    graph, world, bridge = setup
    peer = RecordingPeer(graph)
    sub(peer, graph, "/odom")
    world.command("", 0.9, 1.0)
    world.step()
    bridge.publish(0.0)
    odom = next(m["msg"] for m in peer.take() if m["topic"] == "/odom")
    assert odom["header"] == {"stamp": {"sec": 42, "nanosec": 7}, "frame_id": "odom"}
    assert odom["child_frame_id"] == "base_link"
    theta = world.robots[""].state.theta
    q = odom["pose"]["pose"]["orientation"]
    assert (q["z"], q["w"]) == pytest.approx((math.sin(theta / 2), math.cos(theta / 2)))
    assert odom["twist"]["twist"]["linear"]["x"] == 0.5
    assert odom["twist"]["twist"]["angular"]["z"] == 1.0
    assert odom["pose"]["pose"]["position"]["x"] == pytest.approx(0.5 * 0.05)


def test_tf_matches_odom_and_tf_static_holds_the_laser_mount(setup: Any) -> None:
    """/tf odom -> base_link equals the odom pose; /tf_static base_link -> laser is latched."""
    graph, world, bridge = setup
    world.params = Params.from_flat({**world.params.flat(), "lidar.mount": [0.05, 0.0, math.pi]})
    bridge.publish_static(0.0)
    peer = RecordingPeer(graph)
    sub(peer, graph, "/tf_static")
    sub(peer, graph, "/tf")
    world.command("", 0.2, 0.0)
    world.step()
    bridge.publish(0.0)
    msgs = {m["topic"]: m["msg"] for m in peer.take()}
    static = msgs["/tf_static"]["transforms"][0]
    assert (static["header"]["frame_id"], static["child_frame_id"]) == ("base_link", "laser")
    assert static["transform"]["translation"]["x"] == 0.05
    assert static["transform"]["rotation"]["z"] == pytest.approx(1.0)
    tf = msgs["/tf"]["transforms"][0]
    assert tf["transform"]["translation"]["x"] == pytest.approx(0.01)


def test_scan_is_published_at_the_lidar_rate(setup: Any) -> None:
    """At 20 Hz steps and a 10 Hz LiDAR, every other step carries a scan."""
    graph, world, bridge = setup
    peer = RecordingPeer(graph)
    sub(peer, graph, "/scan")
    for _ in range(10):
        world.step()
        bridge.publish(0.0)
    scans = [m["msg"] for m in peer.take() if m["topic"] == "/scan"]
    assert len(scans) == 5
    assert scans[0]["header"]["frame_id"] == "laser"
    assert len(scans[0]["ranges"]) == 360
    assert scans[0]["intensities"] == []


def test_cmd_vel_commands_the_robot(setup: Any) -> None:
    """A Twist on /cmd_vel sets the robot's command (clamped at step)."""
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    pub(peer, graph, "/cmd_vel", {"linear": {"x": 0.2}, "angular": {"z": -0.4}})
    assert (world.robots[""].cmd_v, world.robots[""].cmd_omega) == (0.2, -0.4)
    assert peer.take() == []


def test_non_finite_cmd_vel_is_refused_to_its_sender(setup: Any) -> None:
    """Null (NaN) velocity: status error to the sender, the robot keeps its command."""
    graph, world, _ = setup
    peer, other = RecordingPeer(graph, "a"), RecordingPeer(graph, "b")
    pub(peer, graph, "/cmd_vel", {"linear": {"x": 0.2}})
    pub(peer, graph, "/cmd_vel", {"linear": {"x": None}})
    (status,) = peer.take()
    assert status["op"] == "status" and "finite" in status["msg"]
    assert world.robots[""].cmd_v == 0.2
    assert other.take() == []


def test_nothing_is_built_for_topics_nobody_listens_to(setup: Any) -> None:
    """No subscriber: no /odom or /scan encoding work."""
    _graph, world, bridge = setup
    calls = []
    original = world.scan
    world.scan = lambda name: calls.append(name) or original(name)  # type: ignore[method-assign]
    for _ in range(4):
        world.step()
        bridge.publish(0.0)
    assert calls == []


def test_parameters_of_the_robot_are_live(setup: Any) -> None:
    """Setting lidar.mount re-publishes /tf_static; invalid values change nothing."""
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    sub(peer, graph, "/tf_static")
    peer.take()
    graph.params.set("/virtual_robot", {"lidar.mount": [0.1, 0.0, 0.0]})
    (msg,) = peer.take()
    assert msg["msg"]["transforms"][0]["transform"]["translation"]["x"] == 0.1
    with pytest.raises(Exception, match="greater than 0"):
        graph.params.set("/virtual_robot", {"robot.mass": 0.0, "robot.inertia": 1.0})
    assert world.params.robot.inertia == 0.0075


def _steps(
    graph: Graph, world: World, bridge: RobotBridge, peer: RecordingPeer, n: int
) -> list[list[str]]:
    """Step ``n`` times; return the robots whose /scan each step carried."""
    steps = []
    for _ in range(n):
        world.step()
        bridge.publish(0.0)
        topics = [m["topic"] for m in peer.take() if m["topic"].endswith("/scan")]
        steps.append(sorted(t.split("/")[1] for t in topics))
    return steps


def _call(peer: RecordingPeer, graph: Graph, service: str, args: Any) -> Any:
    op = {"op": "call_service", "service": service, "args": args, "id": "c"}
    rosbridge_of(graph).receive(peer, json.dumps(op), 0.0)
    (reply,) = [m for m in peer.take() if m["op"] == "service_response"]
    return reply


def test_robots_take_turns_to_scan_even_after_kills_and_spawns() -> None:
    """Each robot scans at the LiDAR rate, at its own offset: a step casts half the scans.

    The first step scans every robot; after it, with a 10 Hz LiDAR and 20 Hz steps, every step
    carries two of the four robots' scans, each robot's two steps apart. Robots killed and
    spawned in their place take the turns they left (the steps stay even).
    """
    graph = Graph(wall_clock_ns=lambda: 42_000_000_007)
    names = ["r0", "r1", "r2", "r3"]
    spec = WorldSpec.parse(
        {
            "walls": [[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]],
            "robots": [{"name": n, "pose": [k - 1.5, 0.0, 0.0]} for k, n in enumerate(names)],
        }
    )
    world = World(spec, Params())
    bridge = RobotBridge(graph, world)
    peer = RecordingPeer(graph)
    for n in names:
        sub(peer, graph, f"/{n}/scan")
    steps = _steps(graph, world, bridge, peer, 9)
    assert steps[0] == names
    assert all(len(step) == 2 for step in steps[1:])
    for n in names:
        at = [k for k, step in enumerate(steps) if n in step][1:]
        assert all(b - a == 2 for a, b in itertools.pairwise(at))
    # r0 and r2 scan on the same steps; in their place, n0 and n2 take their turns
    together = [step for step in steps[1:] if "r0" in step]
    assert all(step == ["r0", "r2"] for step in together)
    for name in ("r0", "r2"):
        assert _call(peer, graph, "/kill", {"name": name})["result"] is True
    for name, y in (("n0", 2.0), ("n2", -2.0)):
        assert _call(peer, graph, "/spawn", {"x": 0.0, "y": y, "name": name})["result"] is True
        sub(peer, graph, f"/{name}/scan")
    steps = _steps(graph, world, bridge, peer, 8)
    assert all(len(step) == 2 for step in steps), steps


def test_a_steps_odom_is_flushed_before_its_scans_are_cast(setup: Any) -> None:
    """What holds messages back (the Zenoh link) is told to send /odom before the scans."""
    graph, world, bridge = setup
    peer = RecordingPeer(graph)
    sub(peer, graph, "/odom")
    sub(peer, graph, "/scan")
    seen: list[str] = []
    graph.topics.taps.append(lambda topic, _out, _source: seen.append(topic.name))
    graph.topics.flushers.append(lambda: seen.append("flush"))
    for _ in range(4):
        world.step()
        bridge.publish(0.0)
    # every step /odom; every other step (10 Hz LiDAR, 20 Hz steps) a flush, then /scan
    assert seen == ["/odom", "flush", "/scan", "/odom"] * 2, seen


def test_ground_truth_is_odom_by_default_and_odom_drifts_from_it_under_a_profile(
    setup: Any,
) -> None:
    """/ground_truth beside /odom; the profile is ROS 2 parameters of /virtual_robot."""
    graph, world, bridge = setup
    install_rosapi(graph)
    install_parameter_services(graph)
    peer = RecordingPeer(graph)
    for topic in ("/odom", "/ground_truth", "/tf"):
        sub(peer, graph, topic)

    def drive() -> dict[str, Any]:
        world.command("", 0.2, 0.4)
        for _ in range(20):
            world.step()
        peer.take()
        bridge.publish(0.0)
        return {m["topic"]: m["msg"] for m in peer.take()}

    first = drive()
    assert first["/ground_truth"]["pose"] == first["/odom"]["pose"]
    assert first["/ground_truth"]["child_frame_id"] == "base_link"
    (slip,) = _service(graph, "/virtual_robot/describe_parameters", {"names": ["realism.slip"]})[
        "descriptors"
    ]
    assert slip["floating_point_range"] == [{"from_value": 0.0, "to_value": 1.0, "step": 0.0}]
    assert slip["description"] == Params.describe()["realism.slip"]
    changes = [
        {"name": "realism.enabled", "value": {"type": 1, "bool_value": True}},
        {"name": "realism.slip", "value": {"type": 3, "double_value": 0.2}},
    ]
    done = _service(graph, "/virtual_robot/set_parameters_atomically", {"parameters": changes})
    assert done["result"]["successful"] is True
    second = drive()
    truth, odom = (second[t]["pose"]["pose"]["position"] for t in ("/ground_truth", "/odom"))
    assert math.hypot(truth["x"] - odom["x"], truth["y"] - odom["y"]) > 0.01
    tf = second["/tf"]["transforms"][0]["transform"]["translation"]
    assert (tf["x"], tf["y"]) == (odom["x"], odom["y"])
    assert truth["x"] == world.robots[""].state.x


def _service(graph: Graph, service: str, args: Any) -> dict[str, Any]:
    peer = RecordingPeer(graph)
    body = {"op": "call_service", "service": service, "id": 1, "args": args}
    rosbridge_of(graph).receive(peer, json.dumps(body), 0.0)
    (reply,) = peer.take()
    assert reply["result"] is True, reply
    return dict(reply["values"])
