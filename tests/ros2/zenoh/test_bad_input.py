"""Bad input from the Zenoh network: a clear answer or one log line, never a stalled loop."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from tests.helpers import recv_until, send_json, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router


pytestmark = pytest.mark.e2e


def sdk_kw(router: Router) -> dict[str, Any]:
    return {"router_ip": "127.0.0.1", "router_port": router.port}


async def test_payload_that_is_not_cdr_is_dropped_and_good_ones_still_drive(
    zapp: App, router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import ROS2Publisher, get_message_class

    assert zapp.zenoh is not None
    pub = await asyncio.to_thread(
        ROS2Publisher, "/cmd_vel", "geometry_msgs/msg/Twist", **sdk_kw(router)
    )
    try:
        # subscribed on the publisher's own key expression (from its token)
        subs = zapp.zenoh._subscribers
        await wait_for(lambda: pub.keyexpr in subs.get("/cmd_vel", {}), timeout=8)
        ticks = zapp.stats.ticks
        async with connect(ws_url(zapp)) as conn:
            await send_json(conn, {"op": "subscribe", "topic": "/rosout"})
            await asyncio.sleep(0.2)
            for garbage in (b"", b"\x00\x01\x00\x00\x01", b"\xff" * 7):
                await asyncio.to_thread(ros2.session.put, pub.keyexpr, garbage)
            # one line (rate-limited) in the log and on /rosout says which topic and why
            said = await recv_until(
                conn, lambda m: "not CDR" in str(m.get("msg", {}).get("msg")), timeout=5
            )
        assert "/cmd_vel" in said["msg"]["msg"] and said["msg"]["level"] == 30
        await wait_for(lambda: zapp.zenoh.stats["bad_payloads"] >= 3, timeout=5)  # type: ignore[union-attr]
        await wait_for(lambda: zapp.stats.ticks > ticks + 5, timeout=5)  # the loop runs on
        vector = get_message_class("geometry_msgs/msg/Vector3")
        robot = next(iter(zapp.world.robots.values()))
        x0 = robot.state.x
        deadline = time.monotonic() + 8
        while robot.state.x < x0 + 0.05 and time.monotonic() < deadline:
            await asyncio.to_thread(
                pub.publish, linear=vector(x=0.3, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0)
            )
            await asyncio.sleep(0.1)
        assert robot.state.x >= x0 + 0.05
    finally:
        pub.close()


async def test_unknown_type_and_type_clash_are_not_bridged_and_counted(
    zapp: App, router: Router, ros2: Any
) -> None:
    assert zapp.zenoh is not None
    zid = ros2.session_id
    weird = (
        f"@ros2_lv/0/{zid}/90/91/MP/%/%/weird/%weird_topic/nobody_msgs::msg::dds_::Thing_/"
        "RIHS01_00/::,10:,:,:,,"
    )
    clash = (
        f"@ros2_lv/0/{zid}/90/92/MP/%/%/weird/%odom/std_msgs::msg::dds_::String_/RIHS01_00/"
        "::,10:,:,:,,"
    )
    broken = f"@ros2_lv/0/{zid}/90/93/XX/%/%/weird"
    tokens = [ros2.liveliness.declare_token(k) for k in (weird, clash, broken)]
    try:
        await wait_for(lambda: zapp.zenoh.stats["unknown_types"] >= 1, timeout=8)  # type: ignore[union-attr]
        await wait_for(lambda: zapp.zenoh.stats["name_clashes"] >= 1, timeout=8)  # type: ignore[union-attr]
        # listed with its type (rosapi shows it, without a definition), never subscribed
        weird_topic = zapp.graph.topics.topics["/weird_topic"]
        assert weird_topic.type == "nobody_msgs/msg/Thing" and not weird_topic.known
        assert "/weird_topic" not in zapp.zenoh._subscribers
        assert zapp.graph.topics.topics["/odom"].type == "nav_msgs/msg/Odometry"
    finally:
        for token in tokens:
            token.undeclare()


async def test_a_service_whose_node_vanishes_mid_call_fails_with_the_reason(
    zapp: App, router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import ROS2ServiceServer

    started = asyncio.Event()
    release = threading.Event()
    loop = asyncio.get_running_loop()
    made: dict[str, Any] = {}

    def slow(request: Any) -> Any:
        loop.call_soon_threadsafe(started.set)
        release.wait(10)  # answers only after its node is gone
        return made["server"].response_msg_class(success=True, message="too late")

    server = made["server"] = await asyncio.to_thread(
        ROS2ServiceServer, "/slow_flag", "std_srvs/srv/SetBool", slow, **sdk_kw(router)
    )
    await wait_for(lambda: "/slow_flag" in zapp.graph.services.services, timeout=8)
    async with connect(ws_url(zapp)) as conn:
        call = {"op": "call_service", "service": "/slow_flag", "id": "x", "args": {"data": True}}
        await send_json(conn, call)
        await asyncio.wait_for(started.wait(), 5)
        await asyncio.to_thread(server.close)  # its tokens go while the call is in flight
        answer = await recv_until(conn, lambda m: m.get("id") == "x", timeout=8)
    release.set()
    assert answer["result"] is False
    assert "/slow_flag" in answer["values"]
