"""Hostile clients of issue 17 against a real server, each watched by an observer of /odom.

Every test runs one attack (rows 8-11, 13-15 and 19 of the issue's table) and asserts both the
refusal or the bound, and that an observer client's /odom kept its 20 Hz meanwhile (on the
server's header stamps, as ``tests/e2e/test_hostile.py``).
"""

from __future__ import annotations

import asyncio
import itertools
import json
import sys
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from simbridge.app.config import load_params, load_world, resource_dir
from simbridge.app.runner import App
from tests.conftest import AppFactory
from tests.helpers import (
    TIMEOUT_FACTOR,
    recv_until,
    send_json,
    stalled_client,
    wait_for,
    ws_url,
)


ADMIN = "admin-token-for-tests"
TOKENS = {f"student-r{n}": f"r{n}" for n in range(1, 6)} | {"ta-token": "*"}
#: The bench holds 19 Hz and 150 ms on a process of its own (bench/hostile.py,
#: bench/httpattacks.py): those are the figures. The suite runs in the same process as its
#: clients, late in a run of a thousand tests on 2 cores, so here the bounds only tell a stall
#: (a stalled loop loses seconds) from a hiccup: full runs on 2 idle cores saw a gap of 284 ms
#: and 16.7 Hz once each (a 278 ms pause of the test process), and a run on a new machine, with
#: the arm64 images building under emulation beside it, a gap of 400.1 ms (the loop 350 ms late
#: once, 7 ticks skipped); those pass. A loop that misses more than a quarter of its ticks or
#: one 600 ms stretch does not.
MIN_RATE = 15.0
MAX_GAP = 0.6 * TIMEOUT_FACTOR


def _stamp(value: Any) -> float:
    return float(value["sec"]) + float(value["nanosec"]) * 1e-9


class OdomWatch:
    """A well-behaved client reading an odometry topic: the server's stamps of each message."""

    def __init__(self, ws: ClientConnection, topic: str) -> None:
        self.ws = ws
        self.topic = topic
        self.stamps: list[float] = []

    async def read(self) -> None:
        async for data in self.ws:
            msg = json.loads(data)
            if msg.get("topic") == self.topic:
                self.stamps.append(_stamp(msg["msg"]["header"]["stamp"]))

    async def steady_since(self, start: float, seconds: float = 1.5) -> None:
        """Wait (bounded) for ``seconds`` of stamps after ``start``; assert 20 Hz, no gap."""
        end = start + seconds
        await wait_for(lambda: bool(self.stamps) and self.stamps[-1] >= end, timeout=10)
        window = [s for s in self.stamps if start <= s <= end]
        assert len(window) >= 2, f"/odom stopped: {len(window)} messages in {seconds} s"
        rate = (len(window) - 1) / (window[-1] - window[0])
        gap = max(max(b - a for a, b in itertools.pairwise(window)), window[0] - start)
        assert rate >= MIN_RATE, f"/odom at {rate:.1f} Hz during the attack"
        assert gap <= MAX_GAP, f"/odom gap of {gap * 1e3:.0f} ms during the attack"


@asynccontextmanager
async def odom_watch(app: App, topic: str = "/odom", token: str = "") -> AsyncIterator[OdomWatch]:
    """An observer subscribed to ``topic``, reading in the background."""
    query = f"/?token={token}" if token else ""
    async with connect(ws_url(app) + query, max_size=None) as ws:
        watch = OdomWatch(ws, topic)
        await send_json(ws, {"op": "subscribe", "topic": topic})
        task = asyncio.create_task(watch.read())
        try:
            await wait_for(lambda: bool(watch.stamps), timeout=5)
            yield watch
        finally:
            task.cancel()


async def classroom(make_app: AppFactory, **settings: Any) -> App:
    """The classroom world (r1-r4) with client tokens and the admin token."""
    options: dict[str, Any] = {"client_tokens": TOKENS, "admin_token": ADMIN}
    options.update(settings)
    world = load_world(resource_dir("config") / "worlds" / "classroom.yaml")
    return await make_app(world=world, **options)


def student(app: App, robot: str = "r3") -> Any:
    # max_queue=None: a test client that reads little must still close at once
    return connect(f"{ws_url(app)}/?token=student-{robot}", max_size=None, max_queue=None)


def tf_goal(goal_id: str, sources: list[str], **extra: Any) -> dict[str, Any]:
    args = {"source_frames": sources, "target_frame": "r1/odom", "rate": 10.0}
    args.update(extra)
    return {
        "op": "send_action_goal",
        "id": goal_id,
        "action": "/tf2_web_republisher",
        "action_type": "tf2_web_republisher_interfaces/action/TFSubscription",
        "args": args,
        "feedback": True,
    }


def is_op(*ops: str) -> Any:
    return lambda m: m.get("op") in ops


# -- row 8: /republish_tfs and TF goals --------------------------------------------------


async def test_republish_tfs_is_capped_per_client_and_dropped_with_its_caller(
    make_app: AppFactory,
) -> None:
    """A 63-year timeout is capped; the 11th request is refused by name; all go with the caller."""
    app = await classroom(make_app)
    years = {"sec": 63 * 365 * 86400, "nanosec": 0}
    request = {"source_frames": ["r1/base_link"], "target_frame": "r1/odom", "timeout": years}
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with student(app) as ws:
            replies = []
            for n in range(12):
                call = {"op": "call_service", "service": "/republish_tfs", "args": request}
                await send_json(ws, {**call, "id": n})
                replies.append(await recv_until(ws, is_op("service_response")))
            assert all(r["result"] for r in replies[:10])
            assert replies[10]["result"] is False
            assert "tf_requests_per_client" in replies[10]["values"]
            limit = app.settings.tf_max_timeout
            assert {r.timeout for r in app.tf_republisher.requests} == {limit}
            costly = {"source_frames": ["r1/base_link"] * 100, "rate": 20.0}
            await send_json(ws, {"op": "call_service", "service": "/republish_tfs", "args": costly})
            # a fresh client, the same cost: over tf_transforms_per_client
            async with student(app, "r2") as other:
                await send_json(
                    other, {"op": "call_service", "service": "/republish_tfs", "args": costly}
                )
                reply = await recv_until(other, is_op("service_response"))
                assert reply["result"] is False
                assert "tf_transforms_per_client" in reply["values"]
        await wait_for(lambda: not app.tf_republisher.requests)
        assert not [t for t in app.graph.topics.topics if t.startswith("/tf_repub_")]
        await watch.steady_since(start)


async def test_tf_goals_over_the_budget_are_refused_and_cancelled_with_their_caller(
    make_app: AppFactory,
) -> None:
    """500 TF goals from one client: 10 run, the rest are refused; none outlive the client."""
    app = await classroom(make_app)
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with student(app) as ws:
            for n in range(500):
                await send_json(ws, tf_goal(f"g{n}", ["r1/base_link", "r2/base_link"]))
            refusal = await recv_until(ws, is_op("action_result"))
            assert refusal["result"] is False and "tf_requests_per_client" in refusal["values"]
            await wait_for(lambda: len(app.graph.actions.goals) == 10)
            assert len(app.tf_republisher.requests) == 10
            await watch.steady_since(start)
        await wait_for(lambda: not app.tf_republisher.requests and not app.graph.actions.goals)


# -- row 9: a TF goal that would fail every tick; hooks isolated ---------------------------


async def test_a_tf_goal_with_a_lone_surrogate_or_a_negative_rate_is_refused(
    make_app: AppFactory,
) -> None:
    """The bad goal gets a refusal naming the problem; the loop and the watchdog go on."""
    app = await classroom(make_app, params=_watchdog_params())
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with student(app, "r1") as ws:
            bad = tf_goal("s", ["\ud800"], target_frame="\ud800")
            await ws.send(json.dumps(bad, ensure_ascii=True))
            reply = await recv_until(ws, is_op("action_result", "status"))
            text = reply.get("values") or reply.get("msg")
            assert "surrogate" in str(text)
            negative = tf_goal("n", ["r1/base_link"], rate=-1.0)
            await send_json(ws, negative)
            reply = await recv_until(ws, is_op("action_result", "status"))
            assert "rate must be" in str(reply.get("values") or reply.get("msg"))
            assert not app.tf_republisher.requests
            await _watchdog_stops(app, ws)
        await watch.steady_since(start)
    assert app.steps.failures == 0


def _watchdog_params() -> Any:
    params = load_params()
    params.safety.cmd_vel_timeout = 0.3
    return params


async def _watchdog_stops(app: App, ws: Any) -> None:
    """r1 commanded once stops within the watchdog's timeout + one tick (+ a tick's slack)."""
    twist = {"linear": {"x": 0.2}, "angular": {"z": 0.0}}
    await send_json(ws, {"op": "publish", "topic": "/r1/cmd_vel", "msg": twist})
    robot = app.world.robots["r1"]
    await wait_for(lambda: robot.cmd_v != 0.0)
    moving = time.monotonic()
    await wait_for(lambda: robot.cmd_v == 0.0, timeout=2)
    timeout = app.world.params.safety.cmd_vel_timeout
    assert time.monotonic() - moving <= timeout + 3 * app.world.dt * TIMEOUT_FACTOR


async def test_a_failing_tick_hook_never_skips_the_watchdog_and_is_logged_once(
    make_app: AppFactory, caplog: pytest.LogCaptureFixture
) -> None:
    """A hook that raises every tick, placed first: the watchdog still stops the robot."""
    app = await classroom(make_app, params=_watchdog_params())

    def broken(now: float) -> None:
        raise RuntimeError("broken hook")

    app.tick_hooks.insert(0, broken)
    async with connect(f"{ws_url(app)}/?token=student-r1") as ws:
        await _watchdog_stops(app, ws)
    assert app.steps.failures >= 5  # every tick failed, each logged once below
    logged = [r for r in caplog.records if r.exc_info and "broken hook" in str(r.exc_info[1])]
    assert len(logged) == 1


# -- row 10: what the server provides stays the server's -----------------------------------


async def test_a_client_cannot_take_over_the_servers_tf_action(make_app: AppFactory) -> None:
    """advertise_action /tf2_web_republisher is refused; TF still works for others after."""
    app = await classroom(make_app)
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with connect(f"{ws_url(app)}/?token=ta-token") as ws:
            take = {
                "op": "advertise_action",
                "action": "/tf2_web_republisher",
                "type": "tf2_web_republisher_interfaces/action/TFSubscription",
            }
            await send_json(ws, take)
            status = await recv_until(ws, is_op("status"))
            assert "the server provides this action" in status["msg"]
        async with student(app, "r1") as other:
            await send_json(other, tf_goal("after", ["r1/base_link"]))
            await recv_until(other, is_op("action_feedback"))
        await watch.steady_since(start)


# -- row 11: the stall timer times the stall --------------------------------------------


async def test_a_long_connected_client_pausing_its_reads_briefly_is_not_evicted(
    make_app: AppFactory,
) -> None:
    """Connected 1.5x stall_timeout, then reading nothing for half of it: kept, drained."""
    app = await make_app(stall_timeout=1.0)
    sub = {"op": "subscribe", "topic": "/blob", "type": "std_msgs/String"}
    sock = await stalled_client(app.ws_port, sub)
    loop = asyncio.get_running_loop()

    async def read() -> None:
        while await loop.sock_recv(sock, 65536):
            pass

    try:
        reader = asyncio.create_task(read())
        await asyncio.sleep(1.5)  # a healthy client for longer than stall_timeout
        client = next(c for c in app.server.clients if "/blob" in c.session.subscriptions)
        reader.cancel()
        async with connect(ws_url(app)) as talker, odom_watch(app) as watch:
            start = watch.stamps[-1]
            await send_json(
                talker, {"op": "advertise", "topic": "/blob", "type": "std_msgs/String"}
            )
            blob = {"op": "publish", "topic": "/blob", "msg": {"data": "x" * 100_000}}

            async def flood(until: Callable[[], bool]) -> None:
                while not until():
                    await send_json(talker, blob)
                    await asyncio.sleep(0.01)

            # until the socket's buffers are full and frames wait for it...
            await asyncio.wait_for(flood(lambda: bool(client.queue.pending)), 10 * TIMEOUT_FACTOR)
            waiting = time.monotonic()
            # ...then for half the stall_timeout more: the old timer (from the connection's
            # last queued write, 1.5 s ago) evicted it within a quarter of a second
            await flood(lambda: time.monotonic() - waiting > 0.5)
            assert client.queue.pending, "frames stopped waiting while it did not read"
            assert client in app.server.clients and app.server.stalled_total == 0
            reader = asyncio.create_task(read())
            await wait_for(lambda: not client.queue.pending, timeout=10)
            await watch.steady_since(start, 1.0)
        assert client in app.server.clients and app.server.stalled_total == 0
        reader.cancel()
    finally:
        sock.close()


# -- row 13: connections that owe a token --------------------------------------------


#: Opens N token-less connections from its own process (their handshakes are the attack, not
#: the test's client work), prints what happened as JSON, holds them until stdin closes.
TOKENLESS = """
import asyncio, json, sys
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

async def main(url, n):
    opened, refused = [], []
    async def one():
        try:
            opened.append(await connect(url, open_timeout=20))
        except InvalidStatus as err:
            refused.append([err.response.status_code, err.response.body.decode()])
    await asyncio.gather(*(one() for _ in range(n)))
    print(json.dumps({"opened": len(opened), "refused": refused}), flush=True)
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)

asyncio.run(main(sys.argv[1], int(sys.argv[2])))
"""


async def test_token_less_connections_cannot_fill_the_class(make_app: AppFactory) -> None:
    """200 token-less connections: 20 wait in their own pool, the rest get 503; a student is in."""
    app = await classroom(make_app, max_clients=30, auth_timeout=30.0)
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            TOKENLESS,
            ws_url(app),
            "200",
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
        )
        assert proc.stdin is not None and proc.stdout is not None
        try:
            line = await asyncio.wait_for(proc.stdout.readline(), 60 * TIMEOUT_FACTOR)
            result = json.loads(line)
            assert result["opened"] == app.settings.max_unauthenticated
            assert {code for code, _ in result["refused"]} == {503}
            assert "max_unauthenticated" in result["refused"][0][1]
            async with student(app, "r1") as ws:
                call = {"op": "call_service", "service": "/rosapi/topics", "id": 1}
                await send_json(ws, call)
                assert (await recv_until(ws, is_op("service_response")))["result"] is True
            await watch.steady_since(start)
        finally:
            proc.stdin.close()
            await asyncio.wait_for(proc.wait(), 20)


async def test_a_token_less_connection_is_closed_after_auth_timeout(make_app: AppFactory) -> None:
    """It is told why and closed with 1008; its slot is free again; big frames are refused."""
    app = await classroom(make_app, auth_timeout=0.5, max_unauthenticated=1)
    async with connect(ws_url(app)) as ws:
        status = await recv_until(ws, is_op("status"))
        assert "auth_timeout" in status["msg"]
        with pytest.raises(ConnectionClosed) as info:
            await asyncio.wait_for(ws.recv(), 5)
        assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    await wait_for(lambda: not app.server.clients)
    async with connect(ws_url(app), max_size=None) as ws:  # the slot is free again
        await ws.send("x" * 100_000)  # bigger than any auth op: not read before admission
        with pytest.raises(ConnectionClosed) as info:
            await asyncio.wait_for(ws.recv(), 5)
        assert info.value.rcvd is not None and info.value.rcvd.code == 1009


# -- rows 14-15: others' goals, others' robots ------------------------------------------


async def test_a_student_cannot_cancel_the_goals_of_another(make_app: AppFactory) -> None:
    """r3 cancels every TF goal: only its own end; r1's goal keeps its feedback."""
    app = await classroom(make_app)
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with student(app, "r1") as victim, student(app, "r3") as ws:
            await send_json(victim, tf_goal("mine", ["r1/base_link"]))
            await recv_until(victim, is_op("action_feedback"))
            zero = {"goal_id": {"uuid": [0] * 16}, "stamp": {"sec": 0, "nanosec": 0}}
            call = {
                "op": "call_service",
                "service": "/tf2_web_republisher/_action/cancel_goal",
                "args": {"goal_info": zero},
                "id": "c",
            }
            await send_json(ws, call)
            reply = await recv_until(ws, is_op("service_response"))
            assert reply["result"] is True and reply["values"]["goals_canceling"] == []
            goal = next(iter(app.graph.actions.goals.values()))
            theirs = {"goal_id": {"uuid": list(goal.uuid)}, "stamp": {"sec": 0, "nanosec": 0}}
            await send_json(ws, {**call, "args": {"goal_info": theirs}})
            reply = await recv_until(ws, is_op("service_response"))
            assert reply["result"] is False and "another client" in reply["values"]
            assert not goal.done and any(r.goal is goal for r in app.tf_republisher.requests)
        await watch.steady_since(start)


async def test_a_student_cannot_squat_another_robots_names(make_app: AppFactory) -> None:
    """r3's student cannot claim /r5/*, so the instructor's /spawn r5 succeeds."""
    app = await classroom(make_app)
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with student(app, "r3") as ws, connect(f"{ws_url(app)}/?token={ADMIN}") as admin:
            await send_json(
                ws, {"op": "advertise", "topic": "/r5/cmd_vel", "type": "std_msgs/String"}
            )
            assert "/r3/" in (await recv_until(ws, is_op("status")))["msg"]
            typed = {"op": "subscribe", "topic": "/r5/odom", "type": "std_msgs/String"}
            await send_json(ws, typed)
            assert "claim the name" in (await recv_until(ws, is_op("status")))["msg"]
            spawn = {"x": 0.0, "y": 1.5, "theta": 0.0, "name": "r5"}
            call = {"op": "call_service", "service": "/spawn", "args": spawn, "id": "s"}
            await send_json(admin, call)
            assert (await recv_until(admin, is_op("service_response")))["result"] is True
            assert app.graph.topics.topics["/r5/odom"].type == "nav_msgs/msg/Odometry"
        await watch.steady_since(start)


async def test_spawn_over_a_name_held_with_another_type_fails_cleanly(make_app: AppFactory) -> None:
    """A client with every topic holds /r5/cmd_vel as a String: /spawn r5 fails, leaving nothing."""
    app = await classroom(make_app)
    async with (
        connect(f"{ws_url(app)}/?token=ta-token") as ta,
        connect(f"{ws_url(app)}/?token={ADMIN}") as admin,
    ):
        await send_json(ta, {"op": "advertise", "topic": "/r5/cmd_vel", "type": "std_msgs/String"})
        await wait_for(lambda: "/r5/cmd_vel" in app.graph.topics.topics)
        spawn = {"x": 0.0, "y": 1.5, "theta": 0.0, "name": "r5"}
        call = {"op": "call_service", "service": "/spawn", "args": spawn, "id": "s"}
        await send_json(admin, call)
        reply = await recv_until(admin, is_op("service_response"))
        assert reply["result"] is False and "/r5/cmd_vel" in reply["values"]
        assert "r5" not in app.world.robots
        assert [t for t in app.graph.topics.topics if t.startswith("/r5/")] == ["/r5/cmd_vel"]
        assert "/r5/teleport_absolute" not in app.graph.services.services
        await ta.close()
        await wait_for(lambda: "/r5/cmd_vel" not in app.graph.topics.topics)
        await send_json(admin, call)
        assert (await recv_until(admin, is_op("service_response")))["result"] is True
        await wait_for(lambda: app.stats.ticks > 3)
        assert app.steps.failures == 0


# -- row 19: the world's bounds -------------------------------------------------------


async def test_teleport_outside_the_world_is_refused(make_app: AppFactory) -> None:
    app = await classroom(make_app)
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        async with student(app, "r1") as ws:
            pose = {"x": 1000.0, "y": -1000.0, "theta": 0.0}
            call = {"op": "call_service", "service": "/r1/teleport_absolute", "args": pose}
            await send_json(ws, call)
            reply = await recv_until(ws, is_op("service_response"))
            assert reply["result"] is False and "outside the world" in reply["values"]
        robot = app.world.robots["r1"]
        assert (robot.state.x, robot.state.y) == (-2.0, -1.0)
        await watch.steady_since(start)
