"""graph.topics: publish and subscribe through the graph, as clients do (latched, typed)."""

from __future__ import annotations

import pytest

from simbridge.graph import Graph
from simbridge.graph.topics import TopicQos
from tests.helpers import RecordingPeer, clocked_graph, op, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    return clocked_graph()


def test_every_subscriber_the_publisher_included_receives_a_message_once(graph: Graph) -> None:
    """Two Topic objects on one name in one client still get each message once."""
    a, b = RecordingPeer(graph, "a"), RecordingPeer(graph, "b")
    op(a, graph, op="advertise", topic="/chatter", type="std_msgs/String")
    op(a, graph, op="subscribe", topic="/chatter", id="s1")
    op(a, graph, op="subscribe", topic="/chatter", id="s2", type="std_msgs/msg/String")
    op(b, graph, op="subscribe", topic="/chatter")
    op(a, graph, op="publish", topic="/chatter", msg={"data": "hi"})
    expected = {"op": "publish", "topic": "/chatter", "msg": {"data": "hi"}}
    assert a.take() == [expected]
    assert b.take() == [expected]


def test_publish_topic_echoes_the_spelling_of_each_subscription(graph: Graph) -> None:
    """A client that subscribed to 'chatter' gets topic 'chatter' back."""
    a = RecordingPeer(graph)
    op(a, graph, op="subscribe", topic="chatter", type="std_msgs/String")
    op(a, graph, op="publish", topic="/chatter", msg={})
    assert a.take()[0]["topic"] == "chatter"


def test_publish_validates_and_fills_defaults(graph: Graph) -> None:
    """A known type is validated: defaults filled, bad fields refused with a status error."""
    a = RecordingPeer(graph)
    op(a, graph, op="advertise", topic="/v", type="geometry_msgs/Vector3")
    op(a, graph, op="subscribe", topic="/v")
    op(a, graph, op="publish", topic="/v", msg={"x": 1})
    assert a.take() == [{"op": "publish", "topic": "/v", "msg": {"x": 1.0, "y": 0.0, "z": 0.0}}]
    op(a, graph, op="publish", topic="/v", msg={"w": 1}, id="p1")
    (status,) = a.take()
    assert status["op"] == "status" and status["level"] == "error"
    assert "does not have a field w" in status["msg"]
    assert status["id"] == "p1"


def test_publish_to_an_unadvertised_topic_without_type_is_refused(graph: Graph) -> None:
    """The type cannot be inferred: clear error, nothing created."""
    a = RecordingPeer(graph)
    op(a, graph, op="publish", topic="/nobody", msg={})
    assert "cannot infer the type" in a.take()[0]["msg"]
    assert "/nobody" not in graph.topics.topics


def test_type_conflict_is_refused_and_the_topic_keeps_its_type(graph: Graph) -> None:
    """Advertising /cmd_vel as String while it is a Twist is an error."""
    a = RecordingPeer(graph)
    graph.advertise("/cmd_vel", "geometry_msgs/msg/Twist", "/sim")
    op(a, graph, op="advertise", topic="/cmd_vel", type="std_msgs/String")
    assert "already established with type geometry_msgs/msg/Twist" in a.take()[0]["msg"]
    assert graph.topics.topics["/cmd_vel"].type == "geometry_msgs/msg/Twist"


def test_subscription_to_a_future_topic_receives_it_once_advertised(graph: Graph) -> None:
    """An untyped subscribe waits for the topic (rosbridge #1142 drops it instead)."""
    a, b = RecordingPeer(graph, "a"), RecordingPeer(graph, "b")
    op(a, graph, op="subscribe", topic="/later")
    op(b, graph, op="advertise", topic="/later", type="std_msgs/String")
    op(b, graph, op="publish", topic="/later", msg={"data": "now"})
    assert a.take() == [{"op": "publish", "topic": "/later", "msg": {"data": "now"}}]


def test_unknown_types_pass_through_unchanged(graph: Graph) -> None:
    """A type simbridge does not know is relayed as sent, without validation."""
    a = RecordingPeer(graph)
    op(a, graph, op="advertise", topic="/custom", type="my_pkg/msg/Thing")
    op(a, graph, op="subscribe", topic="/custom")
    op(a, graph, op="publish", topic="/custom", msg={"anything": [1, "x"]})
    assert a.take()[0]["msg"] == {"anything": [1, "x"]}


def test_latched_message_reaches_late_subscribers(graph: Graph) -> None:
    """Advertise latch: true keeps the last message for subscribers that come later."""
    a, late = RecordingPeer(graph, "a"), RecordingPeer(graph, "late")
    op(a, graph, op="advertise", topic="/map_name", type="std_msgs/String", latch=True)
    op(a, graph, op="publish", topic="/map_name", msg={"data": "lab"})
    op(late, graph, op="subscribe", topic="/map_name")
    assert late.take() == [{"op": "publish", "topic": "/map_name", "msg": {"data": "lab"}}]


def test_a_publish_that_latches_a_topic_counts_as_a_change_once(graph: Graph) -> None:
    """The Zenoh link redoes its subscriptions when the change counter moves (latched apart)."""
    a = RecordingPeer(graph, "a")
    op(a, graph, op="advertise", topic="/note", type="std_msgs/String")
    before = graph.topics.changes
    op(a, graph, op="publish", topic="/note", msg={"data": "x"}, latch=True)
    assert graph.topics.topics["/note"].latch and graph.topics.changes == before + 1
    op(a, graph, op="publish", topic="/note", msg={"data": "y"}, latch=True)
    assert graph.topics.changes == before + 1


def test_unsubscribe_by_id_keeps_the_other_ids(graph: Graph) -> None:
    """Removing one of two ids keeps delivery; removing all stops it."""
    a, pub = RecordingPeer(graph, "a"), RecordingPeer(graph, "pub")
    op(pub, graph, op="advertise", topic="/t", type="std_msgs/Empty")
    op(a, graph, op="subscribe", topic="/t", id="1")
    op(a, graph, op="subscribe", topic="/t", id="2")
    op(a, graph, op="unsubscribe", topic="/t", id="1")
    op(pub, graph, op="publish", topic="/t", msg={})
    assert len(a.take()) == 1
    op(a, graph, op="unsubscribe", topic="/t")
    op(pub, graph, op="publish", topic="/t", msg={})
    assert a.take() == []


def test_disconnect_removes_subscriptions_advertisements_and_topics(graph: Graph) -> None:
    """A client that leaves takes its subscriptions and publishers with it."""
    a = RecordingPeer(graph)
    op(a, graph, op="advertise", topic="/mine", type="std_msgs/String")
    op(a, graph, op="subscribe", topic="/mine")
    rosbridge_of(graph).remove_peer(a)
    assert "/mine" not in graph.topics.topics


def test_a_topic_offers_the_ros_2_default_qos_and_a_latched_one_transient_local_depth_1(
    graph: Graph,
) -> None:
    """What the ROS 2 front ends declare: reliable always; latched topics keep their last one."""
    odom = graph.advertise("/odom", "nav_msgs/msg/Odometry", "/virtual_robot")
    walls = graph.advertise("/walls", "visualization_msgs/msg/Marker", "/virtual_robot", latch=True)
    assert odom.qos == TopicQos(reliable=True, transient_local=False, depth=10)
    assert walls.qos == TopicQos(reliable=True, transient_local=True, depth=1)
    graph.topics.latch(odom)  # a client's latched publish makes the topic latched from then on
    assert odom.qos.transient_local
