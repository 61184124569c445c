"""HTTP for simbridge: the page (``static/``), ``/healthz`` and routes added by extensions.

The same :class:`WebApp` answers on the HTTP port (:func:`serve_http`, HTTP/1.1 with
keep-alive) and for plain HTTP requests on the WebSocket port (websockets' ``process_request``),
so ``http://host:9090/`` shows the page too.

Requests are parsed by httptools (llhttp, Node's parser; sans-I/O: bytes in, callbacks out):
strict (a NUL or a malformed request line or header is a 400 naming the fault), and measured
an order of magnitude cheaper per request than h11 (which would make an HTTP flood cost the
20 Hz loop more than the hand-written parser it replaced did; ``python -m bench http``).

What one client can make the server hold is bounded (``docs/security.md``, "HTTP"): a request
line of at most 8 KB (else 414) and a head of at most 16 KB (else 431), counted as the bytes
arrive, before the parser has buffered more than a slice of them; a head must arrive within
``head_timeout`` of its first byte (10 s, else 408) and its body within ``body_timeout`` (10 s,
else 408), at most 1 MB (else 413). Refusals close the connection. Pipelined requests are parsed a
slice (4 KB) at a time and answered one at a time with a yield to the loop between two, so a
write of 1,500 requests costs the 20 Hz loop no more than 1,500 clients would. Connections are
budgeted in all (``max_http_connections``) and per client address
(``max_http_connections_per_address``), an address's requests take at most a quarter of the
loop's time, and a request with the admin token is never refused for want of room:
:mod:`simbridge.web.pool`. A path holding a control character (``/%00``) is a 400
on both ports before it reaches a route or the disk.

Static files are served read-only from one directory; a request path is resolved to a real path
and must stay inside that directory (starlette's StaticFiles guard), whatever ``..`` or symlinks
it holds.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import mimetypes
import os
import re
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from http import HTTPStatus
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, unquote, urlsplit

import httptools
import orjson
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from simbridge.web.pool import Phase, Pool, Share, Slot, client_address


if TYPE_CHECKING:
    from ssl import SSLContext

__all__ = [
    "BODY_TIMEOUT",
    "HEAD_TIMEOUT",
    "SLOW_REQUEST",
    "HttpRequest",
    "HttpResponse",
    "Route",
    "WebApp",
    "parse_target",
    "rosbridge_route",
    "serve_http",
]

logger = logging.getLogger(__name__)

#: NUL and the other C0 controls (and DEL): never in a file name worth serving.
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")

_TYPES = {
    ".js": "text/javascript; charset=utf-8",
    ".mjs": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".html": "text/html; charset=utf-8",
    ".json": "application/json",
    ".svg": "image/svg+xml",
    ".txt": "text/plain; charset=utf-8",
    ".md": "text/plain; charset=utf-8",
    ".png": "image/png",
    ".ico": "image/x-icon",
    ".webmanifest": "application/manifest+json",
}
#: Longest request target (the URL of the request line), bytes: longer is 414 and close.
_MAX_URL = 8_192
#: Longest request head (request line and header lines), bytes: longer is 431 and close.
_MAX_HEAD = 16_384
_MAX_BODY = 1_000_000
#: Bytes of a read parsed at a time. The requests a slice completes are answered before the
#: next slice is parsed, so the parser holds at most a slice of a head it has not seen the end
#: of, and a read of pipelined requests is answered a few at a time, never all in one go.
_SLICE = 4_096
#: Seconds a keep-alive connection may wait for its next request (or a new one for its first).
_IDLE_TIMEOUT = 30.0
#: Seconds a request's head may take to arrive once its first byte has (then 408 and close).
HEAD_TIMEOUT = 10.0
#: Seconds a request's body may take to arrive once its head has (then 408 and close).
BODY_TIMEOUT = 10.0
#: When the pool is full, a request that has been arriving for longer than this (seconds) gives
#: way to a newcomer (408): a browser sends a request's head in one go.
SLOW_REQUEST = 1.0
#: Seconds a connection in the pool's reserve (no room: it may be the instructor's) has to send
#: its first request's head; then it gets the 503 it was spared.
_RESERVE_TIMEOUT = 2.0
#: Seconds between two looks for a place of a queued request (besides the wake-ups).
_QUEUE_STEP = 0.25
#: Said with a per-address refusal in the log: what an instructor can do about it.
_NAT_HINT = (
    " (a class behind one address, a school's NAT? a browser opens up to 6 connections: raise"
    " --max-http-connections-per-address to 6 per student)"
)
#: Seconds a refused connection is drained before it closes (see ``_Exchange.linger``).
_LINGER = 1.0


@dataclass(slots=True)
class HttpRequest:
    """A parsed HTTP request."""

    method: str
    path: str
    query: dict[str, list[str]]
    headers: dict[str, str]
    body: bytes = b""


@dataclass(slots=True)
class HttpResponse:
    """An HTTP response to send."""

    status: int
    body: bytes = b""
    headers: dict[str, str] = field(default_factory=dict)

    @classmethod
    def json(cls, value: Any, status: int = 200) -> HttpResponse:
        """Return a JSON response."""
        return cls(
            status,
            orjson.dumps(value),
            {"Content-Type": "application/json", "Cache-Control": "no-store"},
        )

    @classmethod
    def text(cls, text: str, status: int) -> HttpResponse:
        """Return a plain-text response."""
        return cls(status, text.encode(), {"Content-Type": "text/plain; charset=utf-8"})


#: A route handler: request -> response.
Route = Callable[[HttpRequest], HttpResponse]


def rosbridge_route(port: Callable[[], int], *, tls: bool) -> Route:
    """``GET /api/rosbridge``: the port this server's rosbridge listens on, for the page it serves.

    The page connects to ``ws://<its own host>:<port>`` (``wss`` when ``tls``), so a server
    started with ``--port 9190`` (9090 taken, by a real robot's rosbridge perhaps) needs no
    ``?url=``. A proxy in front of simbridge answers this path itself with the path it forwards
    to the WebSocket (``{"path": "/ws"}``, ``config/nginx.conf``). ``port()`` is read at each
    request: the bound port, also with ``--port 0``.
    """

    def route(request: HttpRequest) -> HttpResponse:
        if request.method not in ("GET", "HEAD"):
            response = HttpResponse.json({"error": "use GET for /api/rosbridge"}, 405)
            response.headers["Allow"] = "GET, HEAD"
            return response
        return HttpResponse.json({"server": "simbridge", "port": port(), "tls": tls})

    return route


class WebApp:
    """Static files, ``/healthz``, and extension routes."""

    def __init__(self, static_dir: Path, health: Callable[[], dict[str, Any]]) -> None:
        #: Directory the page is served from.
        self.static_dir = static_dir.resolve()
        #: Produces the ``/healthz`` document.
        self.health = health
        #: Exact-path routes, checked before static files.
        self.routes: dict[str, Route] = {"/healthz": self._healthz}
        #: Whether a request's headers (lower-case names) carry the administrator's credentials
        #: (the builder sets :func:`simbridge.web.admin.admin_credentials`): it is never refused
        #: for want of room in the HTTP server's pool.
        self.privileged: Callable[[Mapping[str, str]], bool] = lambda headers: False

    def handle(self, request: HttpRequest) -> HttpResponse:
        """Answer one request (a bad path gets 400: it never reaches a route or the disk)."""
        if _CONTROL.search(unquote(request.path)):
            return HttpResponse.text("bad request: the path holds a control character\n", 400)
        route = self.routes.get(request.path.rstrip("/") or "/")
        try:
            if route is not None:
                response = route(request)
            elif request.method not in ("GET", "HEAD"):
                response = HttpResponse.text("only GET and HEAD are allowed here\n", 405)
                response.headers["Allow"] = "GET, HEAD"
            else:
                response = self._static(request)
        except Exception:
            logger.exception("HTTP %s %s failed", request.method, request.path)
            response = HttpResponse.text("internal error\n", 500)
        return response

    def handle_websocket_port(self, request: Request) -> Response:
        """Answer a plain HTTP request that reached the WebSocket port (websockets parsed it).

        websockets reads only ``GET`` requests there and closes the connection after the
        answer; the answer is the one this port's own server gives (:meth:`handle`).
        """
        path, query = parse_target(request.path)
        headers = {k.lower(): v for k, v in request.headers.raw_items()}
        answer = self.handle(HttpRequest("GET", path, query, headers))
        out = Headers(answer.headers)
        out["Content-Length"] = str(len(answer.body))
        out["Connection"] = "close"
        out["Server"] = "simbridge"
        return Response(answer.status, HTTPStatus(answer.status).phrase, out, answer.body)

    def _healthz(self, request: HttpRequest) -> HttpResponse:
        return HttpResponse.json(self.health())

    def _static(self, request: HttpRequest) -> HttpResponse:
        rel = unquote(request.path).lstrip("/")
        if rel == "" or rel.endswith("/"):
            rel += "index.html"
        if rel == "admin":
            rel = "admin.html"
        full = os.path.realpath(self.static_dir / rel)
        if os.path.commonpath([full, str(self.static_dir)]) != str(self.static_dir):
            return HttpResponse.text("not found\n", 404)
        path = Path(full)
        if not path.is_file():
            return HttpResponse.text("not found\n", 404)
        data = path.read_bytes()
        etag = '"' + hashlib.sha1(data, usedforsecurity=False).hexdigest()[:16] + '"'
        ctype = _TYPES.get(path.suffix) or mimetypes.guess_type(path.name)[0]
        headers = {
            "Content-Type": ctype or "application/octet-stream",
            "Cache-Control": "no-cache",
            "ETag": etag,
            "X-Content-Type-Options": "nosniff",
        }
        if request.headers.get("if-none-match") == etag:
            return HttpResponse(304, b"", headers)
        return HttpResponse(200, data, headers)


def parse_target(target: str) -> tuple[str, dict[str, list[str]]]:
    """Split a request target into its path and query parameters."""
    parts = urlsplit(target)
    return parts.path or "/", parse_qs(parts.query)


def _encode(response: HttpResponse, head_only: bool, keep_alive: bool) -> bytes:
    """Return the bytes of ``response`` (RFC 9112 status line, headers, body)."""
    try:
        reason = HTTPStatus(response.status).phrase
    except ValueError:
        reason = ""
    headers = dict(response.headers)
    headers["Content-Length"] = str(len(response.body))
    headers["Connection"] = "keep-alive" if keep_alive else "close"
    headers.setdefault("Server", "simbridge")
    lines = [f"HTTP/1.1 {response.status} {reason}", *(f"{k}: {v}" for k, v in headers.items())]
    head = ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")
    return head if head_only or response.status in (204, 304) else head + response.body


class _Parsed:
    """httptools' callbacks: the requests of one connection, as they complete."""

    def __init__(self) -> None:
        self.parser = httptools.HttpRequestParser(self)
        #: Complete requests not answered yet, with whether each allows keep-alive.
        self.ready: deque[tuple[HttpRequest, bool]] = deque()
        #: A request has begun and is not complete (its head or body is on its way).
        self.in_message = False
        #: The current request's head is complete and its body is not.
        self.in_body = False
        #: Requests begun, and heads completed, since the connection opened.
        self.begun = 0
        self.heads = 0
        #: The headers of the last complete head (lower-case names).
        self.headers: dict[str, str] = {}
        #: The client waits for ``100 Continue`` before it sends the body.
        self.expects_continue = False
        #: The current request's body is over the limit (413).
        self.too_large = False
        #: Bytes of the current request's target, and of its complete header lines.
        self.url_bytes = 0
        self.head_seen = 0
        #: Bytes of the slices fed wholly inside the current request's head (the parser keeps
        #: an unfinished header line to itself: this is how its length is known).
        self.head_fed = 0
        self._url: list[bytes] = []
        self._headers: dict[str, str] = {}
        self._body: list[bytes] = []
        self._size = 0

    @property
    def in_head(self) -> bool:
        """A request's head has begun and is not complete."""
        return self.in_message and not self.in_body

    def on_message_begin(self) -> None:
        self.in_message = True
        self.begun += 1
        self._url, self._headers, self._body, self._size = [], {}, [], 0
        self.url_bytes = self.head_seen = self.head_fed = 0

    def on_url(self, url: bytes) -> None:
        self.url_bytes += len(url)
        self.head_seen += len(url)
        if self.url_bytes <= _MAX_URL:
            self._url.append(url)

    def on_header(self, name: bytes, value: bytes) -> None:
        self.head_seen += len(name) + len(value) + 4  # ": " and CRLF
        self._headers[name.decode("latin-1").lower()] = value.decode("latin-1")

    def on_headers_complete(self) -> None:
        self.in_body = True
        self.heads += 1
        self.headers = self._headers
        length = self._headers.get("content-length", "0")
        self.too_large = length.isdigit() and int(length) > _MAX_BODY
        self.expects_continue = self._headers.get("expect", "").lower() == "100-continue"

    def on_body(self, body: bytes) -> None:
        self._size += len(body)
        if self._size > _MAX_BODY:
            self.too_large = True
        elif not self.too_large:
            self._body.append(body)

    def on_message_complete(self) -> None:
        self.in_message = self.in_body = False
        path, query = parse_target(b"".join(self._url).decode("latin-1"))
        method = self.parser.get_method().decode("ascii")
        request = HttpRequest(method, path, query, self._headers, b"".join(self._body))
        self.ready.append((request, self.parser.should_keep_alive()))

    def feed(self, piece: bytes | memoryview) -> tuple[int, str] | None:
        """Parse ``piece``; return the refusal ``(status, text)`` when the request is refused.

        Raises:
            httptools.HttpParserError: the bytes are not HTTP (400).
        """
        inside, begun = self.in_head, self.begun
        # no upgrades here: the request is answered, the rest ignored
        with contextlib.suppress(httptools.HttpParserUpgrade):
            self.parser.feed_data(piece)
        if self.url_bytes > _MAX_URL:
            return 414, f"request target too long (limit {_MAX_URL} bytes)\n"
        if self.in_head:
            if inside and self.begun == begun:  # the whole slice was this head's
                self.head_fed += len(piece)
            if max(self.head_seen, self.head_fed) > _MAX_HEAD:
                return 431, f"request head too large (limit {_MAX_HEAD} bytes)\n"
        if self.too_large:
            return 413, f"request body too large (limit {_MAX_BODY} bytes)\n"
        return None


class _Exchange:
    """One HTTP/1.1 connection: httptools (llhttp, sans-I/O) parses, asyncio streams carry."""

    def __init__(
        self,
        app: WebApp,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        head_timeout: float,
        body_timeout: float,
    ) -> None:
        self.app = app
        self.reader = reader
        self.writer = writer
        self.head_timeout = head_timeout
        self.body_timeout = body_timeout
        self.parsed = _Parsed()

    def close(self, status: int, text: str) -> None:
        """Answer ``status`` with ``text`` (unless 0) and close at once (the pool's eviction).

        A connection already refused and lingering (its write side shut) is only closed.
        """
        if status and not self.writer.is_closing():
            with contextlib.suppress(RuntimeError, ConnectionError):  # after write_eof
                self.writer.write(_encode(HttpResponse.text(text, status), False, False))
        self.writer.close()

    async def refuse(self, status: int, text: str, headers: dict[str, str] | None = None) -> None:
        """Answer ``status`` with ``text`` and close (a request that cannot be served)."""
        response = HttpResponse.text(text, status)
        response.headers.update(headers or {})
        self.writer.write(_encode(response, False, False))
        await self.writer.drain()
        await self.linger()

    async def linger(self) -> None:
        """Half-close, then discard what the client still sends (at most 64 KB for 1 s).

        Closing with unread bytes in the socket makes the kernel send a reset, which can reach
        the client before it has read the answer; a lingering close lets it read the refusal.
        """
        if not self.writer.can_write_eof():
            return  # TLS: no half-close; the close_notify does the job
        self.writer.write_eof()
        left = 65536
        with contextlib.suppress(TimeoutError, ConnectionError):
            async with asyncio.timeout(_LINGER):
                while left > 0:
                    chunk = await self.reader.read(left)
                    if not chunk:
                        return
                    left -= len(chunk)

    async def pay(self, share: Share, slot: Slot, spent: float, always_yield: bool = False) -> None:
        """Charge ``spent`` seconds to the address's share; in debt, wait until it is paid.

        The instructor's connection is charged but never waits (a student behind the same
        address must not slow the console down).
        """
        loop = asyncio.get_running_loop()
        wait = share.charge(loop.time(), spent)
        if wait <= 0 or slot.admin:
            if always_yield:
                await asyncio.sleep(0)
            return
        while wait > 0:  # the address's other connections may spend it meanwhile
            await asyncio.sleep(wait)
            wait = share.owed(loop.time())

    async def queue(self, pool: Pool, slot: Slot) -> bool:
        """Wait, unread, for the pool to give a queued request a place; False: none in time.

        Its connection is then out of the pool's books (:meth:`Pool.give_up`), to be refused.
        """
        loop = asyncio.get_running_loop()
        placed = asyncio.Event()
        slot.wake = placed.set
        deadline = loop.time() + pool.queue_for
        try:
            while slot.queued and not slot.evicted:
                step = min(_QUEUE_STEP, deadline - loop.time())
                if step <= 0:
                    pool.give_up(slot)
                    return False
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(step):  # a place freed: woken at once
                        await placed.wait()
                if slot.queued:  # a connection may give way by now (idle or slow long enough)
                    pool.retry(slot, loop.time())
        finally:
            slot.wake = None
        return not slot.evicted

    async def serve(self, pool: Pool, slot: Slot) -> None:
        """Answer requests until the client closes, idles out, or sends what is refused."""
        loop = asyncio.get_running_loop()
        parsed = self.parsed
        now = loop.time()
        idle_until = now + (_RESERVE_TIMEOUT if slot.reserved else _IDLE_TIMEOUT)
        head_until = body_until = 0.0
        pending = memoryview(b"")  # read and not parsed yet (sliced without copies)
        share = pool.share(slot.address, now)
        while not slot.evicted:  # closed to make room (while it waited for its share, too)
            if parsed.ready:
                request, keep_alive = parsed.ready.popleft()
                pool.mark(slot, "busy", now)
                start = loop.time()
                response = self.app.handle(request)
                self.writer.write(_encode(response, request.method == "HEAD", keep_alive))
                spent = loop.time() - start
                await self.writer.drain()
                if not keep_alive:
                    return
                # the next pipelined request waits for the loop's other work (the 20 Hz tick),
                # and for the address's share of the loop's time when it has spent it
                await self.pay(share, slot, spent, always_yield=True)
                now = loop.time()
                idle_until = now + _IDLE_TIMEOUT
                continue
            if not pending:
                phase: Phase = "request" if parsed.in_message else "idle" if parsed.begun else "new"
                pool.mark(slot, phase, now)
                deadline, late = idle_until, ""
                if parsed.in_message:
                    deadline = body_until if parsed.in_body else head_until
                    what = "body" if parsed.in_body else "head"
                    limit = self.body_timeout if parsed.in_body else self.head_timeout
                    late = f"request {what} not received within {limit:g} s\n"
                try:
                    async with asyncio.timeout_at(deadline):
                        pending = memoryview(await self.reader.read(65536))
                except TimeoutError:
                    if late:
                        await self.refuse(408, late)
                    elif slot.reserved:
                        await self.refuse(503, slot.refusal, {"Retry-After": "1"})
                    return
                now = loop.time()
                if slot.evicted or not pending:
                    return  # closed to make room for a new connection, or by the client
            piece, pending = pending[:_SLICE], pending[_SLICE:]
            begun, heads = parsed.begun, parsed.heads
            start = loop.time()
            try:
                refusal = parsed.feed(piece)
            except httptools.HttpParserError as err:
                await self.refuse(400, f"bad request: {err}\n")
                return
            await self.pay(share, slot, loop.time() - start)
            if refusal is not None:
                await self.refuse(*refusal)
                return
            if parsed.begun != begun:
                head_until = now + self.head_timeout
                if slot.reserved:  # it has the reserve's few seconds, not a member's
                    head_until = min(head_until, idle_until)
                pool.mark(slot, "request", now)
            if parsed.heads != heads:
                admin = self.app.privileged(parsed.headers)
                if slot.reserved:
                    refused = pool.claim(slot, admin, now)
                    if refused is not None and await self.queue(pool, slot):
                        refused, now = None, loop.time()  # placed: its deadlines start now
                    if slot.evicted:
                        return
                    if refused is not None:
                        if pool.refused == 1 or pool.refused % 100 == 0:
                            hint = _NAT_HINT if "per_address" in refused else ""
                            logger.warning(
                                "HTTP: %d requests refused so far: %s%s",
                                pool.refused,
                                refused.strip(),
                                hint,
                            )
                        await self.refuse(503, refused, {"Retry-After": "1"})
                        return
                slot.admin = slot.admin or admin
                if parsed.in_body:
                    body_until = now + self.body_timeout
                    if parsed.expects_continue:
                        self.writer.write(b"HTTP/1.1 100 Continue\r\n\r\n")


async def _serve_connection(
    app: WebApp,
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
    pool: Pool,
    head_timeout: float,
    body_timeout: float,
) -> None:
    exchange = _Exchange(app, reader, writer, head_timeout, body_timeout)
    slot = Slot(client_address(writer.get_extra_info("peername")), exchange.close)
    try:
        pool.admit(slot, asyncio.get_running_loop().time())
        await exchange.serve(pool, slot)
    except (ConnectionError, TimeoutError):
        return
    finally:
        pool.leave(slot, asyncio.get_running_loop().time())
        with contextlib.suppress(Exception):
            writer.close()


async def serve_http(
    app: WebApp,
    host: str,
    port: int,
    *,
    ssl: SSLContext | None = None,
    max_connections: int = 256,
    max_per_address: int = 16,
    head_timeout: float = HEAD_TIMEOUT,
    body_timeout: float = BODY_TIMEOUT,
    slow_request: float = SLOW_REQUEST,
    queue_for: float = 5.0,
    pool: Pool | None = None,
) -> asyncio.Server:
    """Start the HTTP server (HTTPS with ``ssl``); return it (``sockets`` tells the port).

    Args:
        app: what answers the requests.
        host: address to listen on.
        port: port (0: a free one).
        ssl: serve HTTPS with this context.
        max_connections: open connections at most; when all are busy a new one queues for a
            place (``queue_for``), then gets 503 naming the budget; an idle keep-alive
            connection (the longest idle) is closed to make room.
        max_per_address: open connections from one client address at most (the same rule).
        head_timeout: seconds a request's head may take to arrive after its first byte (408).
        body_timeout: seconds a request's body may take to arrive after its head (then 408).
        slow_request: when the pool is full, a request arriving for longer than this (seconds)
            is closed (408) to make room for a newcomer.
        queue_for: seconds a request with no place waits for one before its 503.
        pool: the connections' books, made by the caller (who reads them: ``/healthz``);
            then ``max_connections``, ``max_per_address``, ``slow_request`` and ``queue_for``
            are its own.
    """
    if pool is None:
        pool = Pool(max_connections, max_per_address, slow=slow_request, queue_for=queue_for)

    connections = pool  # (narrowed for the closure)

    async def handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # a page's idle keep-alive connection is cancelled at shutdown (SIGTERM): end quietly
        # (asyncio's stream callback would log the cancellation as an error with a traceback)
        with contextlib.suppress(asyncio.CancelledError):
            await _serve_connection(app, reader, writer, connections, head_timeout, body_timeout)

    return await asyncio.start_server(handler, host, port, ssl=ssl)
