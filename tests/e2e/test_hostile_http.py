"""Issue 29's HTTP attacks (items 2, 3, 7 and 11) against a real server, each watched.

Every test runs one attack for about a second and a half against the classroom world and
asserts the refusal or the bound, that an observer client's ``/r1/odom`` kept its 20 Hz on the
server's header stamps (as ``tests/e2e/test_hostile_clients.py``), and that the process's
resident set grew by less than :data:`MAX_RSS_GROWTH_MB` over its quiet value just before the
attack. The attackers connect from loopback addresses of their own (``127.0.0.2`` and up), as
machines other than the page's and the instructor's. ``bench/httpattacks.py`` runs the
full-size attacks against a separate server process for the figures.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import Counter
from collections.abc import AsyncIterator
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.config import load_world, resource_dir
from tests.conftest import AppFactory
from tests.e2e.test_hostile_clients import ADMIN, classroom, odom_watch
from tests.helpers import TIMEOUT_FACTOR, wait_for, ws_url


pytestmark = pytest.mark.e2e

#: How long each attack runs (seconds).
ATTACK = 1.5
#: Growth of the resident set an attack may cause, MB (before issue 29: 200-270 MB in 6 s).
MAX_RSS_GROWTH_MB = 60.0


def rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS")) / 1024


@contextlib.asynccontextmanager
async def rss_growth() -> AsyncIterator[list[float]]:
    """Sample the resident set while the block runs; the list gets the peak growth (MB)."""
    quiet = rss_mb()
    peak = [quiet]
    done = asyncio.Event()

    async def sample() -> None:
        while not done.is_set():
            peak[0] = max(peak[0], rss_mb())
            await asyncio.sleep(0.05)

    out: list[float] = []
    task = asyncio.create_task(sample())
    try:
        yield out
    finally:
        done.set()
        await task
        out.append(max(peak[0], rss_mb()) - quiet)


async def _open(port: int, source: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))


def _status(data: bytes) -> str:
    return data[9:12].decode("latin-1") if data.startswith(b"HTTP/1.1 ") else "none"


async def endless(port: int, head: bytes, until: float, told: Counter[str]) -> None:
    """Send ``head``, then ``a`` without end; when answered, note the status and start again."""
    filler = b"a" * 65536
    while time.monotonic() < until:
        reader, writer = await _open(port, "127.0.0.2")
        writer.write(head)
        answer = asyncio.ensure_future(reader.read(100))
        with contextlib.suppress(OSError):
            while time.monotonic() < until and not answer.done():
                writer.write(filler)
                await writer.drain()
                await asyncio.sleep(0)  # a client on a machine of its own
        if answer.done() or time.monotonic() < until:
            with contextlib.suppress(OSError, TimeoutError):
                told[_status(await asyncio.wait_for(answer, 2.0))] += 1
        answer.cancel()
        writer.close()


async def test_endless_request_lines_and_headers_are_refused_while_the_loop_keeps_20_hz(
    make_app: AppFactory,
) -> None:
    """Two endless URLs and two endless header values: 414 and 431, each closed; 20 Hz held."""
    app = await classroom(make_app)
    port = app.http_port or 0
    told: Counter[str] = Counter()
    async with odom_watch(app, "/r1/odom", "ta-token") as watch, rss_growth() as growth:
        start = watch.stamps[-1]
        until = time.monotonic() + ATTACK
        url, header = b"GET /", b"GET / HTTP/1.1\r\nHost: x\r\nX-Endless: "
        await asyncio.gather(
            *(endless(port, url, until, told) for _ in range(2)),
            *(endless(port, header, until, told) for _ in range(2)),
        )
        await watch.steady_since(start, ATTACK)
    assert told["414"] >= 2 and told["431"] >= 2, told
    assert set(told) <= {"414", "431"}, told
    assert growth[0] < MAX_RSS_GROWTH_MB, f"RSS grew {growth[0]:.0f} MB"


async def pipeline(port: int, batch: bytes, until: float) -> int:
    """Keep a batch of pipelined requests ahead of the answers until ``until``; count those."""
    reader, writer = await _open(port, "127.0.0.3")
    per_batch = batch.count(b" HTTP/1.1\r\n")
    sent = answered = 0

    async def read() -> None:
        nonlocal answered
        tail = b""
        while data := await reader.read(1 << 20):
            both = tail + data
            answered += both.count(b"HTTP/1.1 ")
            tail = both[-8:]

    reading = asyncio.create_task(read())
    try:
        while time.monotonic() < until:
            writer.write(batch)
            sent += per_batch
            await writer.drain()
            while answered < sent - per_batch and time.monotonic() < until:
                await asyncio.sleep(0.005)
    finally:
        writer.close()
        reading.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await reading
    return answered


async def test_pipelined_requests_are_answered_while_the_loop_keeps_20_hz(
    make_app: AppFactory,
) -> None:
    """1,500 ``GET /healthz`` per write on one connection and 1,500 404s on another."""
    app = await classroom(make_app)
    port = app.http_port or 0
    healthz = b"GET /healthz HTTP/1.1\r\n\r\n" * 1500
    missing = b"".join(b"GET /x%d HTTP/1.1\r\n\r\n" % n for n in range(1500))
    async with odom_watch(app, "/r1/odom", "ta-token") as watch, rss_growth() as growth:
        start = watch.stamps[-1]
        until = time.monotonic() + ATTACK
        answered = await asyncio.gather(
            pipeline(port, healthz, until), pipeline(port, missing, until)
        )
        await watch.steady_since(start, ATTACK)
    assert min(answered) >= 300, answered  # served, at the address's share of the loop
    assert growth[0] < MAX_RSS_GROWTH_MB, f"RSS grew {growth[0]:.0f} MB"


async def probe(port: int, path: str, headers: str = "") -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(
            f"GET {path} HTTP/1.1\r\nHost: x\r\n{headers}Connection: close\r\n\r\n".encode()
        )
        return await asyncio.wait_for(reader.read(), 5 * TIMEOUT_FACTOR)
    finally:
        writer.close()


async def test_a_pool_held_mid_request_leaves_room_for_the_page_and_the_instructor(
    make_app: AppFactory,
) -> None:
    """256 connections from 32 addresses never finish a request: the console gets in at once.

    The page gets in as soon as the oldest of them are over a second old.
    """
    app = await classroom(make_app)
    port = app.http_port or 0
    told: Counter[str] = Counter()
    stop = asyncio.Event()

    async def hold(source: str) -> None:
        while not stop.is_set():
            reader, writer = await _open(port, source)
            try:
                writer.write(b"GET / HTTP/1.1\r\nHost: x\r\nX-Never")
                with contextlib.suppress(OSError):
                    data = await reader.read(100)  # until the server closes it
                    told[_status(data)] += 1
            finally:
                writer.close()
            await asyncio.sleep(0.05)

    async with odom_watch(app, "/r1/odom", "ta-token") as watch, rss_growth() as growth:
        start = watch.stamps[-1]
        sources = [f"127.0.0.{10 + n}" for n in range(32)]
        holders = [asyncio.create_task(hold(s)) for s in sources for _ in range(8)]
        members = app.http_pool.members
        await wait_for(  # the pool is full of unfinished requests, younger than a second
            lambda: len(members) == 256 and all(s.phase == "request" for s in members), timeout=5
        )
        admin = f"Authorization: Bearer {ADMIN}\r\n"
        state = [await probe(port, "/api/admin/state", admin) for _ in range(3)]
        # the page once the oldest unfinished requests are over a second old
        first, deadline = b"", time.monotonic() + 3 * TIMEOUT_FACTOR
        while _status(first) != "200" and time.monotonic() < deadline:
            first = await probe(port, "/")
        page = [first, *[await probe(port, "/") for _ in range(2)]]
        stop.set()
        for task in holders:
            task.cancel()
        await asyncio.gather(*holders, return_exceptions=True)
        await watch.steady_since(start, ATTACK)
    assert [_status(r) for r in page] == ["200"] * 3, page[0][:200]
    assert [_status(r) for r in state] == ["200"] * 3, state[0][:200]
    assert json.loads(state[0].split(b"\r\n\r\n", 1)[1])["clients"]
    assert told["408"] >= 1, told  # an unfinished request gave way to the console, told why
    assert app.health()["http"]["evicted"] >= 1
    assert growth[0] < MAX_RSS_GROWTH_MB, f"RSS grew {growth[0]:.0f} MB"


async def test_admin_state_of_a_crowded_class_keeps_the_loop_at_20_hz(
    make_app: AppFactory,
) -> None:
    """120 clients with 120 idle subscriptions each; the console polls /api/admin/state."""
    tokens = {f"student-{n:03d}-token": "r1" for n in range(120)} | {"ta-token": "*"}
    world = load_world(resource_dir("config") / "worlds" / "classroom.yaml")
    app = await make_app(world=world, client_tokens=tokens, admin_token=ADMIN)
    clients: list[Any] = []
    for token in list(tokens)[:120]:
        ws = await connect(f"{ws_url(app)}/?token={token}")
        clients.append(ws)
        for first in (0, 60):  # 60 ops a frame (a student's frame holds at most 100 values)
            subs = ({"op": "subscribe", "topic": f"/idle_{k}"} for k in range(first, first + 60))
            await ws.send("".join(json.dumps(s) for s in subs))
    topics = app.graph.topics.topics
    await wait_for(
        lambda: sum(len(sink) for t in topics.values() for sink in t.sinks.values()) >= 120 * 120,
        timeout=10,
    )
    admin = f"Authorization: Bearer {ADMIN}\r\n"
    async with odom_watch(app, "/r1/odom", "ta-token") as watch:
        start = watch.stamps[-1]
        took = []
        for _ in range(3):
            begun = time.monotonic()
            reply = await probe(app.http_port or 0, "/api/admin/state", admin)
            took.append(time.monotonic() - begun)
            assert _status(reply) == "200"
            await asyncio.sleep(0.3)
        await watch.steady_since(start, 1.0)
    state = json.loads(reply.split(b"\r\n\r\n", 1)[1])
    listed = [c for c in state["clients"] if c["name"].endswith("(r1's token)")]
    assert len(listed) == 120
    assert all(c["subscriptions"] == sorted(f"/idle_{k}" for k in range(120)) for c in listed)
    assert state["robots"]["r1"]["clients"] == [c["name"] for c in listed]
    assert state["robots"]["r2"]["clients"] == []  # the observer's token drives any robot
    assert max(took) < 0.25 * TIMEOUT_FACTOR, took
    for ws in clients:
        await ws.close()
