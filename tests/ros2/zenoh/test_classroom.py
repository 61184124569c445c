"""One classroom over two simbridge processes and a router.

A roslibjs client of one process drives a robot simulated by the other; robot names stay unique
across the classroom.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.graph import Graph
from simbridge.ros2.names import Entity
from simbridge.ros2.zenoh.config import ZenohOptions
from simbridge.ros2.zenoh.link import ZenohLink
from tests.conftest import ClientRunner
from tests.helpers import recv_until, send_json, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router, room_a_process, zenoh_options


pytestmark = pytest.mark.e2e


@pytest.fixture
async def other_process(router: Router, tmp_path: Path) -> AsyncIterator[None]:
    """A second simbridge process simulating robot a1, on the same router."""
    async with room_a_process(router, tmp_path):
        yield


async def test_a_client_of_one_process_drives_a_robot_of_another(
    router: Router, ros2: Any, other_process: None, run_js: ClientRunner
) -> None:
    app = App(ServerSettings(host="127.0.0.1", port=0, http_port=0), zenoh=zenoh_options(router))
    await app.start()
    try:
        await wait_for(lambda: "/a1/odom" in app.graph.topics.topics, timeout=10)
        async with connect(ws_url(app)) as conn:
            # the page's robot picker reads /rosapi/topics: a1 is listed with its type
            await send_json(conn, {"op": "call_service", "service": "/rosapi/topics", "id": "t"})
            values = (await recv_until(conn, lambda m: m.get("id") == "t"))["values"]
            index = values["topics"].index("/a1/odom")
            assert values["types"][index] == "nav_msgs/msg/Odometry"
            # ...and in /simbridge/access, where the page takes its robots from
            call = {"op": "call_service", "service": "/simbridge/access", "id": "a"}
            await send_json(conn, call)
            answer = await recv_until(conn, lambda m: m.get("id") == "a")
            access = json.loads(answer["values"]["message"])
            assert "a1" in access["robots"] and "" in access["robots"]
            assert access["robot_info"]["a1"]["remote"] is True
            assert access["robot_info"]["a1"]["max_linear_velocity"] == 0.5
            # a robot name of another process is refused here, with the reason
            spawn = {"op": "call_service", "service": "/spawn", "id": "s", "args": {"name": "a1"}}
            await send_json(conn, spawn)
            refused = await recv_until(conn, lambda m: m.get("id") == "s")
            assert refused["result"] is False
            assert "taken by another simbridge process" in refused["values"]
        result = await run_js("roslib2", ws_url(app), "drive", {"ns": "a1", "v": 0.5}, 30)
        moved = result["final"]["x"] - result["start"]["x"]
        # 0.5 m/s for 1 s of commands: forward by up to 0.5 m (less when a loaded machine makes
        # the loop skip ticks), never more
        assert 0.1 < moved < 0.75, result
        assert result["twist_during_motion"]["max_linear_x"] == pytest.approx(0.5)
    finally:
        await app.stop()


@contextlib.asynccontextmanager
async def _processes(router: Router, count: int) -> AsyncIterator[list[App]]:
    """``count`` simbridge servers (default world) on the router's Zenoh network, started."""
    apps: list[App] = []
    try:
        for _ in range(count):
            app = App(
                ServerSettings(host="127.0.0.1", port=0, http_port=0), zenoh=zenoh_options(router)
            )
            await app.start()
            apps.append(app)
        yield apps
    finally:
        for app in apps:
            await app.stop()


async def test_a_latched_topic_reaches_a_late_subscriber_of_another_process(
    router: Router, ros2: Any
) -> None:
    async with _processes(router, 2) as (first, second):
        async with connect(ws_url(first)) as conn:
            advertise = {"op": "advertise", "topic": "/lesson", "type": "std_msgs/msg/String"}
            await send_json(conn, {**advertise, "latch": True})
            await wait_for(lambda: "/lesson" in second.graph.topics.topics, timeout=10)
            msg = {"data": "lesson 3: PID"}
            await send_json(conn, {"op": "publish", "topic": "/lesson", "msg": msg, "latch": True})
            await asyncio.sleep(0.5)  # published long before the other process's client asks
            async with connect(ws_url(second)) as late:
                await send_json(late, {"op": "subscribe", "topic": "/lesson"})
                got = await recv_until(late, lambda m: m.get("topic") == "/lesson", timeout=8)
        assert got["msg"] == {"data": "lesson 3: PID"}
        assert second.graph.topics.topics["/lesson"].latch


def _phase(times: list[float], dt: float) -> float:
    """The mean phase of wall-clock times in a period ``dt`` (circular: no wrap at 0)."""
    angles = [2.0 * math.pi * (t % dt) / dt for t in times]
    mean = math.atan2(sum(map(math.sin, angles)), sum(map(math.cos, angles)))
    return (mean / (2.0 * math.pi) * dt) % dt


async def test_simulators_of_one_network_take_turns_in_the_step_period(
    router: Router, ros2: Any
) -> None:
    """Two simulators tick half a period apart (each sees the other's /virtual_robot)."""
    async with _processes(router, 2) as apps:

        def shares() -> list[tuple[int, int] | None]:
            return [app.zenoh.tick_share if app.zenoh is not None else None for app in apps]

        await wait_for(lambda: all(s is not None and s[1] == 2 for s in shares()), timeout=10)
        by_rank = sorted(apps, key=lambda app: app.zenoh.tick_share if app.zenoh else (0, 0))
        assert [app.zenoh.tick_share for app in by_rank if app.zenoh] == [(0, 2), (1, 2)]
        ticks: list[list[float]] = [[], []]
        for k, app in enumerate(by_rank):
            app.tick_hooks.append(lambda _now, k=k: ticks[k].append(time.time()))
        await wait_for(lambda: min(map(len, ticks)) >= 40, timeout=10)
        dt = apps[0].world.dt
        # rank r of 2 ticks r/2 of the period after each multiple of it (wall clock), after the
        # few ticks it takes to get there (a tenth of the period a tick)
        for rank, times in enumerate(ticks):
            off = (_phase(times[15:], dt) - rank * dt / 2.0 + dt / 2.0) % dt - dt / 2.0
            assert abs(off) < dt / 10.0, (rank, off, dt)
        health = apps[0].health()["zenoh"]
        assert health["tick_share"] in ([0, 2], [1, 2])


def test_the_simulators_are_the_sessions_with_both_simulator_nodes() -> None:
    """Rank by session id among the processes with /virtual_robot and /sim; not --no-sim."""

    def node(zid: str, name: str) -> str:
        return Entity(0, zid, "0", "0", "NN", "/", name).token()

    link = ZenohLink(Graph(), ZenohOptions(), simulator=True)
    link.zid = "5"
    assert link.tick_share is None
    link._token_changed(node("3", "virtual_robot"), alive=True)  # a node of that name alone
    assert link.tick_share is None
    link._token_changed(node("3", "sim"), alive=True)
    assert link.tick_share == (1, 2)
    link._token_changed(node("9", "virtual_robot"), alive=True)
    link._token_changed(node("9", "sim"), alive=True)
    assert link.tick_share == (1, 3)
    link._token_changed(node("3", "sim"), alive=False)  # "3" left (its tokens go one by one)
    assert link.tick_share == (0, 2)
    link._token_changed(node("9", "virtual_robot"), alive=False)
    assert link.tick_share is None  # alone again
    front = ZenohLink(Graph(), ZenohOptions(), simulator=False)
    front.zid = "1"
    front._token_changed(node("3", "virtual_robot"), alive=True)
    front._token_changed(node("3", "sim"), alive=True)
    assert front.tick_share is None  # a --no-sim front-end takes no turn
