from __future__ import annotations

import asyncio

import pytest

from simbridge.app.runner import App
from simbridge.tools.client import ClientError, RosbridgeClient
from tests.helpers import wait_for, ws_url


async def test_subscribe_publish_and_call(app: App) -> None:
    async with RosbridgeClient.connect(ws_url(app)) as ros:
        odom = await ros.subscribe("/odom", "nav_msgs/msg/Odometry")
        msg = await asyncio.wait_for(odom.get(), 3)
        assert msg["header"]["frame_id"] == "odom"
        await ros.publish("/cmd_vel", {"linear": {"x": 0.1}}, "geometry_msgs/msg/Twist")
        await wait_for(lambda: app.world.robots[""].cmd_v == 0.1)
        assert ("/odom", "nav_msgs/msg/Odometry") in await ros.topics()
        assert await ros.topic_type("/scan") == "sensor_msgs/msg/LaserScan"
        with pytest.raises(ClientError, match="does not exist"):
            await ros.call_service("/nope", {})


async def test_server_status_errors_are_kept(app: App) -> None:
    async with RosbridgeClient.connect(ws_url(app)) as ros:
        await ros.publish("/cmd_vel", {"linear": {"x": "x"}}, "geometry_msgs/msg/Twist")
        await wait_for(lambda: bool(ros.errors))
        assert "linear.x" in ros.errors[0]


async def test_connection_closed_by_the_server_fails_pending_calls(app: App) -> None:
    async with RosbridgeClient.connect(ws_url(app)) as ros:
        await app.stop()
        await asyncio.wait_for(ros.closed.wait(), 5)
        with pytest.raises(ClientError):
            await ros.call_service("/rosapi/topics", {}, timeout=2)


async def test_connect_refused() -> None:
    with pytest.raises(ClientError, match="cannot connect"):
        async with RosbridgeClient.connect("ws://127.0.0.1:1", timeout=2):
            pass
