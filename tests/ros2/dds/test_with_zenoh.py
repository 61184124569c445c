"""``--dds`` and ``--zenoh`` in one process: a student on DDS and one on Zenoh see the same robot.

Everything runs in the test's network namespace (DDS discovery is multicast): the Zenoh router
(``simbridge zenohd``), simbridge with both links, a Fast DDS node (``ddspeer``) and a ROS 2
node on Zenoh (zenoh-ros2-sdk, the independent rmw_zenoh implementation of the Zenoh tests, in
a process of its own: the SDK keeps one session per process).
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import urllib.request
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import ROOT, TIMEOUT_FACTOR
from tests.ros2.dds.harness import NetNamespace
from tests.ros2.zenoh.conftest import write_definitions


pytestmark = pytest.mark.e2e

#: The router's port inside the namespace (the namespace is the test's own: nothing else
#: listens there).
ROUTER_PORT = 17447

#: A ROS 2 node on Zenoh that prints each /odom's x as a JSON line (ROS_DOMAIN_ID is the
#: Zenoh link's domain too: the test's own).
ZENOH_NODE = """
import json, sys
from zenoh_ros2_sdk import message_registry
message_registry.get_registry(sys.argv[1])
from zenoh_ros2_sdk import ROS2Subscriber

def odom(msg):
    print(json.dumps({"x": msg.pose.pose.position.x}), flush=True)

ROS2Subscriber("/odom", "nav_msgs/msg/Odometry", callback=odom, node_name="zenoh_student",
               domain_id=int(sys.argv[3]), router_ip="127.0.0.1", router_port=int(sys.argv[2]))
print(json.dumps({"ready": True}), flush=True)
sys.stdin.read()
"""


async def _line(stream: asyncio.StreamReader, what: str) -> dict[str, Any]:
    raw = await asyncio.wait_for(stream.readline(), 20 * TIMEOUT_FACTOR)
    assert raw, f"{what} ended"
    line: dict[str, Any] = json.loads(raw)
    return line


async def _started(netns: NetNamespace, argv: list[str], **kw: Any) -> Any:
    proc = await asyncio.create_subprocess_exec(
        *netns.command(argv), cwd=ROOT, stdout=asyncio.subprocess.PIPE, **kw
    )
    netns.own(proc)
    return proc


def _health(port: int) -> dict[str, Any]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=5) as reply:
        health: dict[str, Any] = json.load(reply)
    return health


async def test_a_fast_dds_node_drives_the_robot_that_a_zenoh_node_watches_move(
    netns: NetNamespace, dds_domain: int, ddspeer: Any, tmp_path: Path
) -> None:
    endpoint = f"tcp/127.0.0.1:{ROUTER_PORT}"
    router = await _started(
        netns, [sys.executable, "-m", "simbridge", "zenohd", "--listen", endpoint]
    )
    assert b"listening on" in await asyncio.wait_for(router.stdout.readline(), 20)
    # simbridge with both links, one process (in the namespace: a process of its own)
    both = ["--dds", "--zenoh", "--zenoh-connect", endpoint, "--zenoh-listen", "tcp/127.0.0.1:0"]
    server = await _started(
        netns,
        [sys.executable, "-m", "simbridge", *both, "--port", "9090", "--http-port", "8080"],
        env={**os.environ, "ROS_DOMAIN_ID": str(dds_domain)},
    )
    assert b"rosbridge ws://" in await asyncio.wait_for(server.stdout.readline(), 30)
    write_definitions(tmp_path)
    node = await _started(
        netns,
        [sys.executable, "-c", ZENOH_NODE, str(tmp_path), str(ROUTER_PORT), str(dds_domain)],
        stdin=asyncio.subprocess.PIPE,
    )
    assert (await _line(node.stdout, "the Zenoh node"))["ready"]
    # the Zenoh node sees the robot's /odom before anyone drives it
    first = (await _line(node.stdout, "the Zenoh node's /odom"))["x"]
    # a Fast DDS node sees the same /odom and drives /cmd_vel
    peer = await ddspeer("--echo", "/odom", "--cmd-vel", "0.5,0", node="dds_student")
    assert (await peer.sample("/odom"))["child_frame_id"] == "base_link"
    x = first
    while x < first + 0.1:  # what the Zenoh node reads moves
        x = (await _line(node.stdout, "the Zenoh node's /odom"))["x"]
    await peer.wait_for(
        lambda e: (
            e.get("event") == "sample"
            and e["topic"] == "/odom"
            and e["data"]["pose"]["pose"]["position"]["x"] > first + 0.1
        ),
        what="the DDS node's /odom moving",
    )
    health = await asyncio.to_thread(_health, netns.forward(8080))
    assert health["dds"]["state"] == "running" and health["dds"]["received"] > 0
    assert health["zenoh"]["state"] == "connected"
    for proc in (node, server, router):
        proc.terminate()
        await asyncio.wait_for(proc.communicate(), 15)
