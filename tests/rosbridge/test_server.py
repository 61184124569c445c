from __future__ import annotations

import asyncio
import json
import socket
import struct
import urllib.request

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from simbridge.app.runner import App
from simbridge.rosbridge import status_frame
from tests.conftest import AppFactory
from tests.helpers import recv_json, recv_until, send_json, stalled_client, wait_for, ws_url


async def test_bad_input_gets_status_errors_and_the_connection_stays_open(app: App) -> None:
    """Invalid JSON, unknown ops, missing and wrong-typed fields: one status error each."""
    async with connect(ws_url(app)) as ws:
        for frame in (
            "{oops",
            '{"op":"dance"}',
            '{"op":"subscribe"}',
            '{"op":"advertise","topic":1}',
        ):
            await ws.send(frame)
            reply = await recv_json(ws)
            assert reply["op"] == "status" and reply["level"] == "error", reply
        await send_json(ws, {"op": "call_service", "service": "/rosapi/topics", "id": "after"})
        reply = await recv_until(ws, lambda m: m.get("op") == "service_response")
        assert reply["id"] == "after" and reply["result"] is True


async def test_garbage_binary_frame_is_answered_not_fatal(app: App) -> None:
    """A binary frame that is not UTF-8 JSON gets a status error; the client stays."""
    async with connect(ws_url(app)) as ws:
        await ws.send(b"\xff\x00\x13\x37")
        reply = await recv_json(ws)
        assert "could not decode the binary frame" in reply["msg"]


async def test_a_bad_client_does_not_affect_others_or_the_robot(app: App) -> None:
    """While one client sends junk and hostile commands, another sees /odom and a still robot."""
    async with connect(ws_url(app)) as good, connect(ws_url(app)) as bad:
        await send_json(good, {"op": "subscribe", "topic": "/odom"})
        await recv_until(good, lambda m: m.get("topic") == "/odom")
        for frame in (
            "not json",
            json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": None}}}),
            json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": "fast"}}}),
            '{"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": Infinity}}}',
        ):
            await bad.send(frame)
            assert (await recv_json(bad))["op"] == "status"
        odom = await recv_until(good, lambda m: m.get("topic") == "/odom")
        assert odom["msg"]["pose"]["pose"]["position"]["x"] == 0.0
        assert app.world.robots[""].cmd_v == 0.0


async def test_stalled_client_is_bounded_and_does_not_delay_others(make_app: AppFactory) -> None:
    """A client that stops reading: its queue stays within the byte budget, others keep 20 Hz."""
    app = await make_app(max_queue_bytes=200_000)
    big = "x" * 100_000
    sub = {"op": "subscribe", "topic": "/blob", "type": "std_msgs/String"}
    stalled = await stalled_client(app.ws_port, sub)
    try:
        await _flood_while_stalled(app, big)
    finally:
        stalled.close()


async def _flood_while_stalled(app: App, big: str) -> None:
    async with connect(ws_url(app)) as talker, connect(ws_url(app)) as watcher:
        await wait_for(lambda: any(c.session.subscriptions for c in app.server.clients))
        await send_json(watcher, {"op": "subscribe", "topic": "/odom"})
        await recv_until(watcher, lambda m: m.get("topic") == "/odom")
        await send_json(talker, {"op": "advertise", "topic": "/blob", "type": "std_msgs/String"})
        server_side = next(c for c in app.server.clients if c.session.subscriptions.get("/blob"))

        async def flood() -> None:
            while server_side.queue.dropped == 0:
                await send_json(talker, {"op": "publish", "topic": "/blob", "msg": {"data": big}})
                await asyncio.sleep(0.005)

        await asyncio.wait_for(flood(), 30)
        assert server_side.queue.bytes <= 200_000
        ticks = app.stats.ticks
        for _ in range(10):
            await recv_until(watcher, lambda m: m.get("topic") == "/odom")
        assert app.stats.ticks - ticks <= 12  # ten /odom within ~ten ticks: nobody waited


async def test_websocket_port_answers_plain_http_health_checks(app: App) -> None:
    """GET /healthz on the rosbridge port (Docker HEALTHCHECK) returns JSON status ok."""

    def fetch() -> dict[str, object]:
        with urllib.request.urlopen(f"http://127.0.0.1:{app.ws_port}/healthz", timeout=5) as r:
            assert r.status == 200
            return json.loads(r.read())

    body = await asyncio.to_thread(fetch)
    assert body["status"] == "ok"


async def test_disconnect_cleans_up_the_client(app: App) -> None:
    """After a client leaves, its subscriptions, topics and services are gone."""
    async with connect(ws_url(app)) as ws:
        await send_json(ws, {"op": "advertise", "topic": "/mine", "type": "std_msgs/String"})
        await send_json(
            ws, {"op": "advertise_service", "service": "/my_srv", "type": "std_srvs/Trigger"}
        )
        await send_json(ws, {"op": "subscribe", "topic": "/odom"})
        await recv_until(ws, lambda m: m.get("topic") == "/odom")
        assert "/mine" in app.graph.topics.topics
    await wait_for(lambda: not app.server.clients)
    assert "/mine" not in app.graph.topics.topics
    assert "/my_srv" not in app.graph.services.services
    assert not app.graph.topics.topics["/odom"].sinks


async def test_clients_over_max_clients_are_refused_with_503(make_app: AppFactory) -> None:
    app = await make_app(max_clients=2)
    async with connect(ws_url(app)), connect(ws_url(app)):
        with pytest.raises(InvalidStatus) as info:
            async with connect(ws_url(app)):
                pass
        assert info.value.response.status_code == 503
        assert b"full" in info.value.response.body
    await wait_for(lambda: not app.server.clients)
    async with connect(ws_url(app)) as ws:  # room again
        await send_json(ws, {"op": "call_service", "service": "/rosapi/topics", "id": 1})
        assert (await recv_until(ws, lambda m: m.get("id") == 1))["result"] is True
    assert app.server.refused_total == 1


async def test_a_stalled_client_is_told_once_then_disconnected_after_stall_timeout(
    make_app: AppFactory,
) -> None:
    """A client that reads nothing loses old messages, then is dropped; the others go on."""
    app = await make_app(max_queue_bytes=200_000, stall_timeout=1.0)
    sub = {"op": "subscribe", "topic": "/blob", "type": "std_msgs/String"}
    stalled = await stalled_client(app.ws_port, sub)
    try:
        await _flood_while_stalled(app, "x" * 100_000)
        victim = next(c for c in app.server.clients if c.session.subscriptions.get("/blob"))
        assert victim.told_dropped
        warnings = [f for f in victim.queue._fifo if f.frame and b'"warning"' in f.frame.data]
        assert len(warnings) <= 1  # told once, not once per dropped message
        await wait_for(lambda: victim not in app.server.clients, timeout=10)
        assert app.server.stalled_total == 1
        assert "/blob" not in app.graph.topics.topics  # the victim's subscription is gone too
    finally:
        stalled.close()


async def test_keepalive_pings_evict_a_dead_peer(make_app: AppFactory) -> None:
    """A peer that never answers pings (gone without a FIN) is dropped after the timeout."""
    app = await make_app(ping_interval=0.2, ping_timeout=0.2)
    dead = await stalled_client(app.ws_port, {"op": "subscribe", "topic": "/rosout"})
    try:
        await wait_for(lambda: len(app.server.clients) == 1)
        await wait_for(lambda: not app.server.clients, timeout=15)
    finally:
        dead.close()


async def test_message_flood_is_rate_limited_told_once_and_the_client_carries_on(
    make_app: AppFactory,
) -> None:
    app = await make_app(message_rate=20.0, message_burst=10)
    async with connect(ws_url(app)) as ws:
        for k in range(200):
            await send_json(ws, {"op": "set_level", "level": "error", "id": k})
        told = await recv_until(ws, lambda m: m.get("op") == "status")
        assert "too many messages" in told["msg"] and "message_rate" in told["msg"]
        await asyncio.sleep(0.6)  # a sustained 20/s is allowed again
        await send_json(ws, {"op": "call_service", "service": "/rosapi/topics", "id": "ok"})
        reply = await recv_until(ws, lambda m: m.get("op") == "service_response")
        assert reply["result"] is True


async def test_cmd_vel_flood_does_not_stall_the_loop_or_other_clients(app: App) -> None:
    """One client floods /cmd_vel as fast as it can; another still gets /odom at 20 Hz."""
    async with connect(ws_url(app)) as flooder, connect(ws_url(app)) as watcher:
        await send_json(watcher, {"op": "subscribe", "topic": "/odom"})
        await recv_until(watcher, lambda m: m.get("topic") == "/odom")
        frame = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.0}}})
        stop = asyncio.Event()

        async def flood() -> int:
            sent = 0
            while not stop.is_set():
                await flooder.send(frame)
                sent += 1
                if sent % 64 == 0:
                    await asyncio.sleep(0)
            return sent

        task = asyncio.create_task(flood())
        loop = asyncio.get_running_loop()
        start = loop.time()
        ticks = app.stats.ticks
        for _ in range(40):
            await recv_until(watcher, lambda m: m.get("topic") == "/odom")
        elapsed = loop.time() - start
        stop.set()
        sent = await task
        assert sent > 1000, sent
        assert app.stats.ticks - ticks >= 38
        assert elapsed < 2.0 * 1.5, elapsed  # 40 messages at 20 Hz: 2 s, with slack for load


async def test_abrupt_disconnect_of_a_provider_fails_its_pending_calls(app: App) -> None:
    """A provider that vanishes mid-call: the caller gets result false, nothing lingers."""
    provider = await stalled_client(
        app.ws_port, {"op": "advertise_service", "service": "/slow", "type": "std_srvs/Trigger"}
    )
    try:
        await wait_for(lambda: "/slow" in app.graph.services.services)
        async with connect(ws_url(app)) as caller:
            await send_json(caller, {"op": "call_service", "service": "/slow", "id": "c1"})
            await wait_for(lambda: bool(app.graph.services.pending))
            provider.setsockopt(
                socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00"
            )
            provider.close()  # RST: no close frame
            reply = await recv_until(caller, lambda m: m.get("op") == "service_response")
            assert reply["id"] == "c1" and reply["result"] is False
            assert "/slow" in reply["values"]
    finally:
        provider.close()
    await wait_for(lambda: len(app.server.clients) == 0, timeout=5)
    assert "/slow" not in app.graph.services.services and not app.graph.services.pending


async def test_abrupt_disconnect_of_an_action_server_aborts_its_goals(app: App) -> None:
    """An action server that vanishes mid-goal: the caller gets a failed action_result."""
    provider = await stalled_client(
        app.ws_port,
        {"op": "advertise_action", "action": "/fib", "type": "example_interfaces/Fibonacci"},
    )
    try:
        await wait_for(lambda: "/fib" in app.graph.actions.actions)
        async with connect(ws_url(app)) as caller:
            goal = {
                "op": "send_action_goal",
                "action": "/fib",
                "action_type": "example_interfaces/action/Fibonacci",
                "args": {"order": 5},
                "id": "g1",
            }
            await send_json(caller, goal)
            await wait_for(lambda: bool(app.graph.actions.goals))
            provider.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            provider.close()  # RST: no close frame
            reply = await recv_until(caller, lambda m: m.get("op") == "action_result")
            assert reply["id"] == "g1" and reply["result"] is False
    finally:
        provider.close()
    await wait_for(lambda: not app.server.clients, timeout=5)
    assert "/fib" not in app.graph.actions.actions and not app.graph.actions.goals


async def test_subscription_changes_apply_to_the_next_message(app: App) -> None:
    """Each delivery follows the current subscriptions (the server caches how it delivers).

    A plain /odom subscriber gets whole frames; a later op carrying ``fragment_size`` makes
    its next /odom messages arrive in fragments; a second spelling of the topic adds a second
    copy; after unsubscribing that spelling, one copy again; a gone client takes nothing.
    """
    async with connect(ws_url(app)) as ws, connect(ws_url(app)) as other:
        await send_json(ws, {"op": "subscribe", "topic": "/odom"})
        await send_json(other, {"op": "subscribe", "topic": "/odom"})
        first = await recv_until(ws, lambda m: m.get("op") == "publish")
        assert first["topic"] == "/odom"
        await other.close()
        await send_json(ws, {"op": "subscribe", "topic": "/tf_static", "fragment_size": 300})
        await recv_until(ws, lambda m: m.get("op") == "fragment" and m["id"].startswith("/odom"))
        await send_json(ws, {"op": "subscribe", "topic": "/scan", "fragment_size": 100_000})
        # the client-wide fragment size is now large: /odom comes whole again
        await recv_until(ws, lambda m: m.get("op") == "publish" and m["topic"] == "/odom")
        await send_json(ws, {"op": "subscribe", "topic": "odom"})  # a second spelling
        spellings = set()
        while spellings != {"/odom", "odom"}:
            msg = await recv_until(ws, lambda m: m.get("topic") in ("/odom", "odom"))
            spellings.add(msg["topic"])
        await send_json(ws, {"op": "unsubscribe", "topic": "odom"})
        stamps: dict[str, list[tuple[int, int]]] = {"/odom": [], "odom": []}
        while len(stamps["/odom"]) < 5:
            msg = await recv_until(ws, lambda m: m.get("topic") in ("/odom", "odom"))
            stamp = msg["msg"]["header"]["stamp"]
            stamps[msg["topic"]].append((stamp["sec"], stamp["nanosec"]))
        # anything under the old spelling was sent before the unsubscribe took effect
        assert all(s < stamps["/odom"][-1] for s in stamps["odom"])
        assert len(set(stamps["/odom"])) == len(stamps["/odom"])
    await wait_for(lambda: not app.server.clients)


@pytest.mark.parametrize("size", [0, 125, 126, 65535, 65536])
@pytest.mark.parametrize("text", [True, False])
def test_a_frame_framed_once_for_all_is_what_websockets_writes(size: int, text: bool) -> None:
    from websockets.protocol import State
    from websockets.server import ServerProtocol

    from simbridge.rosbridge import Frame
    from simbridge.rosbridge.server import _wire

    data = (b"x" if text else b"\xff") * size
    protocol = ServerProtocol()
    protocol.state = State.OPEN
    if text:
        protocol.send_text(data)
    else:
        protocol.send_binary(data)
    assert _wire(Frame(data, text)) == b"".join(protocol.data_to_send())


async def test_messages_of_one_turn_are_written_together_in_the_order_published(app: App) -> None:
    """What a client gets in one turn of the event loop goes out in one write, in order.

    Three publications on two topics, then a status frame sent to the client alone, all in
    one synchronous block: the client reads them in that order.
    """
    graph = app.graph
    a = graph.advertise("/corked_a", "std_msgs/msg/String", "/test_node")
    b = graph.advertise("/corked_b", "std_msgs/msg/String", "/test_node")
    async with connect(ws_url(app)) as ws:
        await send_json(ws, {"op": "subscribe", "topic": "/corked_a"})
        await send_json(ws, {"op": "subscribe", "topic": "/corked_b"})
        await wait_for(lambda: bool(a.sinks and b.sinks))
        (client,) = app.server.clients
        now = asyncio.get_running_loop().time()
        graph.publish(a, {"data": "1"}, now)
        graph.publish(b, {"data": "2"}, now)
        graph.publish(a, {"data": "3"}, now)
        assert len(client.corked) == 3  # not written yet: at the end of this turn
        client.send(status_frame("warning", "4"))  # goes after what was corked before it
        assert not client.corked
        got = [json.loads(await ws.recv()) for _ in range(4)]
    assert [(m["topic"], m["msg"]["data"]) for m in got[:3]] == [
        ("/corked_a", "1"),
        ("/corked_b", "2"),
        ("/corked_a", "3"),
    ]
    assert got[3]["op"] == "status" and got[3]["msg"] == "4"


@pytest.mark.parametrize(
    ("close_code", "keeps"),
    [(1000, True), (None, True), (1001, False), (4000, False), ("no frame", False)],
)
async def test_a_robot_keeps_its_command_only_when_its_client_closed_on_purpose(
    app: App, close_code: int | str | None, keeps: bool
) -> None:
    """1000 or no code: the course's robot. A page gone (1001), an error, no frame: stopped."""
    ws = await connect(ws_url(app))
    msg = {"linear": {"x": 0.2}, "angular": {"z": 0.0}}
    await send_json(ws, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
    await send_json(ws, {"op": "publish", "topic": "/cmd_vel", "msg": msg})
    robot = app.world.robots[""]
    await wait_for(lambda: robot.cmd_v == 0.2)
    if close_code == "no frame":
        ws.transport.abort()
    elif close_code is None:  # an empty close frame, as roslibpy and ws.close() send
        ws.transport.write(b"\x88\x80\x00\x00\x00\x00")  # FIN + close, masked, no payload
    else:
        assert isinstance(close_code, int)
        await ws.close(code=close_code)
    await wait_for(lambda: not app.server.clients)
    assert robot.cmd_v == (0.2 if keeps else 0.0)
    assert app.safety.stops == (0 if keeps else 1)
