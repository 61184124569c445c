from __future__ import annotations

import asyncio
import json
import socket
import time
import urllib.error
import urllib.request
from collections.abc import AsyncIterator
from typing import Any

import pytest
from websockets.datastructures import Headers
from websockets.http11 import Request

from simbridge.app.config import resource_dir
from simbridge.app.runner import App
from simbridge.web import HttpRequest, HttpResponse, WebApp, serve_http
from tests.helpers import http_url


def get(
    url: str, headers: dict[str, str] | None = None, method: str = "GET"
) -> tuple[int, dict[str, str], bytes]:
    request = urllib.request.Request(url, headers=headers or {}, method=method)
    try:
        with urllib.request.urlopen(request, timeout=5) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as err:
        return err.code, dict(err.headers), err.read()


async def fetch(*args: Any, **kwargs: Any) -> tuple[int, dict[str, str], bytes]:
    return await asyncio.to_thread(get, *args, **kwargs)


async def test_root_serves_the_page(app: App) -> None:
    """GET / returns static/index.html as HTML."""
    status, headers, body = await fetch(http_url(app) + "/")
    assert status == 200
    assert headers["Content-Type"].startswith("text/html")
    assert b"<html" in body


async def test_healthz_reports_status_uptime_clients_and_loop_timing(app: App) -> None:
    """/healthz: JSON with status, uptime, client count and loop statistics."""
    status, headers, body = await fetch(http_url(app) + "/healthz")
    health = json.loads(body)
    assert status == 200 and headers["Content-Type"] == "application/json"
    assert health["status"] == "ok"
    assert health["uptime_s"] >= 0
    assert health["clients"] == 0
    assert {"ticks", "lateness_ms_p99", "work_ms_p99"} <= set(health["loop"])
    assert health["http"]["open"] >= 1 and health["http"]["refused"] == 0  # this request's


async def test_api_rosbridge_names_the_bound_websocket_port_on_both_ports(app: App) -> None:
    """/api/rosbridge: the port the page's rosbridge is on (the bound one: a free port here)."""
    for base in (http_url(app), f"http://127.0.0.1:{app.ws_port}"):
        status, headers, body = await fetch(base + "/api/rosbridge")
        assert status == 200 and headers["Content-Type"] == "application/json"
        assert json.loads(body) == {"server": "simbridge", "port": app.ws_port, "tls": False}
    status, headers, _ = await fetch(http_url(app) + "/api/rosbridge", method="POST")
    assert status == 405 and "GET" in headers["Allow"]


@pytest.mark.parametrize(
    "path", ["/../pyproject.toml", "/%2e%2e/pyproject.toml", "/..%2fpyproject.toml", "/nope.js"]
)
async def test_paths_outside_static_are_not_found(app: App, path: str) -> None:
    """Traversal attempts and missing files give 404."""
    status, _, _ = await fetch(http_url(app) + path)
    assert status == 404


async def test_etag_revalidation_and_head(app: App) -> None:
    """A matching If-None-Match gets 304; HEAD has headers but no body."""
    _, headers, _ = await fetch(http_url(app) + "/index.html")
    status, _, body = await fetch(http_url(app) + "/index.html", {"If-None-Match": headers["ETag"]})
    assert (status, body) == (304, b"")
    status, head_headers, body = await fetch(http_url(app) + "/", method="HEAD")
    assert status == 200 and body == b"" and int(head_headers["Content-Length"]) > 0


async def test_post_to_a_static_path_is_not_allowed(app: App) -> None:
    """Static files are read-only."""
    status, headers, _ = await fetch(http_url(app) + "/index.html", method="POST")
    assert status == 405 and "GET" in headers["Allow"]


async def test_keep_alive_serves_two_requests_on_one_connection(app: App) -> None:
    """HTTP/1.1 keep-alive: two requests, one TCP connection."""

    def two_requests() -> bytes:
        with socket.create_connection(("127.0.0.1", app.http_port or 0), timeout=5) as s:
            req = b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"
            s.sendall(req + req.replace(b"\r\n\r\n", b"\r\nConnection: close\r\n\r\n"))
            data = b""
            while chunk := s.recv(65536):
                data += chunk
            return data

    data = await asyncio.to_thread(two_requests)
    assert data.count(b"HTTP/1.1 200 OK") == 2


async def test_garbage_request_gets_400(app: App) -> None:
    """A request line that is not HTTP is answered 400 and closed."""

    def garbage() -> bytes:
        with socket.create_connection(("127.0.0.1", app.http_port or 0), timeout=5) as s:
            s.sendall(b"HELLO\r\n\r\n")
            return s.recv(1024)

    assert (await asyncio.to_thread(garbage)).startswith(b"HTTP/1.1 400")


# -- bounds (issue 17): what one HTTP client can make the server hold -------------------------


@pytest.fixture
async def small_server() -> AsyncIterator[tuple[int, WebApp]]:
    """A real HTTP server of the page: 2 connections at most, bodies due within 0.3 s."""
    web = WebApp(resource_dir("static"), lambda: {"status": "ok"})
    web.routes["/echo"] = lambda r: HttpResponse(200, r.body)
    server = await serve_http(web, "127.0.0.1", 0, max_connections=2, body_timeout=0.3)
    yield server.sockets[0].getsockname()[1], web
    server.close()
    await server.wait_closed()


CLOSE_HEALTHZ = b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
LENGTH_2 = b"Content-Length: 2\r\n\r\nhi"


async def exchange(port: int, data: bytes, timeout: float = 5.0) -> bytes:
    """Send ``data`` on a new connection; return all it gets until the server closes."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(data)
    try:
        return await asyncio.wait_for(reader.read(), timeout)
    finally:
        writer.close()


async def head_sent(port: int, body_length: int) -> tuple[asyncio.StreamReader, Any]:
    """Open a connection and send a POST head whose body does not follow (yet)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(
        f"POST /echo HTTP/1.1\r\nHost: x\r\nContent-Length: {body_length}\r\n\r\n".encode()
    )
    await writer.drain()
    return reader, writer


async def test_a_body_that_never_arrives_times_out_with_408(
    small_server: tuple[int, WebApp],
) -> None:
    """Head says 100 bytes, 10 come: 408 after the body timeout, connection closed."""
    port, _ = small_server
    start = time.monotonic()
    head = b"POST /echo HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n0123456789"
    reply = await exchange(port, head)
    assert reply.startswith(b"HTTP/1.1 408 Request Timeout\r\n"), reply
    assert b"request body not received within 0.3 s" in reply
    assert 0.25 < time.monotonic() - start < 3.0
    ok = await exchange(port, b"POST /echo HTTP/1.1\r\nHost: x\r\nConnection: close\r\n" + LENGTH_2)
    assert ok.startswith(b"HTTP/1.1 200 OK\r\n") and ok.endswith(b"\r\n\r\nhi")


async def test_at_the_budget_a_request_queues_and_is_served_when_a_place_frees(
    small_server: tuple[int, WebApp],
) -> None:
    """Two requests waiting for their bodies fill the budget: a third waits for a place.

    It is served, unrefused, the moment one frees (their bodies never come: 408 after 0.3 s).
    """
    port, _ = small_server
    busy = [await head_sent(port, 5), await head_sent(port, 5)]
    start = time.monotonic()
    reply = await exchange(port, CLOSE_HEALTHZ)
    assert reply.startswith(b"HTTP/1.1 200 OK"), reply
    assert time.monotonic() - start > 0.1  # it waited for a place
    for reader, writer in busy:
        assert (await asyncio.wait_for(reader.read(), 5)).startswith(b"HTTP/1.1 408")
        writer.close()


async def test_an_idle_keep_alive_connection_makes_room_for_a_new_one(
    small_server: tuple[int, WebApp],
) -> None:
    """At the budget with idle keep-alive connections, a newcomer is served, not refused."""
    port, _ = small_server
    idle = []
    for _ in range(2):
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        await reader.readuntil(b'{"status":"ok"}')
        idle.append((reader, writer))
    ok = await exchange(port, b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
    assert ok.startswith(b"HTTP/1.1 200 OK")
    closed = await asyncio.wait_for(idle[0][0].read(), 5)  # the longest idle one: closed
    assert closed == b""
    for _, writer in idle:
        writer.close()


@pytest.mark.parametrize(
    "request_bytes",
    [
        b"GET /%00 HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
        b"GET /index.html%00.js HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
        b"GET /%0a HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
        b"GET /\x00 HTTP/1.1\r\nHost: x\r\n\r\n",
        b"GET / HTTP/1.1\r\nHost: x\r\nX-Bad: a\x00b\r\n\r\n",
        b"GET / HTTP/1.1\r\nHost: x\r\nno colon here\r\n\r\n",
        b"GET / HTTP/1.1\r\nHost: x\r\nContent-Length: -1\r\n\r\n",
        b"GET / HTTP/9.9\r\n\r\n",
    ],
)
async def test_nul_or_malformed_header_or_path_gets_400_never_500(
    small_server: tuple[int, WebApp], request_bytes: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    port, _ = small_server
    reply = await exchange(port, request_bytes)
    assert reply.startswith(b"HTTP/1.1 400 Bad Request\r\n"), reply
    assert b"bad request" in reply
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"


async def test_nul_path_on_the_websocket_port_gets_400_too(
    app: App, caplog: pytest.LogCaptureFixture
) -> None:
    """The page is also served on the WebSocket port: /%00 is a 400 there as well."""
    reply = await exchange(
        app.ws_port, b"GET /%00 HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )
    assert reply.startswith(b"HTTP/1.1 400"), reply
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"
    status, _, _ = await fetch(http_url(app) + "/%00")
    assert status == 400


def test_the_websocket_port_answers_what_the_page_answers_and_closes() -> None:
    """The handler the rosbridge server is given: the page's answer, then the connection ends.

    Same status, body and ETag as :meth:`WebApp.handle`; a matching If-None-Match is a 304.
    """
    web = WebApp(resource_dir("static"), lambda: {"status": "ok"})
    page = web.handle(HttpRequest("GET", "/", {}, {}))
    answer = web.handle_websocket_port(Request("/?x=1", Headers({"Host": "x"})))
    assert (answer.status_code, answer.reason_phrase, answer.body) == (200, "OK", page.body)
    assert answer.headers["ETag"] == page.headers["ETag"]
    assert answer.headers["Connection"] == "close" and answer.headers["Server"] == "simbridge"
    assert answer.headers["Content-Length"] == str(len(page.body))
    again = Request("/", Headers({"If-None-Match": page.headers["ETag"]}))
    assert web.handle_websocket_port(again).status_code == 304
    missing = web.handle_websocket_port(Request("/nothing-here", Headers()))
    assert (missing.status_code, missing.body) == (404, b"not found\n")


# -- issue 29: heads bounded, pipelines yield, the pool has room for the instructor ----------


async def _open(port: int, source: str = "127.0.0.1") -> tuple[asyncio.StreamReader, Any]:
    """A connection from loopback address ``source`` (Linux routes all of 127/8 to lo)."""
    return await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))


async def ask(port: int, data: bytes, source: str = "127.0.0.1") -> bytes:
    """Send ``data`` from ``source``; return all it gets until the server closes."""
    reader, writer = await _open(port, source)
    writer.write(data)
    try:
        return await asyncio.wait_for(reader.read(), 5.0)
    finally:
        writer.close()


@pytest.mark.parametrize(
    ("request_bytes", "status", "text"),
    [
        (b"GET /" + b"a" * 200_000, b"414 ", b"request target too long (limit 8192 bytes)"),
        (
            b"GET / HTTP/1.1\r\nHost: x\r\nX-Endless: " + b"a" * 200_000,
            b"431 Request Header Fields Too Large\r\n",
            b"request head too large (limit 16384 bytes)",
        ),
        (
            b"GET / HTTP/1.1\r\n" + b"".join(b"X-%d: v\r\n" % n for n in range(3_000)),
            b"431 Request Header Fields Too Large\r\n",
            b"request head too large",
        ),
    ],
    ids=["endless-url", "endless-header-value", "many-headers"],
)
async def test_an_oversized_request_line_or_head_is_refused_as_it_arrives_and_closed(
    small_server: tuple[int, WebApp], request_bytes: bytes, status: bytes, text: bytes
) -> None:
    """The refusal comes after at most a slice past the limit, not at the end of the bytes."""
    port, _ = small_server
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(request_bytes)  # in one write: most of it is still on its way when refused
    reply = await asyncio.wait_for(reader.read(), 5.0)
    writer.close()
    assert reply.startswith(b"HTTP/1.1 " + status), reply[:200]
    assert text in reply and b"Connection: close" in reply


async def test_a_head_that_never_completes_times_out_with_408() -> None:
    """A request line and one header, then silence: 408 after the head timeout, closed."""
    web = WebApp(resource_dir("static"), lambda: {"status": "ok"})
    server = await serve_http(web, "127.0.0.1", 0, head_timeout=0.3)
    port = server.sockets[0].getsockname()[1]
    try:
        start = time.monotonic()
        reply = await ask(port, b"GET / HTTP/1.1\r\nHost: x\r\n")
        assert reply.startswith(b"HTTP/1.1 408 Request Timeout\r\n"), reply
        assert b"request head not received within 0.3 s" in reply
        assert 0.25 < time.monotonic() - start < 3.0
    finally:
        server.close()
        await server.wait_closed()


async def test_pipelined_requests_are_answered_one_at_a_time_with_the_loop_running_between(
    small_server: tuple[int, WebApp],
) -> None:
    """1,500 requests in one write: another task runs between the answers, not after them all."""
    port, web = small_server
    answered = 0

    def count(request: HttpRequest) -> HttpResponse:
        nonlocal answered
        answered += 1
        return HttpResponse(200, b"ok")

    web.routes["/count"] = count
    seen: set[int] = set()
    done = asyncio.Event()

    async def other_task() -> None:
        while not done.is_set():
            seen.add(answered)
            await asyncio.sleep(0)

    watcher = asyncio.create_task(other_task())
    pipeline = b"GET /count HTTP/1.1\r\nHost: x\r\n\r\n" * 1_499
    reply = await ask(port, pipeline + CLOSE_HEALTHZ.replace(b"/healthz", b"/count"))
    done.set()
    await watcher
    assert reply.count(b"HTTP/1.1 200 OK") == 1_500 and answered == 1_500
    assert len(seen) > 1_000, f"the other task ran only at {len(seen)} points of 1,500 answers"


@pytest.fixture
async def pool_server() -> AsyncIterator[tuple[int, WebApp]]:
    """A real HTTP server with a pool of 4, 2 per address; 'Bearer secret' is the instructor."""
    web = WebApp(resource_dir("static"), lambda: {"status": "ok"})
    web.privileged = lambda headers: headers.get("authorization") == "Bearer secret"
    server = await serve_http(
        web, "127.0.0.1", 0, max_connections=4, max_per_address=2, slow_request=60.0, queue_for=0.5
    )
    yield server.sockets[0].getsockname()[1], web
    server.close()
    await server.wait_closed()


async def held_mid_request(port: int, source: str) -> tuple[asyncio.StreamReader, Any]:
    """A connection from ``source`` that has begun a request and never finishes it."""
    reader, writer = await _open(port, source)
    writer.write(b"GET / HTTP/1.1\r\nHost: x\r\nX-Never: ")
    await writer.drain()
    return reader, writer


ADMIN_HEALTHZ = CLOSE_HEALTHZ.replace(b"Host: x", b"Host: x\r\nAuthorization: Bearer secret")


async def test_one_address_gets_its_share_of_the_pool_and_the_503_names_the_budget(
    pool_server: tuple[int, WebApp],
) -> None:
    port, _ = pool_server
    held = [await held_mid_request(port, "127.0.0.2") for _ in range(2)]
    reply = b""
    for _ in range(50):  # until the server has read both heads (it counts them then)
        reply = await ask(port, CLOSE_HEALTHZ, "127.0.0.2")
        if reply.startswith(b"HTTP/1.1 503"):
            break
        await asyncio.sleep(0.01)
    assert reply.startswith(b"HTTP/1.1 503 Service Unavailable\r\n"), reply
    assert b"(max_http_connections_per_address)" in reply and b"Retry-After: 1" in reply
    assert (await ask(port, CLOSE_HEALTHZ, "127.0.0.3")).startswith(b"HTTP/1.1 200 OK")
    # the instructor behind the same address as the attacker still gets in
    assert (await ask(port, ADMIN_HEALTHZ, "127.0.0.2")).startswith(b"HTTP/1.1 200 OK")
    for _, writer in held:
        writer.close()


async def test_a_full_pool_of_unfinished_requests_still_serves_the_instructor(
    pool_server: tuple[int, WebApp],
) -> None:
    """Four requests that never finish fill the pool: a student gets 503, the instructor 200."""
    port, _ = pool_server
    held = [await held_mid_request(port, f"127.0.0.{2 + n // 2}") for n in range(4)]
    reply = b""
    for _ in range(50):
        reply = await ask(port, CLOSE_HEALTHZ, "127.0.0.9")
        if reply.startswith(b"HTTP/1.1 503"):
            break
        await asyncio.sleep(0.01)
    assert reply.startswith(b"HTTP/1.1 503"), reply
    assert b"(max_http_connections)" in reply
    reply = await ask(port, ADMIN_HEALTHZ, "127.0.0.9")
    assert reply.startswith(b"HTTP/1.1 200 OK"), reply
    # one unfinished request gave way to it, told why; the others are still open
    reads = [asyncio.create_task(reader.read()) for reader, _ in held]
    done, waiting = await asyncio.wait(reads, timeout=5.0, return_when=asyncio.FIRST_COMPLETED)
    assert len(done) == 1 and b"room for the instructor's request" in next(iter(done)).result()
    for task in waiting:
        task.cancel()
    for _, writer in held:
        writer.close()
