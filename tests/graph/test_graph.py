from __future__ import annotations

import pytest

from simbridge.graph import Graph, Peer, PeerWatcher
from tests.helpers import RecordingPeer, clocked_graph, op, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    return clocked_graph()


def test_bad_frames_and_ops_get_status_errors_and_nothing_else(graph: Graph) -> None:
    """Invalid JSON, unknown ops and wrong fields are answered with status errors."""
    a = RecordingPeer(graph)
    rosbridge_of(graph).receive(a, "{not json", 0.0)
    op(a, graph, op="teleport_me")
    op(a, graph, op="subscribe", topic=5)
    statuses = a.take()
    assert [s["op"] for s in statuses] == ["status"] * 3
    assert "could not decode" in statuses[0]["msg"]
    assert "unknown operation 'teleport_me'" in statuses[1]["msg"]
    assert "topic to be a string" in statuses[2]["msg"]


def test_set_level_none_silences_status(graph: Graph) -> None:
    """A client that asked for level none gets no status messages."""
    a = RecordingPeer(graph)
    op(a, graph, op="set_level", level="none")
    op(a, graph, op="nope")
    assert a.take() == []


def test_rosout_carries_notable_events(graph: Graph) -> None:
    """graph.log publishes an rcl_interfaces/Log on /rosout."""
    a = RecordingPeer(graph)
    op(a, graph, op="subscribe", topic="/rosout")
    graph.log("warn", "something happened")
    (msg,) = a.take()
    assert msg["msg"]["msg"] == "something happened"
    assert msg["msg"]["level"] == 30
    assert msg["msg"]["stamp"] == {"sec": 1_700_000_000, "nanosec": 500_000_000}


def test_rosout_reaches_in_process_subscribers_and_the_taps_without_a_rosbridge_client(
    graph: Graph,
) -> None:
    """Front ends' subscribers (Foxglove channels, ROS 2 nodes) receive /rosout too.

    Each stands in the graph as an in-process subscriber; its front end sends what the delivery
    tap sees.
    """
    got: list[object] = []
    tapped: list[str] = []
    graph.subscribe(
        "/rosout", "rcl_interfaces/msg/Log", "/foxglove_bridge", lambda m, s: got.append(m)
    )
    graph.topics.taps.append(lambda topic, out, source: tapped.append(topic.name))
    graph.log("info", "world reset")
    assert [m["msg"] for m in got] == ["world reset"]  # type: ignore[index]
    assert tapped == ["/rosout"]


class _Leaving(PeerWatcher):
    def __init__(self) -> None:
        self.heard: list[str] = []

    def peer_lost(self, peer: Peer) -> None:
        self.heard.append(f"lost {peer.label}")

    def peer_left(self, peer: Peer) -> None:
        self.heard.append(f"left {peer.label}")


def test_a_watching_part_hears_what_it_overrides_lost_before_left(graph: Graph) -> None:
    """Graph.watch (the builder's wiring): only the methods a part overrides are called."""
    part = _Leaving()
    graph.watch(part)
    assert part.peer_connected not in graph.on_connect
    a, b = RecordingPeer(graph), RecordingPeer(graph)
    rosbridge_of(graph).remove_peer(a)
    rosbridge_of(graph).remove_peer(b, lost=True)
    assert part.heard == [f"left {a.label}", f"lost {b.label}", f"left {b.label}"]
