from __future__ import annotations

import json
import math
from typing import Any

import pytest

from simbridge.errors import ProtocolError
from simbridge.graph import Graph
from simbridge.robot.tfrepublisher import TfBuffer, TfRepublisher
from tests.helpers import RecordingPeer, rosbridge_of


def tf(parent: str, child: str, x: float, yaw: float) -> dict[str, Any]:
    return {
        "header": {"frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": x, "y": 0.0, "z": 0.0},
            "rotation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
        },
    }


def test_buffer_composes_through_the_common_ancestor() -> None:
    """odom->base (x 1, yaw 90 deg), base->laser (x 0.5): laser in odom is (1, 0.5)."""
    buffer = TfBuffer()
    buffer.add({"transforms": [tf("odom", "base_link", 1.0, math.pi / 2)]})
    buffer.add({"transforms": [tf("/base_link", "laser", 0.5, 0.0)]})
    (x, y, _z), q = buffer.lookup("odom", "/laser")  # type: ignore[misc]
    assert (x, y) == (pytest.approx(1.0), pytest.approx(0.5))
    assert q[2] == pytest.approx(math.sin(math.pi / 4))
    (x, y, _z), _q = buffer.lookup("laser", "odom")  # type: ignore[misc]
    assert (x, y) == (pytest.approx(-0.5), pytest.approx(1.0))
    assert buffer.lookup("odom", "elsewhere") is None


def call(graph: Graph, peer: RecordingPeer, **body: Any) -> None:
    rosbridge_of(graph).receive(peer, json.dumps(body), 0.0)


def test_republish_service_feeds_a_topic_and_drops_it_after_the_timeout() -> None:
    """/republish_tfs names a TFArray topic; transforms that did not move are not re-sent."""
    graph = Graph()
    repub = TfRepublisher(graph)
    tf_topic = graph.advertise("/tf", "tf2_msgs/msg/TFMessage", "/sim")
    client = RecordingPeer(graph)
    call(
        graph,
        client,
        op="call_service",
        service="/republish_tfs",
        id=1,
        args={
            "source_frames": ["base_link"],
            "target_frame": "odom",
            "trans_thres": 0.01,
            "angular_thres": 0.1,
            "rate": 10.0,
            "timeout": {"secs": 1, "nsecs": 0},
        },
    )
    name = client.take()[0]["values"]["topic_name"]
    call(graph, client, op="subscribe", topic=name, type="tf2_web_republisher/TFArray")
    graph.publish(tf_topic, {"transforms": [tf("odom", "base_link", 2.0, 0.0)]}, 0.0)
    repub.tick(0.0)
    (msg,) = client.take()
    assert msg["msg"]["transforms"][0]["transform"]["translation"]["x"] == 2.0
    repub.tick(0.2)
    assert client.take() == []  # nothing moved
    call(graph, client, op="unsubscribe", topic=name)
    repub.tick(0.3)
    repub.tick(1.4)
    assert name not in graph.topics.topics and repub.requests == []
    assert graph.topics.topics["/tf"].internal == []  # stops following /tf when idle


def test_action_goal_gets_feedback_until_cancelled() -> None:
    """TFSubscription goal: feedback with the transforms; cancel ends it with status 5."""
    graph = Graph()
    repub = TfRepublisher(graph)
    tf_topic = graph.advertise("/tf", "tf2_msgs/msg/TFMessage", "/sim")
    client = RecordingPeer(graph)
    goal = {"source_frames": ["base_link"], "target_frame": "odom", "rate": 10.0}
    call(
        graph,
        client,
        op="send_action_goal",
        action="/tf2_web_republisher",
        action_type="tf2_web_republisher_interfaces/TFSubscription",
        args=goal,
        id="g",
        feedback=True,
    )
    graph.publish(tf_topic, {"transforms": [tf("odom", "base_link", 2.0, 0.0)]}, 0.0)
    repub.tick(0.0)
    (feedback,) = client.take()
    assert feedback["op"] == "action_feedback" and feedback["id"] == "g"
    assert feedback["values"]["transforms"][0]["child_frame_id"] == "base_link"
    call(graph, client, op="cancel_action_goal", action="/tf2_web_republisher", id="g")
    (result,) = client.take()
    assert (result["op"], result["status"], result["result"]) == ("action_result", 5, True)
    assert repub.requests == []


def test_a_late_subscriber_of_a_republished_topic_gets_static_transforms() -> None:
    """Transforms due before anyone subscribed are sent once a subscriber arrives."""
    graph = Graph()
    repub = TfRepublisher(graph)
    static = graph.advertise("/tf_static", "tf2_msgs/msg/TFMessage", "/sim", latch=True)
    graph.publish(static, {"transforms": [tf("base_link", "laser", 0.1, 0.0)]}, 0.0)
    client = RecordingPeer(graph)
    call(
        graph,
        client,
        op="call_service",
        service="/republish_tfs",
        id=1,
        args={"source_frames": ["laser"], "target_frame": "base_link", "rate": 10.0},
    )
    name = client.take()[0]["values"]["topic_name"]
    repub.tick(0.0)  # nobody listens yet
    call(graph, client, op="subscribe", topic=name)
    repub.tick(0.1)
    (msg,) = client.take()
    assert msg["msg"]["transforms"][0]["child_frame_id"] == "laser"


@pytest.mark.parametrize(("trans", "angular"), [(-1.0, 2.0), (0.01, -1.0), (0.0, 2.0)])
def test_a_threshold_of_zero_or_below_sends_every_tick(trans: float, angular: float) -> None:
    """As tf2_web_republisher's TFPair: the transform goes every tick, moved or not."""
    graph = Graph()
    repub = TfRepublisher(graph)
    tf_topic = graph.advertise("/tf", "tf2_msgs/msg/TFMessage", "/sim")
    client = RecordingPeer(graph)
    call(graph, client, **goal_op("g", trans_thres=trans, angular_thres=angular))
    graph.publish(tf_topic, {"transforms": [tf("odom", "base_link", 2.0, 0.0)]}, 0.0)
    for tick in range(3):
        repub.tick(tick * 0.1)
    sent = [m for m in client.take() if m["op"] == "action_feedback"]
    assert len(sent) == 3


def goal_op(goal_id: str, **args: Any) -> dict[str, Any]:
    request = {"source_frames": ["base_link"], "target_frame": "odom", "rate": 10.0}
    return {
        "op": "send_action_goal",
        "action": "/tf2_web_republisher",
        "action_type": "tf2_web_republisher_interfaces/TFSubscription",
        "args": {**request, **args},
        "id": goal_id,
        "feedback": True,
    }


@pytest.mark.parametrize(
    ("args", "error"),
    [
        ({"source_frames": ["\ud800"]}, "lone UTF-16 surrogate"),
        ({"target_frame": "od\x00om"}, "NUL"),
        ({"trans_thres": -math.inf}, "trans_thres must be a finite number"),
        ({"angular_thres": math.nan}, "angular_thres must be a finite number"),
        ({"rate": -1.0}, "rate must be a finite number >= 0"),
        ({"source_frames": ["f"] * 101}, "at most 100"),
        ({"source_frames": ["f"] * 100, "rate": 20.0}, "tf_transforms_per_client"),
    ],
)
def test_a_goal_that_would_fail_or_cost_too_much_is_refused(args: Any, error: str) -> None:
    graph = Graph()
    repub = TfRepublisher(graph)
    client = RecordingPeer(graph)
    op = _goal(graph, client, goal_op("g", **args))
    if isinstance(op, ProtocolError):  # a lone surrogate: the session refuses the whole frame
        assert error in str(op)
        return
    rosbridge_of(graph).dispatch(client, op, 0.0)
    (result,) = client.take()
    assert (result["op"], result["result"]) == ("action_result", False)
    assert error in result["values"]
    assert repub.requests == []


def _goal(graph: Graph, client: RecordingPeer, body: dict[str, Any]) -> Any:
    """The op as parsed (a frame with a lone surrogate cannot be encoded to send)."""
    (op,) = client.session.parse(json.dumps(body, ensure_ascii=True), 0.0)
    return op


def test_requests_are_counted_per_client_and_go_with_it() -> None:
    """The 11th request of a client is refused; the others' are not; a leaving client's go."""
    graph = Graph()
    repub = TfRepublisher(graph)
    graph.watch(repub)
    one, two = RecordingPeer(graph), RecordingPeer(graph)
    for n in range(11):
        call(graph, one, **goal_op(f"g{n}"))
    refused = [m for m in one.take() if m["op"] == "action_result"]
    assert len(refused) == 1 and "tf_requests_per_client" in refused[0]["values"]
    call(graph, two, **goal_op("mine"))
    assert two.take() == [] and len(repub.requests) == 11
    rosbridge_of(graph).remove_peer(one)
    assert [r.owner for r in repub.requests] == [two]
