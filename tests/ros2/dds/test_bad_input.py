"""Bad input from DDS: a call simbridge cannot answer, bytes that are not CDR, a peer that goes.

Cyclone DDS checks each sample against the reader's type and drops what does not fit before
simbridge could read it; simbridge reads those refusals back from Cyclone's log, and they, like
what simbridge's own checks refuse, are counted and said in one rate-limited log line naming
the topic and the node (also on /rosout). The robot, the loop and the other peers carry on.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import sys
from typing import Any

import pytest

from simbridge.app.runner import App
from tests.helpers import wait_for
from tests.ros2.dds.harness import SPDP_GROUP, NetNamespace, spdp_port
from tests.ros2.dds.test_link import _peer, dds_app


pytestmark = pytest.mark.e2e

__all__ = ["dds_app"]


async def test_bad_input_from_dds_is_logged_and_counted_and_the_robot_runs_on(
    dds_app: App,
    netns: NetNamespace,
    ddspeer: Any,
    caplog: pytest.LogCaptureFixture,
    capfd: pytest.CaptureFixture[str],
) -> None:
    app = dds_app
    link = app.dds
    assert link is not None
    # the server's stderr (file descriptor 2, where Cyclone's C code writes) with simbridge's
    # log lines on it, as the command line has them
    stderr = logging.StreamHandler(sys.stderr)
    stderr.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    logging.getLogger().addHandler(stderr)
    try:
        await _bad_input(app, link, netns, ddspeer, caplog)
    finally:
        logging.getLogger().removeHandler(stderr)
    # one line of simbridge's for the samples Cyclone refused (10 a second) and one for the
    # malformed packets, none of Cyclone's own for each of them: its domain's log comes to
    # simbridge, not to stderr
    err = capfd.readouterr().err
    assert link.stats["refused_by_cyclone"] >= 3
    assert err.count("DDS: /cmd_vel: a sample from /student") == 1, err[-2000:]
    assert "deserialization rt/cmd_vel" not in err and "deserialization rq/" not in err
    (malformed,) = [line for line in err.splitlines() if "malformed packet" in line]
    assert "DDS: Cyclone DDS says: malformed packet received from vendor 1.15" in malformed


async def _bad_input(
    app: App, link: Any, netns: NetNamespace, ddspeer: Any, caplog: pytest.LogCaptureFixture
) -> None:
    # an rmw_fastrtps client's /reset: it carries no rmw_cyclonedds request header; and 5
    # bytes on /cmd_vel under Twist's name (a Fast DDS writer sends no type information, so it
    # matches by the name alone), where a Twist has 48
    bad = "/cmd_vel=geometry_msgs/msg/Twist:0001000001"
    caplog.set_level(logging.WARNING)
    client = await ddspeer(
        "--call-reset", "--chatter", "--raw", bad, node="student", distro="jazzy"
    )
    await client.wait_for(
        lambda e: e.get("event") == "matched" and e["topic"] == "rr/resetReply" and e["count"],
        what="its /reset reply reader matched",
    )
    await wait_for(lambda: "/student" in app.graph.nodes, 10)
    await client.send("call_reset")
    # Cyclone checks each sample against the reader's type before simbridge sees it: the
    # request (no header: 5 bytes for a 21-byte type) is dropped there, never answered
    await client.wait_for(lambda e: e.get("event") == "called", what="the request sent")

    # the bytes on /cmd_vel that are not a Twist: Cyclone refuses them, simbridge counts them
    # and says so once, naming the topic and the node; the robot runs on, undriven
    def said() -> list[str]:
        lines = [r.getMessage() for r in caplog.records if "Cyclone DDS refused" in r.getMessage()]
        return [text for text in lines if "/cmd_vel" in text]

    await wait_for(lambda: said(), 15)
    (line,) = said()
    guid = next(e["guid"] for e in client.events if e.get("event") == "ready")
    assert line.startswith("DDS: /cmd_vel: a sample from ")  # the node, once it was announced
    assert f"(participant {guid})" in line
    assert "is not CDR of geometry_msgs/msg/Twist" in line
    assert link.stats["bad_payloads"] >= link.stats["refused_by_cyclone"]
    # RTPS that is not: a DATA submessage longer than its packet, to the discovery group (the
    # Fast DDS peer shares its port: a unicast datagram reaches one of them only)
    with netns.entered():
        _send_malformed(link.options.domain, times=5)
    # Cyclone drops them, simbridge says so once (Cyclone's line, counted: rate-limited by kind)
    await wait_for(lambda: link.stats["cyclone_log_lines"] >= 5, 10)
    peer = asyncio.create_task(_peer(link.options.domain, "--seconds", "2", "--unknown-type"))
    # a type the registry does not know: listed with its type (rosapi), counted, not bridged
    topics = app.graph.topics.topics
    await wait_for(lambda: "/mystery" in topics, 10)
    assert topics["/mystery"].type == "foo_msgs/msg/Mystery" and not topics["/mystery"].known
    assert link.stats["unknown_types"] >= 1
    seen = await peer
    assert seen["samples"]["/odom"]  # the robot still publishes
    assert not [e for e in client.events if e.get("event") == "reply"]
    assert link.stats["calls_answered"] == 0
    # the Fast DDS node leaves: its node and topic leave the graph (rosapi) with it
    chatter = app.graph.topics.topics["/peer_chatter"]
    assert chatter.publishers
    await client.stop()
    await wait_for(lambda: "/student" not in app.graph.nodes and not chatter.publishers, 15)
    assert link.state == "running"


def _send_malformed(domain: int, *, times: int) -> None:
    header = b"RTPS\x02\x03\x01\x0f" + bytes(range(1, 13))
    data = b"\x15\x01\x00\x01" + bytes(8)  # DATA, little-endian, 256 bytes said, 8 there
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _ in range(times):
            sock.sendto(header + data, (SPDP_GROUP, spdp_port(domain)))
