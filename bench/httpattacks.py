"""HTTP attacks of issue 29 (items 2, 3, 7 and 11), rows of ``python -m bench hostile``.

Each attack is ``run(port, ws_port, admin, until) -> str``: it attacks the HTTP port ``port``
(``ws_port``: the rosbridge port, for attacks that need clients) until ``time.monotonic()``
reaches ``until`` and returns what the server answered, in a few words. ``admin`` is the admin
token. The attackers connect from loopback addresses of their own (``127.0.0.2`` and up; Linux
routes all of ``127.0.0.0/8`` to the loopback device), so that the server tells them from the
probes of the page and of the instructor (``127.0.0.1``), as it would tell machines apart.

- ``http_url``: 4 connections each sending an endless ``GET /aaaa...`` (reconnecting when closed);
- ``http_header``: 4 connections each sending an endless header value;
- ``http_pipeline``: 1,500 pipelined ``GET /healthz`` per write, as fast as they are answered;
- ``http_pipeline_404``: the same with 404 paths;
- ``http_pool``: 256 connections from 32 addresses kept mid-request (a header byte every 0.5 s),
  while the page (``/``) and the instructor's ``/api/admin/state`` are probed twice a second;
- ``admin_state``: 150 WebSocket clients with 130 idle subscriptions each, while the instructor's
  page polls ``/api/admin/state`` every 2 s (each GET's time is reported).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import time
from collections import Counter
from collections.abc import Callable

from websockets.asyncio.client import ClientConnection, connect


#: ``(http_port, ws_port, admin_token, until) -> note``
HttpAttack = Callable[[int, int, str, float], str]
HOST = "127.0.0.1"
ATTACKER = "127.0.0.2"


async def _open(
    port: int, source: str = ATTACKER
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection(HOST, port, local_addr=(source, 0))


def _status(data: bytes) -> str:
    line = data.split(b"\r\n", 1)[0].decode("latin-1")
    return line.removeprefix("HTTP/1.1 ")[:3] if line.startswith("HTTP/") else "none"


async def _endless(port: int, head: bytes, until: float, told: Counter[str]) -> None:
    """Send ``head`` then ``a`` without end; when closed, note the answer and start again."""
    filler = b"a" * 65536
    while time.monotonic() < until:
        try:
            reader, writer = await _open(port)
        except OSError:
            told["connect failed"] += 1
            await asyncio.sleep(0.05)
            continue
        writer.write(head)
        answer = asyncio.ensure_future(reader.read(200))
        try:
            while time.monotonic() < until and not answer.done():
                writer.write(filler)
                await writer.drain()
        except OSError:
            pass
        with contextlib.suppress(OSError, TimeoutError):
            told[_status(await asyncio.wait_for(answer, 1.0))] += 1
        answer.cancel()
        writer.close()


def _note(told: Counter[str]) -> str:
    return ", ".join(f"{status}: {n}" for status, n in told.most_common()) or "nothing"


def http_url(port: int, ws_port: int, admin: str, until: float) -> str:
    """Four endless request lines."""

    async def go() -> str:
        told: Counter[str] = Counter()
        head = b"GET /"
        await asyncio.gather(*(_endless(port, head, until, told) for _ in range(4)))
        return f"answers to 4 endless URLs: {_note(told)}"

    return asyncio.run(go())


def http_header(port: int, ws_port: int, admin: str, until: float) -> str:
    """Four endless header values."""

    async def go() -> str:
        told: Counter[str] = Counter()
        head = b"GET / HTTP/1.1\r\nHost: x\r\nX-Endless: "
        await asyncio.gather(*(_endless(port, head, until, told) for _ in range(4)))
        return f"answers to 4 endless headers: {_note(told)}"

    return asyncio.run(go())


async def _pipeline(port: int, batch: bytes, until: float) -> tuple[int, int]:
    """Write ``batch`` whenever the last one is answered; return (requests sent, answered)."""
    reader, writer = await _open(port)
    sent = answered = 0
    per_batch = batch.count(b"HTTP/1.1\r\n")

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
    except OSError:
        pass
    finally:
        writer.close()
        reading.cancel()
        with contextlib.suppress(asyncio.CancelledError, OSError):
            await reading
    return sent, answered


def http_pipeline(port: int, ws_port: int, admin: str, until: float) -> str:
    """1,500 pipelined GET /healthz per write."""
    batch = b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n" * 1500
    sent, answered = asyncio.run(_pipeline(port, batch, until))
    return f"{sent} pipelined /healthz sent, {answered} answered"


def http_pipeline_404(port: int, ws_port: int, admin: str, until: float) -> str:
    """1,500 pipelined requests for missing files per write."""
    batch = b"".join(b"GET /nope-%d HTTP/1.1\r\nHost: x\r\n\r\n" % n for n in range(1500))
    sent, answered = asyncio.run(_pipeline(port, batch, until))
    return f"{sent} pipelined 404s sent, {answered} answered"


async def _probe(port: int, path: str, headers: str = "") -> str:
    try:
        reader, writer = await asyncio.open_connection(HOST, port)
    except OSError:
        return "connect failed"
    try:
        writer.write(
            f"GET {path} HTTP/1.1\r\nHost: x\r\n{headers}Connection: close\r\n\r\n".encode()
        )
        return _status(await asyncio.wait_for(reader.read(), 5.0))
    except (OSError, TimeoutError):
        return "no answer"
    finally:
        writer.close()


def http_pool(port: int, ws_port: int, admin: str, until: float) -> str:
    """256 connections from 32 addresses held mid-request; the page and /admin probed."""

    async def hold(source: str, told: Counter[str]) -> None:
        while time.monotonic() < until:
            try:
                reader, writer = await _open(port, source)
            except OSError:
                told["connect failed"] += 1
                await asyncio.sleep(0.1)
                continue
            try:
                writer.write(b"GET / HTTP/1.1\r\nHost: x\r\n")
                while time.monotonic() < until and not reader.at_eof():
                    writer.write(b"X")  # one byte of a header name, never finished
                    await writer.drain()
                    with contextlib.suppress(TimeoutError):
                        data = await asyncio.wait_for(reader.read(200), 0.5)
                        told[_status(data)] += 1
                        break
            except OSError:
                told["reset"] += 1
            writer.close()

    async def go() -> str:
        held: Counter[str] = Counter()
        page: Counter[str] = Counter()
        console: Counter[str] = Counter()
        sources = [f"127.0.0.{10 + n}" for n in range(32)]
        tasks = [asyncio.create_task(hold(s, held)) for s in sources for _ in range(8)]
        await asyncio.sleep(1.0)  # the pool fills
        while time.monotonic() < until:
            page[await _probe(port, "/")] += 1
            console[
                await _probe(port, "/api/admin/state", f"Authorization: Bearer {admin}\r\n")
            ] += 1
            await asyncio.sleep(0.5)
        await asyncio.gather(*tasks)
        return (
            f"page: {_note(page)}; /api/admin/state: {_note(console)}; attackers got {_note(held)}"
        )

    return asyncio.run(go())


#: The tokens the admin_state clients spread over (the bench's students and its TA).
CLIENT_TOKENS = [*(f"student-r{n}" for n in range(1, 9)), "bench-ta"]


def admin_state(port: int, ws_port: int, admin: str, until: float) -> str:
    """150 clients with 130 idle subscriptions each; /api/admin/state polled every 2 s."""

    async def client(n: int) -> ClientConnection | None:
        token = CLIENT_TOKENS[n % len(CLIENT_TOKENS)]
        try:
            ws = await connect(f"ws://{HOST}:{ws_port}/?token={token}", open_timeout=20)
        except Exception:  # refused (a cap): counted by its absence
            return None
        for first in (0, 65):  # a student's frame holds 100 ops at most
            subs = ({"op": "subscribe", "topic": f"/idle_{k}"} for k in range(first, first + 65))
            await ws.send("".join(json.dumps(s) for s in subs))
        return ws

    async def watch(stamps: list[float]) -> None:
        """/r1/odom's header stamps while the console polls (the table's window has the setup)."""
        async with connect(f"ws://{HOST}:{ws_port}/?token=bench-ta", max_size=None) as ws:
            await ws.send(json.dumps({"op": "subscribe", "topic": "/r1/odom"}))
            async for data in ws:
                stamp = json.loads(data).get("msg", {}).get("header", {}).get("stamp")
                if stamp:
                    stamps.append(stamp["sec"] + stamp["nanosec"] * 1e-9)

    async def go() -> str:
        clients = [c for c in await asyncio.gather(*(client(n) for n in range(150))) if c]
        await asyncio.sleep(1.0)  # the subscriptions are made
        stamps: list[float] = []
        watching = asyncio.create_task(watch(stamps))
        await asyncio.sleep(0.5)
        polling = time.time()
        times: list[float] = []
        statuses: Counter[str] = Counter()
        size = 0
        while time.monotonic() < until:
            start = time.monotonic()
            reader, writer = await asyncio.open_connection(HOST, port)
            writer.write(
                f"GET /api/admin/state HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {admin}\r\n"
                "Connection: close\r\n\r\n".encode()
            )
            data = await reader.read()
            writer.close()
            times.append(time.monotonic() - start)
            statuses[_status(data)] += 1
            size = len(data)
            await asyncio.sleep(max(0.0, start + 2.0 - time.monotonic()))
        watching.cancel()
        polled = [t for t in stamps if t >= polling]
        gap = max((b - a for a, b in itertools.pairwise(polled)), default=float("nan"))
        for ws in clients:
            await ws.close()
        shown = ", ".join(f"{t * 1e3:.0f}" for t in times)
        return (
            f"{len(clients)} clients x 130 subscriptions; state GETs {_note(statuses)}, "
            f"{size // 1000} kB, ms: {shown}; worst /r1/odom gap while polling {gap * 1e3:.0f} ms"
        )

    return asyncio.run(go())


#: name -> (row of issue 29, attack)
ATTACKS: dict[str, tuple[str, HttpAttack]] = {
    "http_url": ("29.2", http_url),
    "http_header": ("29.2", http_header),
    "http_pipeline": ("29.3", http_pipeline),
    "http_pipeline_404": ("29.3", http_pipeline_404),
    "http_pool": ("29.11", http_pool),
    "admin_state": ("29.7", admin_state),
}
