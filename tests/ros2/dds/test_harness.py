"""The DDS test harness itself, with no simbridge in it: namespaces keep DDS in, peers talk.

Two Fast DDS peers (``peer/peer.cpp``, the library rmw_fastrtps_cpp is made of) in a private
network namespace: a stand-in robot driven over ``/cmd_vel``, a late joiner getting
``/tf_static``, a node listed from ``ros_discovery_info``, a ``/reset`` call correlated by the
sample identity of the DDS write.
"""

from __future__ import annotations

import asyncio
import socket
import struct
import subprocess
import time
from collections.abc import Callable
from typing import Any

import pytest

from tests.helpers import TIMEOUT_FACTOR
from tests.ros2.dds.harness import (
    SPDP_GROUP,
    NetNamespace,
    PeerFactory,
    namespace_exists,
    spdp_port,
)


def _discovery_socket(port: int) -> socket.socket:
    """A socket that hears DDS discovery multicast on ``lo`` of the namespace it is made in."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("", port))
    group = struct.pack("4s4s", socket.inet_aton(SPDP_GROUP), socket.inet_aton("127.0.0.1"))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group)
    sock.setblocking(False)
    return sock


def _rtps_datagrams(sock: socket.socket) -> int:
    count = 0
    while True:
        try:
            data = sock.recv(65536)
        except BlockingIOError:
            return count
        count += data[:4] == b"RTPS"


async def test_discovery_multicast_stays_inside_the_namespace(
    netns: NetNamespace, dds_domain: int, ddspeer: PeerFactory
) -> None:
    assert netns.interfaces() == ["lo"]
    port = spdp_port(dds_domain)
    host = _discovery_socket(port)
    with netns.entered():
        inside = _discovery_socket(port)
    try:
        await ddspeer()
        heard_inside = heard_outside = 0
        deadline = time.monotonic() + 5 * TIMEOUT_FACTOR
        while heard_inside < 3 and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
            heard_inside += _rtps_datagrams(inside)
            heard_outside += _rtps_datagrams(host)
        assert heard_inside >= 3, "the peer's discovery announcements were not heard inside"
        assert heard_outside == 0, "DDS discovery reached the host's network"
    finally:
        host.close()
        inside.close()


async def test_namespace_and_its_processes_end_with_it() -> None:
    ns = NetNamespace()
    inode = ns.inode
    proc = subprocess.Popen(ns.command(["sleep", "60"]))
    ns.own(proc)
    assert namespace_exists(inode)
    ns.close()
    assert proc.returncode is not None
    assert not namespace_exists(inode)


async def test_forwarder_reaches_a_server_that_the_host_cannot(netns: NetNamespace) -> None:
    async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.write(await reader.readline())
        await writer.drain()
        writer.close()

    with netns.entered():
        server = await asyncio.start_server(echo, "127.0.0.1", 0)
    inner_port = server.sockets[0].getsockname()[1]
    try:
        with pytest.raises(ConnectionRefusedError):
            await asyncio.open_connection("127.0.0.1", inner_port)
        reader, writer = await asyncio.open_connection("127.0.0.1", netns.forward(inner_port))
        writer.write(b"through the namespace\n")
        await writer.drain()
        assert await asyncio.wait_for(reader.readline(), 5) == b"through the namespace\n"
        writer.close()
    finally:
        server.close()
        await server.wait_closed()


async def test_fast_dds_peer_drives_the_stand_in_robot(ddspeer: PeerFactory) -> None:
    robot = await ddspeer("--robot", node="robot")
    driver = await ddspeer(
        "--cmd-vel", "0.5,0.3", "--echo", "/odom", "--echo", "/scan@sensor", node="driver"
    )
    command = await robot.wait_for(lambda e: e.get("event") == "cmd_vel", what="/cmd_vel")
    assert command["data"]["linear"]["x"] == 0.5
    assert command["data"]["angular"]["z"] == 0.3
    odom = await driver.sample("/odom", lambda d: d["pose"]["pose"]["position"]["x"] > 0.05)
    assert odom["twist"]["twist"]["linear"]["x"] == 0.5
    assert odom["header"]["frame_id"] == "odom"
    assert odom["child_frame_id"] == "base_link"
    # a best-effort reader (Nav2's sensor subscribers) is served by the reliable writer
    scan = await driver.sample("/scan")
    assert len(scan["ranges"]) == 360
    assert scan["range_min"] <= min(scan["ranges"]) <= scan["range_max"]
    readers = (await robot.wait_graph(lambda g: bool(g.readers("rt/scan")))).readers("rt/scan")
    assert [r.reliability for r in readers] == ["best_effort"]
    await driver.send("cmd_vel 0 0")
    await driver.sample("/odom", lambda d: d["twist"]["twist"]["linear"]["x"] == 0.0)


async def test_late_joiner_gets_tf_static_from_a_transient_local_writer(
    ddspeer: PeerFactory,
) -> None:
    robot = await ddspeer("--robot", node="robot")
    # the robot's /tf_static went out before the listener existed
    await robot.wait_for(lambda e: e.get("event") == "ready")
    listener = await ddspeer("--echo", "/tf_static", node="listener")
    static = await listener.sample("/tf_static")
    [transform] = static["transforms"]
    assert (transform["header"]["frame_id"], transform["child_frame_id"]) == ("base_link", "laser")
    graph = await listener.wait_graph(lambda g: bool(g.writers("rt/tf_static")))
    [writer] = graph.writers("rt/tf_static")
    assert (writer.reliability, writer.durability) == ("reliable", "transient_local")


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
async def test_discovery_lists_the_announced_node_and_its_topics(
    ddspeer: PeerFactory, distro: str
) -> None:
    type_hash = "RIHS01_" + "5e" * 32  # what the peer is told; Iron and later send it
    await ddspeer(
        "--chatter",
        "--echo",
        "/cmd_vel",
        "--type-hash",
        f"std_msgs/msg/String={type_hash}",
        node="talker",
        distro=distro,
    )
    lister = await ddspeer(node="lister", distro=distro)
    graph = await lister.wait_graph(
        lambda g: "/talker" in g.nodes() and bool(g.node("/talker")["publishers"]),
        what="/talker with its topics",
    )
    assert graph.node("/talker") == {
        "publishers": {"/peer_chatter": "std_msgs/msg/String"},
        "subscribers": {"/cmd_vel": "geometry_msgs/msg/Twist"},
        "services": {},
        "clients": {},
    }
    assert graph.topics()["/peer_chatter"] == {"std_msgs/msg/String"}
    assert set(graph.participants.values()) == {"enclave=/;\\0"}
    [writer] = graph.writers("rt/peer_chatter")
    assert (writer.reliability, writer.durability) == ("reliable", "volatile")
    assert writer.user_data == ("" if distro == "humble" else f"typehash={type_hash};")
    gid_size = 24 if distro == "humble" else 16
    assert {e["gid_size"] for e in lister.events if e.get("event") == "nodes"} == {gid_size}


async def test_reset_reply_is_matched_to_its_request_by_sample_identity(
    ddspeer: PeerFactory,
) -> None:
    robot = await ddspeer("--robot", "--serve-reset", node="robot")
    client = await ddspeer("--call-reset", node="client")

    def matched(kind: str, topic: str) -> Callable[[dict[str, Any]], bool]:
        return lambda e: e.get("event") == "matched" and (e["kind"], e["topic"]) == (kind, topic)

    # a service is available once both of the client's endpoints and the server's reply writer
    # are matched (rmw_fastrtps's service_is_available and its reply check)
    await client.wait_for(matched("writer", "rq/resetRequest"), what="the request writer matched")
    await client.wait_for(matched("reader", "rr/resetReply"), what="the reply reader matched")
    await robot.wait_for(matched("writer", "rr/resetReply"), what="the reply writer matched")
    # and a volatile reader drops what a writer sent before the reader matched it
    await robot.wait_for(matched("reader", "rq/resetRequest"), what="the request reader matched")
    await client.send("call_reset")
    called = await client.wait_for(lambda e: e.get("event") == "called")
    reply = await client.wait_for(lambda e: e.get("event") == "reply", what="a /reset reply")
    assert reply["ours"] is True
    assert reply["sequence"] == called["sequence"]
    request = await robot.wait_for(lambda e: e.get("event") == "request")
    assert request["sequence"] == called["sequence"]
    graph = await client.wait_graph(lambda g: "/robot" in g.nodes())
    assert graph.services() == {"/reset": {"std_srvs/srv/Empty"}}
    assert graph.node("/robot")["services"] == {"/reset": "std_srvs/srv/Empty"}


async def test_cyclone_peer_lists_reads_and_drives_the_fast_dds_robot(
    ddspeer: PeerFactory, cyclonepeer: PeerFactory
) -> None:
    robot = await ddspeer("--robot", node="robot")
    driver = await cyclonepeer(
        "--echo", "/odom", "--echo", "/tf_static", "--cmd-vel", "0.4,0.2", node="cyclone_driver"
    )
    graph = await driver.wait_graph(
        lambda g: "/robot" in g.nodes() and "/cmd_vel" in g.node("/robot")["subscribers"],
        what="/robot with its topics",
    )
    assert graph.node("/robot") == {
        "publishers": {
            "/odom": "nav_msgs/msg/Odometry",
            "/scan": "sensor_msgs/msg/LaserScan",
            "/tf": "tf2_msgs/msg/TFMessage",
            "/tf_static": "tf2_msgs/msg/TFMessage",
        },
        "subscribers": {"/cmd_vel": "geometry_msgs/msg/Twist"},
        "services": {},
        "clients": {},
    }
    command = await robot.wait_for(lambda e: e.get("event") == "cmd_vel", what="/cmd_vel")
    assert (command["data"]["linear"]["x"], command["data"]["angular"]["z"]) == (0.4, 0.2)
    odom = await driver.sample("/odom", lambda d: d["pose"]["pose"]["position"]["x"] > 0.05)
    assert odom["twist"]["twist"]["linear"]["x"] == 0.4
    [transform] = (await driver.sample("/tf_static"))["transforms"]
    assert transform["child_frame_id"] == "laser"
    seen_by_robot = await robot.wait_graph(lambda g: "/cyclone_driver" in g.nodes())
    assert seen_by_robot.node("/cyclone_driver")["publishers"] == {
        "/cmd_vel": "geometry_msgs/msg/Twist"
    }


async def test_stand_in_robot_under_a_namespace(ddspeer: PeerFactory) -> None:
    await ddspeer("--robot", "--namespace", "/robot1", node="robot")
    driver = await ddspeer(
        "--echo", "/robot1/odom", "--cmd-vel", "0.2,0", "--cmd-vel-topic", "/robot1/cmd_vel"
    )
    await driver.sample("/robot1/odom", lambda d: d["twist"]["twist"]["linear"]["x"] == 0.2)
    graph = await driver.wait_graph(lambda g: "/robot1/robot" in g.nodes())
    assert set(graph.node("/robot1/robot")["publishers"]) == {
        "/robot1/odom",
        "/robot1/scan",
        "/robot1/tf",
        "/robot1/tf_static",
    }
