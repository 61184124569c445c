from __future__ import annotations

import asyncio
from typing import Any

from websockets.asyncio.client import ClientConnection, connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.robot.simclock import MAX_REAL_TIME_FACTOR
from tests.conftest import AppFactory
from tests.helpers import recv_until, send_json, wait_for, ws_url


async def call(conn: ClientConnection, service: str, args: Any, op_id: str) -> Any:
    await send_json(conn, {"op": "call_service", "service": service, "args": args, "id": op_id})
    reply = await recv_until(conn, lambda m: m.get("op") == "service_response" and m["id"] == op_id)
    assert reply["result"] is True, reply
    return reply["values"]


def stamp_s(stamp: dict[str, int]) -> float:
    return stamp["sec"] + stamp["nanosec"] * 1e-9


async def next_clock(conn: ClientConnection) -> float:
    msg = await recv_until(conn, lambda m: m.get("op") == "publish" and m["topic"] == "/clock")
    return stamp_s(msg["msg"]["clock"])


async def test_clock_publishes_sim_time_every_step(ws: ClientConnection, app: App) -> None:
    """/clock (rosgraph_msgs/Clock) advances by exactly one dt per message."""
    await send_json(ws, {"op": "subscribe", "topic": "/clock", "type": "rosgraph_msgs/msg/Clock"})
    first = await next_clock(ws)
    second = await next_clock(ws)
    assert abs(second - first - app.world.dt) < 1e-9


async def test_pause_stops_time_and_step_advances_exactly_one_dt(
    ws: ClientConnection, app: App
) -> None:
    """While paused nothing moves; /sim/step advances one step, publishes it and runs its hooks.

    The step's hooks (TF, the watchdog, the grader) have run by the time the reply is sent, as
    a headless step's have (tests/test_headless.py).
    """
    await send_json(ws, {"op": "subscribe", "topic": "/clock"})
    await next_clock(ws)
    reply = await call(ws, "/sim/pause", {"data": True}, "p")
    assert reply["success"] is True
    paused_at = app.world.time
    steps = app.world.steps
    await wait_for(lambda: app.stats.ticks >= steps + 5)  # the loop keeps ticking
    assert app.world.time == paused_at
    hooked: list[int] = []
    app.tick_hooks.append(lambda now: hooked.append(app.world.steps))
    seen: list[Any] = []

    def until_reply(m: Any) -> bool:
        seen.append(m)
        return m.get("op") == "service_response" and m["id"] == "s"

    await send_json(ws, {"op": "call_service", "service": "/sim/step", "args": {}, "id": "s"})
    reply = await recv_until(ws, until_reply)
    assert reply["values"]["success"] is True, reply
    assert abs(app.world.time - paused_at - app.world.dt) < 1e-9
    assert hooked[-1] == steps + 1  # ran in the step, before its reply
    clocks = [stamp_s(m["msg"]["clock"]) for m in seen if m.get("topic") == "/clock"]
    assert clocks, "the step published no /clock before its reply"
    assert abs(clocks[-1] - app.world.time) < 1e-9
    reply = await call(ws, "/sim/pause", {"data": False}, "r")
    assert reply["success"] is True
    await wait_for(lambda: app.world.time > paused_at + 3 * app.world.dt)


async def test_step_is_refused_while_running(ws: ClientConnection) -> None:
    reply = await call(ws, "/sim/step", {}, "s")
    assert reply["success"] is False
    assert "pause it first" in reply["message"]


async def test_real_time_factor_speeds_the_loop_up(ws: ClientConnection, app: App) -> None:
    """At factor 4 sim time runs clearly faster than the wall clock; bad factors are refused."""
    for bad in (0, -1, MAX_REAL_TIME_FACTOR * 2):
        reply = await call(ws, "/sim/set_real_time_factor", {"factor": bad}, f"bad{bad}")
        assert reply["success"] is False, bad
    args = {"op": "call_service", "service": "/sim/set_real_time_factor", "id": "typed"}
    await send_json(ws, {**args, "args": {"factor": "fast"}})
    reply = await recv_until(ws, lambda m: m.get("id") == "typed")
    assert reply["result"] is False
    assert "factor" in reply["values"]
    reply = await call(ws, "/sim/set_real_time_factor", {"factor": 4.0}, "f")
    assert reply["success"] is True
    loop = asyncio.get_running_loop()
    t0, s0 = loop.time(), app.world.time
    await wait_for(lambda: app.world.time - s0 >= 2.0, timeout=5)
    ratio = (app.world.time - s0) / (loop.time() - t0)
    assert ratio > 2.0, ratio  # 1.0 without the factor; 4.0 on an idle machine


async def test_use_sim_time_stamps_headers_with_sim_time(make_app: AppFactory) -> None:
    """With use_sim_time, /odom header stamps equal the /clock time of the same step."""
    app = await make_app(use_sim_time=True)
    async with connect(ws_url(app)) as conn:
        await send_json(conn, {"op": "subscribe", "topic": "/odom"})
        msg = await recv_until(conn, lambda m: m.get("topic") == "/odom")
        stamp = stamp_s(msg["msg"]["header"]["stamp"])
        assert stamp < 3600  # sim time starts at 0; wall-clock stamps are ~1.7e9
        assert abs(stamp - round(stamp / app.world.dt) * app.world.dt) < 1e-6


async def test_wall_clock_stamps_by_default(ws: ClientConnection) -> None:
    await send_json(ws, {"op": "subscribe", "topic": "/odom"})
    msg = await recv_until(ws, lambda m: m.get("topic") == "/odom")
    assert stamp_s(msg["msg"]["header"]["stamp"]) > 1e9


def test_server_settings_default_to_wall_clock() -> None:
    assert ServerSettings().use_sim_time is False
