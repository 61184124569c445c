"""simbridge --dds with a ROS 2 node on DDS in another process, and rosbridge clients.

Every test runs in a network namespace of its own (DDS discovery is multicast: nothing may reach
the machine's interfaces), with a domain id of its own (tests/ros2/dds/harness.py). The ROS 2
side is Fast DDS (``ddspeer``, the library rmw_fastrtps is made of) and Cyclone DDS's own typed
Python (``cyclone_peer.py``, as rmw_cyclonedds's other library serializes).
"""

from __future__ import annotations

import asyncio
import importlib.metadata
import json
import os
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.ros2.dds import link as dds_link
from simbridge.ros2.dds.link import RECONCILE_PERIOD
from simbridge.ros2.dds.options import DdsOptions
from tests.helpers import ROOT, TIMEOUT_FACTOR, wait_for, ws_url
from tests.ros2.dds.harness import NetNamespace


pytestmark = pytest.mark.e2e

PEER = Path(__file__).with_name("cyclone_peer.py")


@pytest.fixture
async def dds_app(netns: NetNamespace, dds_domain: int) -> AsyncIterator[App]:
    """Simbridge --dds with the default world, in the test's namespace (the test runs there)."""
    with netns.entered():
        settings = ServerSettings(host="127.0.0.1", port=0, http_port=0)
        app = App(settings, dds=DdsOptions(domain=dds_domain))
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


async def test_a_cyclone_node_lists_reads_drives_and_calls_the_robot_that_rosbridge_clients_watch(
    dds_app: App, run_js: Any, run_roslibpy: Any
) -> None:
    app = dds_app
    get = ["/virtual_robot/get_parameters", "rcl_interfaces/srv/GetParameters"]
    calls = ["--call", "/reset", "std_srvs/srv/Empty", "{}"]
    calls += ["--call", *get, '{"names": ["robot.max_linear_velocity"]}']
    peer = asyncio.create_task(
        _peer(app.dds.options.domain, "--seconds", "4", "--drive", "0.4", *calls)
    )
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
    # `ros2 service call /reset std_srvs/srv/Empty` and `ros2 param get /virtual_robot
    # robot.max_linear_velocity` on rmw_cyclonedds: the request header in the payload
    assert seen["replies"]["/reset"] == {"structure_needs_at_least_one_member": 0}
    (value,) = seen["replies"]["/virtual_robot/get_parameters"]["values"]
    assert (value["type"], value["double_value"]) == (3, 0.5)
    health = app.health()["dds"]
    assert health["state"] == "running" and health["received"] > 0
    # what it read came through the writers' shared pack (the binding 11.0.1's)
    assert health["shared_pack"] is (importlib.metadata.version("cyclonedds") == "11.0.1")


async def test_an_idle_link_reconciles_only_when_the_graph_or_discovery_changes(
    dds_app: App, monkeypatch: pytest.MonkeyPatch
) -> None:
    link = dds_app.dds
    assert link is not None
    window = 4 * RECONCILE_PERIOD

    async def settled() -> None:
        """Wait (10 s at most) until no reconcile ran for four periods in a row."""
        deadline = asyncio.get_running_loop().time() + 10 * TIMEOUT_FACTOR
        while asyncio.get_running_loop().time() < deadline:
            before = link.stats["reconciles"]
            await asyncio.sleep(window)
            if link.stats["reconciles"] == before:
                return
        raise AssertionError("the idle link went on reconciling every period")

    # nothing changes: the robot runs, the link reads neither discovery nor the graph's tables
    await settled()
    # an in-process publisher of a new topic: a DDS writer for it, at the next tick
    dds_app.graph.advertise("/idle_probe", "std_msgs/msg/String", "/sim")
    await wait_for(lambda: "/idle_probe" in link._writers, 2 * RECONCILE_PERIOD)
    await settled()
    # another participant: discovery's readers say so, and its node and topic join the graph,
    # even read one sample at a time (Cyclone says only of new samples, not of those left)
    monkeypatch.setattr(dds_link, "DISCOVERY_BATCH", 1)
    peer = asyncio.create_task(_peer(link.options.domain, "--seconds", "4"))
    await wait_for(lambda: "/talker" in dds_app.graph.nodes, 10)
    await wait_for(lambda: "/chatter" in dds_app.graph.topics.topics, 10)
    await peer
    # and it leaves: its node goes (its participant deleted, not waited out for 30 s)
    await wait_for(lambda: "/talker" not in dds_app.graph.nodes, 10)


async def test_a_fast_dds_node_sees_simbridge_as_a_ros_2_node_and_drives_its_robot(
    dds_app: App, ddspeer: Any, run_js: Any, run_roslibpy: Any
) -> None:
    app = dds_app
    echo = [
        "--echo",
        "/odom",
        "--echo",
        "/scan@sensor",
        "--echo",
        "/tf",
        "--echo",
        "/tf_static@latched",
    ]
    peer = await ddspeer(*echo, "--cmd-vel", "0.4,0", "--chatter", node="student", distro="jazzy")
    url = ws_url(app)
    await wait_for(lambda: "/peer_chatter" in app.graph.topics.topics, 10)
    watched, echoed = await asyncio.gather(
        run_js("roslib2", url, "odom_rate", {"count": 20}),
        run_roslibpy(url, "echo", {"topic": "/peer_chatter", "type": "std_msgs/msg/String"}),
    )
    # a roslibjs client watches the robot that the Fast DDS node drives forward
    first, last = (watched[k]["pose"]["pose"]["position"]["x"] for k in ("first", "last"))
    assert last > first + 0.05
    # a roslibpy client reads the Fast DDS node's topic, listed in rosapi with its type
    assert echoed["messages"][0]["data"].startswith("hello ")
    assert echoed["topics"]["/peer_chatter"] == "std_msgs/msg/String"
    await wait_for(lambda: "/student" in app.graph.nodes, 10)  # from its ros_discovery_info
    # what `ros2 topic list -t`, `ros2 node list` and `ros2 topic echo` show on rmw_fastrtps
    odom = await peer.sample("/odom")
    assert (odom["header"]["frame_id"], odom["child_frame_id"]) == ("odom", "base_link")
    # /scan through a best-effort reader (Nav2's sensor QoS) from simbridge's reliable writer
    assert len((await peer.sample("/scan"))["ranges"]) == 360
    tf = await peer.sample("/tf")
    assert tf["transforms"][0]["child_frame_id"] == "base_link"
    tf_static = await peer.sample("/tf_static")  # a late joiner: the latched message
    assert tf_static["transforms"][0]["child_frame_id"] == "laser"
    graph = peer.graph()
    topics = graph.topics()
    assert topics["/odom"] == {"nav_msgs/msg/Odometry"}
    assert topics["/tf_static"] == {"tf2_msgs/msg/TFMessage"}
    assert {"/virtual_robot", "/sim", "/rosbridge_websocket"} <= graph.nodes()
    assert "/odom" in graph.node("/virtual_robot")["publishers"]
    assert "/cmd_vel" in graph.node("/virtual_robot")["subscribers"]
    ours = [p for p in graph.participants.values() if p.startswith("enclave=/;")]
    assert ours, graph.participants
    assert any(w.user_data.startswith("typehash=RIHS01_") for w in graph.writers("rt/odom")), (
        "Jazzy's endpoints carry their type hash"
    )


@pytest.mark.parametrize(
    ("distro", "env"),
    [
        ("humble", {"ROS_LOCALHOST_ONLY": "1"}),
        ("jazzy", {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}),
    ],
)
async def test_localhost_only_on_both_sides_finds_and_drives_a_fast_dds_node(
    netns: NetNamespace, dds_domain: int, ddspeer: Any, distro: str, env: dict[str, str]
) -> None:
    """A student's laptop with discovery kept on the machine, as rmw_fastrtps keeps it."""
    options = DdsOptions.from_env({"ROS_DOMAIN_ID": str(dds_domain), **env})
    assert options.discovery == "LOCALHOST"
    with netns.entered():
        app = App(ServerSettings(host="127.0.0.1", port=0, http_port=0), dds=options)
        await app.start()
        try:
            peer = await ddspeer(
                "--localhost", distro, "--echo", "/odom", "--cmd-vel", "0.4,0",
                node="student", distro=distro,
            )  # fmt: skip
            # each sees the other: the Fast DDS node reads /odom, its node joins the graph...
            odom = await peer.sample("/odom")
            assert odom["child_frame_id"] == "base_link"
            await wait_for(lambda: "/student" in app.graph.nodes, 10)
            # ... and its /cmd_vel drives the robot
            await peer.sample("/odom", lambda o: o["pose"]["pose"]["position"]["x"] > 0.05)
        finally:
            await app.stop()


async def test_no_sim_dds_is_a_rosbridge_in_front_of_a_humble_robot_on_fast_dds(
    netns: NetNamespace, dds_domain: int, ddspeer: Any, run_js: Any
) -> None:
    robot = await ddspeer("--robot", node="robot_driver", distro="humble")
    with netns.entered():
        settings = ServerSettings(host="127.0.0.1", port=0, http_port=0)
        app = App(settings, no_sim=True, dds=DdsOptions(domain=dds_domain, distro="humble"))
        await app.start()
        try:
            # the robot's topics join the graph (rosapi) under its node, from 24-byte GIDs
            await wait_for(lambda: "/cmd_vel" in app.graph.topics.topics, 10)
            await wait_for(lambda: "/robot_driver" in app.graph.nodes, 10)
            # a roslibjs client (the page's library) drives the real /cmd_vel, reads /odom
            driven = await run_js("roslib2", ws_url(app), "drive", {"v": 0.5, "seconds": 1})
        finally:
            await app.stop()
    assert driven["final"]["x"] > driven["start"]["x"] + 0.1
    command = await robot.wait_for(lambda e: e.get("event") == "cmd_vel", what="/cmd_vel")
    assert command["data"]["linear"]["x"] == 0.5
    infos = [e for e in robot.events if e.get("event") == "nodes" and e["gid_size"] == 24]
    assert any(n["name"] == "rosbridge_websocket" for e in infos for n in e["nodes"])
