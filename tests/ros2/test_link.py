"""What every ROS 2 link keeps on the event loop's side (simbridge.ros2.link).

The inbox, the logbook, the refusals, and which of the graph's topics and services a link
mirrors outward.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from typing import Any

from simbridge.graph import BRIDGE_NODE, Graph
from simbridge.graph.access import NO_ROBOT, Access
from simbridge.ros2.link import (
    DRAIN_BATCH,
    INBOX_LIMIT,
    ForeignNode,
    Inbox,
    Logbook,
    Refusals,
    Ros2Peer,
    local_owner,
    local_publisher,
    outward_services,
    outward_topics,
)
from tests.helpers import wait_for


class _Other(ForeignNode):
    """A node of another transport's process."""


def _logbook(graph: Graph | None = None) -> Logbook:
    return Logbook(graph or Graph(), "DDS", "simbridge.test", Counter(), logging.getLogger("t"))


def _inbox(logbook: Logbook, **budget: int) -> Inbox:
    return Inbox(
        logbook,
        max_bytes=budget.get("max_bytes", 10_000_000),
        max_sample=budget.get("max_sample", 1_000),
        dropped="dropped",
        oversized="oversized",
        setting="dds",
    )


def test_a_node_of_another_process_is_never_a_local_node_nor_one_of_another_transport() -> None:
    here, there = ForeignNode("/talker", "a"), ForeignNode("/talker", "b")
    assert str(here) == "/talker" and here != "/talker"
    assert here != there and here == ForeignNode("/talker", "a")
    assert here != _Other("/talker", "a") and len({here, there, _Other("/talker", "a")}) == 3
    assert local_owner("/virtual_robot") == "/virtual_robot"
    assert local_owner(here) is None and local_owner(Ros2Peer()) is None
    assert local_owner(object()) == BRIDGE_NODE  # a rosbridge client


def test_the_outward_walk_gives_local_publishers_and_subscribers_but_not_the_remote_ones() -> None:
    graph = Graph()
    topics = graph.topics
    client = object()
    topics.advertise("/chatter", "std_msgs/msg/String", ForeignNode("/talker", "z"))
    topics.advertise("/chatter", "std_msgs/msg/String", client)
    topics.advertise("/odom", "nav_msgs/msg/Odometry", "/virtual_robot")

    def marker(msg: Any, source: Any) -> None:
        """A remote subscription's stand-in."""

    def listener(msg: Any, source: Any) -> None:
        """An in-process subscriber."""

    topics.subscribe_internal("/odom", "nav_msgs/msg/Odometry", ForeignNode("/echo", "z"), marker)
    topics.subscribe_internal("/cmd_vel", "geometry_msgs/msg/Twist", "/virtual_robot", listener)
    topics.advertise("/mystery", "foo_msgs/msg/Mystery", "/virtual_robot")  # unknown: not
    walked = {t.name: (p, s) for t, p, s in outward_topics(graph, {id(marker)})}
    assert walked["/chatter"] == ([BRIDGE_NODE], [])
    assert walked["/odom"] == (["/virtual_robot"], [])
    assert walked["/cmd_vel"] == ([], ["/virtual_robot"])
    assert "/mystery" not in walked
    assert local_publisher(topics.topics["/chatter"]) == BRIDGE_NODE
    assert local_publisher(topics.topics["/chatter"], clients=False) is None
    assert local_publisher(topics.topics["/odom"], clients=False) == "/virtual_robot"


def test_outward_services_are_the_ones_provided_here() -> None:
    graph = Graph()
    graph.services.add("/reset_here", "std_srvs/srv/Empty", "/sim", lambda request: {})
    remote = {s.name for s, _node in outward_services(graph)}
    assert "/reset_here" in remote
    assert dict((s.name, n) for s, n in outward_services(graph))["/reset_here"] == "/sim"


def test_refusals_are_kept_per_name_counted_and_said_once_per_period() -> None:
    graph = Graph()
    graph.access.guarded = True
    logbook = _logbook(graph)
    refusals = Refusals(graph, Access(NO_ROBOT, False, guarded=True), logbook)
    assert refusals.refused("/cmd_vel", "a sample on")
    assert refusals.refused("/cmd_vel", "a sample on")
    assert refusals.refused("/cmd_vel", "a sample on", count=False)
    assert logbook.stats["refused"] == 2
    assert "/cmd_vel" in refusals.cache and list(logbook.logged) == ["refused /cmd_vel"]


async def test_the_inbox_drops_the_oldest_past_its_bounds_and_drains_in_batches() -> None:
    logbook = _logbook()
    inbox = _inbox(logbook)
    inbox.loop = asyncio.get_running_loop()
    taken: list[bytes] = []
    for k in range(INBOX_LIMIT + 5):
        inbox.put(lambda _name, data: taken.append(data), "/t", k.to_bytes(4, "little"))
    assert len(inbox.samples) == INBOX_LIMIT and logbook.stats["dropped"] == 5
    inbox.drain()
    assert len(taken) == DRAIN_BATCH and taken[0] == (5).to_bytes(4, "little")
    await wait_for(lambda: not inbox.samples and inbox.bytes == 0, timeout=10)
    assert len(taken) == INBOX_LIMIT


async def test_a_batch_past_the_inbox_bytes_loses_its_new_samples_and_oversized_ones_are_said() -> (
    None
):
    logbook = _logbook()
    inbox = _inbox(logbook, max_bytes=2_500, max_sample=1_000)
    inbox.loop = asyncio.get_running_loop()
    taken: list[bytes] = []
    inbox.put_many(
        lambda _n, data: taken.append(data), "/scan", [b"a" * 1_000] * 3 + [b"b" * 1_001]
    )
    assert len(inbox.samples) == 2 and logbook.stats["dropped"] == 1
    assert logbook.stats["oversized"] == 1
    await wait_for(lambda: len(taken) == 2 and "oversized" in logbook.logged, timeout=5)
