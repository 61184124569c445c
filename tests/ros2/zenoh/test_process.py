"""--zenoh as a user meets it: opt-in imports, a router that comes later, /healthz, Humble."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import urllib.request
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from tests.helpers import ROOT, http_url, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router, zenoh_options


pytestmark = pytest.mark.e2e


def _python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60
    )


def test_zenoh_without_the_extra_exits_at_once_with_the_install_command() -> None:
    done = _python(
        "import sys; sys.modules['zenoh'] = None\n"
        "from simbridge.cli import main\n"
        "raise SystemExit(main(['--zenoh', '--port', '0', '--http-port', '0']))"
    )
    assert done.returncode == 2
    assert 'pip install "simbridge[zenoh]"' in done.stderr


def test_zenohd_without_the_extra_names_the_command_not_an_option() -> None:
    done = _python(
        "import sys; sys.modules['zenoh'] = None\n"
        "from simbridge.cli import main\n"
        "raise SystemExit(main(['zenohd']))"
    )
    assert done.returncode == 2
    assert done.stderr.startswith("simbridge zenohd: the router needs the Zenoh extra: pip install")
    assert "--zenoh" not in done.stderr


def test_without_zenoh_nothing_of_it_is_imported() -> None:
    done = _python(
        "import asyncio, sys\n"
        "from simbridge.app.settings import ServerSettings\n"
        "from simbridge.app.runner import App\n"
        "async def main():\n"
        "    app = App(ServerSettings(host='127.0.0.1', port=0, http_port=None))\n"
        "    await app.start(); await app.stop()\n"
        "asyncio.run(main())\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'zenoh'"
        " or m.startswith('simbridge.ros2.zenoh')))"
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


async def test_server_runs_without_router_and_connects_when_it_appears() -> None:
    router = Router()  # its port is chosen, nothing listens there yet
    retry = "connect/retry={period_init_ms: 200, period_max_ms: 500, period_increase_factor: 2}"
    app = App(
        ServerSettings(host="127.0.0.1", port=0, http_port=0),
        zenoh=zenoh_options(router, override=retry),
    )
    await app.start()
    try:
        assert app.health()["zenoh"]["state"] == "connecting"
        async with connect(ws_url(app)):  # the rosbridge side serves meanwhile
            pass
        await asyncio.to_thread(router.start)
        await wait_for(lambda: app.health()["zenoh"]["state"] == "connected", timeout=10)

        def healthz() -> Any:
            with urllib.request.urlopen(http_url(app) + "/healthz", timeout=5) as response:
                return json.loads(response.read())

        body = await asyncio.to_thread(healthz)
        assert body["zenoh"]["state"] == "connected" and body["zenoh"]["routers"] == 1
    finally:
        await app.stop()
        router.stop()


async def test_humble_declares_no_type_hashes_and_humble_peers_get_data(
    router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import ROS2Subscriber

    app = App(
        ServerSettings(host="127.0.0.1", port=0, http_port=0),
        zenoh=zenoh_options(router, distro="humble"),
    )
    await app.start()
    got: list[Any] = []
    try:
        assert app.zenoh is not None
        odom = app.zenoh._declared[("MP", "/virtual_robot", "/odom")].entity
        assert odom.keyexpr() == "0/odom/nav_msgs::msg::dds_::Odometry_/TypeHashNotSupported"
        sub = await asyncio.to_thread(
            ROS2Subscriber,
            "/odom",
            "nav_msgs/msg/Odometry",
            got.append,
            type_hash="TypeHashNotSupported",
            router_ip="127.0.0.1",
            router_port=router.port,
        )
        await wait_for(lambda: len(got) >= 3, timeout=8)
        sub.close()
    finally:
        await app.stop()


async def test_no_sim_is_a_rosbridge_in_front_of_ros2_nodes(router: Router, ros2: Any) -> None:
    from zenoh_ros2_sdk import ROS2Publisher

    app = App(
        ServerSettings(host="127.0.0.1", port=0, http_port=0),
        zenoh=zenoh_options(router),
        no_sim=True,
    )
    await app.start()
    pub = await asyncio.to_thread(
        ROS2Publisher,
        "/robot_status",
        "std_msgs/msg/String",
        node_name="real_robot",
        router_ip="127.0.0.1",
        router_port=router.port,
    )
    try:
        graph = app.graph
        assert "/odom" not in graph.topics.topics and "/reset" not in graph.services.services
        assert "/virtual_robot" not in graph.nodes
        await wait_for(lambda: "/robot_status" in graph.topics.topics, timeout=8)
        async with connect(ws_url(app)) as conn:
            await conn.send(json.dumps({"op": "subscribe", "topic": "/robot_status"}))

            async def talk() -> None:
                while True:
                    await asyncio.to_thread(pub.publish, data="battery ok")
                    await asyncio.sleep(0.05)

            talking = asyncio.create_task(talk())
            try:
                while True:
                    msg = json.loads(await asyncio.wait_for(conn.recv(), 5))
                    if msg.get("topic") == "/robot_status":
                        break
            finally:
                talking.cancel()
        assert msg["msg"] == {"data": "battery ok"}
        # the ROS 2 side sees the bridge's nodes only, no simulated robot
        assert app.zenoh is not None
        nodes = {key[1] for key in app.zenoh._declared if key[0] == "NN"}
        assert "/virtual_robot" not in nodes and "/rosapi" in nodes
    finally:
        pub.close()
        await app.stop()
