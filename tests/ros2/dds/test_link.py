"""simbridge --dds with a ROS 2 node on DDS in another process, and rosbridge clients.

Every test runs in a network namespace of its own (DDS discovery is multicast: nothing may reach
the machine's interfaces), with a domain id of its own.
"""

from __future__ import annotations

import asyncio
import ctypes
import itertools
import json
import os
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import pytest

from simbridge.app.settings import ServerSettings
from simbridge.ros2.dds.options import DdsOptions
from simbridge.runner import App
from tests.helpers import ROOT, TIMEOUT_FACTOR, wait_for, ws_url


pytestmark = pytest.mark.e2e

PEER = Path(__file__).with_name("cyclone_peer.py")
_CLONE_NEWNET = 0x40000000
_domains = itertools.count(150 + os.getpid() % 40)


@pytest.fixture
def netns() -> Iterator[int]:
    """Put this test's thread (and what it starts) in a new network namespace; yield a domain.

    ``lo`` is up with multicast and a 224.0.0.0/4 route, the only interface there.
    """
    libc = ctypes.CDLL(None, use_errno=True)
    home = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    try:
        if libc.unshare(_CLONE_NEWNET) != 0:
            pytest.skip(f"no network namespace here: {os.strerror(ctypes.get_errno())}")
        for cmd in (
            ["ip", "link", "set", "lo", "up", "multicast", "on"],
            ["ip", "route", "add", "224.0.0.0/4", "dev", "lo"],
        ):
            subprocess.run(cmd, check=True, capture_output=True)
        yield next(_domains)
    finally:
        libc.setns(home, _CLONE_NEWNET)
        os.close(home)


@pytest.fixture
async def dds_app(netns: int) -> AsyncIterator[App]:
    settings = ServerSettings(host="127.0.0.1", port=0, http_port=0)
    app = App(settings, dds=DdsOptions(domain=netns))
    await app.start()
    try:
        yield app
    finally:
        await app.stop()


async def _peer(domain: int, *args: str) -> dict[str, Any]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        str(PEER),
        "--domain",
        str(domain),
        *args,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(proc.communicate(), 60 * TIMEOUT_FACTOR)
    assert proc.returncode == 0, err.decode()[-2000:]
    result: dict[str, Any] = json.loads(out.decode().splitlines()[-1])
    return result


def test_dds_without_the_extra_exits_at_once_with_the_install_command() -> None:
    code = (
        "import sys; sys.modules['cyclonedds'] = None\n"
        "from simbridge.cli import main\n"
        "raise SystemExit(main(['--dds', '--port', '0', '--http-port', '0']))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert done.stderr.startswith(
        'simbridge: --dds needs the DDS extra: pip install "simbridge[dds]"'
    )


async def test_a_dds_node_lists_reads_and_drives_the_robot_that_rosbridge_clients_watch(
    dds_app: App, run_js: Any, run_roslibpy: Any
) -> None:
    app = dds_app
    peer = asyncio.create_task(_peer(app.dds.options.domain, "--seconds", "5", "--drive", "0.4"))
    # the peer's /chatter joins the graph under its node, from DDS discovery
    await wait_for(lambda: "/talker" in app.graph.nodes, 10 * TIMEOUT_FACTOR)
    url = ws_url(app)
    watched, echoed = await asyncio.gather(
        run_js("roslib2", url, "odom_rate", {"count": 20}),
        run_roslibpy(url, "echo", {"topic": "/chatter", "type": "std_msgs/msg/String"}),
    )
    seen = await peer

    # a roslibjs client watches the robot the DDS node drives forward
    first, last = (watched[k]["pose"]["pose"]["position"]["x"] for k in ("first", "last"))
    assert last > first + 0.05
    # a roslibpy client reads the DDS node's topic, which rosapi lists with its type
    assert echoed["messages"][0] == {"data": "hello from dds"}
    assert echoed["topics"]["/chatter"] == "std_msgs/msg/String"
    # the DDS node sees simbridge as a ROS 2 node sees another: names, types, nodes, data
    topics = seen["topics"]
    assert topics["rt/odom"] == "nav_msgs::msg::dds_::Odometry_"
    assert topics["rt/scan"] == "sensor_msgs::msg::dds_::LaserScan_"
    assert topics["rt/tf_static"] == "tf2_msgs::msg::dds_::TFMessage_"
    assert {"/virtual_robot", "/sim", "/rosbridge_websocket"} <= set(seen["nodes"])
    samples = seen["samples"]
    assert samples["/odom"] == {"frame_id": "odom", "child_frame_id": "base_link"}
    assert samples["/scan"] == {"frame_id": "laser", "ranges": 360}
    assert samples["/tf"] == [["odom", "base_link"]]
    assert samples["/tf_static"] == [["base_link", "laser"]]  # a late joiner's latched TF
    health = app.health()["dds"]
    assert health["state"] == "running" and health["received"] > 0
