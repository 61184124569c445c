"""HTTP for simbridge: the page (``static/``), ``/healthz`` and routes added by extensions.

The same :class:`WebApp` answers on the HTTP port (:func:`serve_http`, HTTP/1.1 with
keep-alive) and for plain HTTP requests on the WebSocket port (websockets' ``process_request``),
so ``http://host:9090/`` shows the page too.

Requests are parsed by httptools (llhttp, Node's parser; sans-I/O: bytes in, callbacks out):
strict (a NUL or a malformed request line or header is a 400 naming the fault), and measured
an order of magnitude cheaper per request than h11 (which would make an HTTP flood cost the
20 Hz loop more than the hand-written parser it replaced did; ``python -m bench http``).

What one client can make the server hold is bounded: a request's body must arrive within
``body_timeout`` (10 s, else 408) and be at most 1 MB (else 413); at most
``max_http_connections`` connections are open (when all are busy, 503 naming the budget;
otherwise the longest-idle keep-alive connection is closed to make room). A path holding a
control character (``/%00``) is a 400 on both ports before it reaches a route or the disk.

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
from collections.abc import Callable
from dataclasses import dataclass, field
from http import HTTPStatus
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, unquote, urlsplit

import httptools
import orjson


if TYPE_CHECKING:
    from ssl import SSLContext

__all__ = [
    "BODY_TIMEOUT",
    "HttpRequest",
    "HttpResponse",
    "Route",
    "WebApp",
    "parse_target",
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
_MAX_HEAD = 16_384
_MAX_BODY = 1_000_000
#: Seconds a keep-alive connection may wait for its next request (or a new one for its first).
_IDLE_TIMEOUT = 30.0
#: Seconds a request's body may take to arrive once its head has (then 408 and close).
BODY_TIMEOUT = 10.0
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


class WebApp:
    """Static files, ``/healthz``, and extension routes."""

    def __init__(self, static_dir: Path, health: Callable[[], dict[str, Any]]) -> None:
        #: Directory the page is served from.
        self.static_dir = static_dir.resolve()
        #: Produces the ``/healthz`` document.
        self.health = health
        #: Exact-path routes, checked before static files.
        self.routes: dict[str, Route] = {"/healthz": self._healthz}

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


class _Connections:
    """The open HTTP connections of one server, and its budget of them."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        #: Each open connection's writer -> whether it waits between requests (keep-alive).
        self.open: dict[asyncio.StreamWriter, bool] = {}
        #: Connections refused with 503 since the start.
        self.refused = 0

    def admit(self, writer: asyncio.StreamWriter) -> bool:
        """Take a slot for ``writer``: a free one, else the longest-idle keep-alive one."""
        if len(self.open) >= self.limit:
            idle = next((w for w, waiting in self.open.items() if waiting), None)
            if idle is None:
                return False
            del self.open[idle]
            idle.close()  # a keep-alive connection between requests: the client reconnects
        self.open[writer] = False
        return True


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
        #: The client waits for ``100 Continue`` before it sends the body.
        self.expects_continue = False
        #: The current request's body is over the limit (413).
        self.too_large = False
        self._url = b""
        self._headers: dict[str, str] = {}
        self._body: list[bytes] = []
        self._size = 0

    def on_message_begin(self) -> None:
        self.in_message = True
        self._url, self._headers, self._body, self._size = b"", {}, [], 0

    def on_url(self, url: bytes) -> None:
        self._url += url

    def on_header(self, name: bytes, value: bytes) -> None:
        self._headers[name.decode("latin-1").lower()] = value.decode("latin-1")

    def on_headers_complete(self) -> None:
        self.in_body = True
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
        path, query = parse_target(self._url.decode("latin-1"))
        method = self.parser.get_method().decode("ascii")
        request = HttpRequest(method, path, query, self._headers, b"".join(self._body))
        self.ready.append((request, self.parser.should_keep_alive()))


class _Exchange:
    """One HTTP/1.1 connection: httptools (llhttp, sans-I/O) parses, asyncio streams carry."""

    def __init__(
        self,
        app: WebApp,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        body_timeout: float,
    ) -> None:
        self.app = app
        self.reader = reader
        self.writer = writer
        self.body_timeout = body_timeout
        self.parsed = _Parsed()

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

    async def serve(self, connections: _Connections) -> None:
        """Answer requests until the client closes, idles out, or sends what is refused."""
        loop = asyncio.get_running_loop()
        parsed = self.parsed
        idle_until = loop.time() + _IDLE_TIMEOUT
        body_until = 0.0
        while True:
            if parsed.ready:
                request, keep_alive = parsed.ready.popleft()
                response = self.app.handle(request)
                self.writer.write(_encode(response, request.method == "HEAD", keep_alive))
                await self.writer.drain()
                if not keep_alive:
                    return
                idle_until = loop.time() + _IDLE_TIMEOUT
                continue
            # between requests a connection is idle: it may be closed to make room
            connections.open[self.writer] = not parsed.in_message
            deadline = body_until if parsed.in_body else idle_until
            try:
                async with asyncio.timeout_at(deadline):
                    data = await self.reader.read(65536)
            except TimeoutError:
                if parsed.in_body:
                    await self.refuse(
                        408, f"request body not received within {self.body_timeout:g} s\n"
                    )
                return
            if self.writer not in connections.open or not data:
                return  # closed to make room for a new connection, or by the client
            was_in_body = parsed.in_body
            try:
                parsed.parser.feed_data(data)
            except httptools.HttpParserUpgrade:
                pass  # no upgrades here: the request is answered, the rest ignored
            except httptools.HttpParserError as err:
                await self.refuse(400, f"bad request: {err}\n")
                return
            if parsed.too_large:
                await self.refuse(413, f"request body too large (limit {_MAX_BODY} bytes)\n")
                return
            if parsed.in_body and not was_in_body:
                body_until = loop.time() + self.body_timeout
                if parsed.expects_continue:
                    self.writer.write(b"HTTP/1.1 100 Continue\r\n\r\n")


async def _serve_connection(
    app: WebApp,
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
    connections: _Connections,
    body_timeout: float,
) -> None:
    exchange = _Exchange(app, reader, writer, body_timeout)
    try:
        if not connections.admit(writer):
            connections.refused += 1
            if connections.refused == 1 or connections.refused % 100 == 0:
                logger.warning(
                    "HTTP: %d connections refused so far (max_http_connections=%d)",
                    connections.refused,
                    connections.limit,
                )
            await exchange.refuse(
                503,
                f"server busy: {connections.limit} HTTP connections are open "
                "(max_http_connections); try again shortly\n",
                {"Retry-After": "1"},
            )
            return
        await exchange.serve(connections)
    except (ConnectionError, TimeoutError):
        return
    finally:
        connections.open.pop(writer, None)
        with contextlib.suppress(Exception):
            writer.close()


async def serve_http(
    app: WebApp,
    host: str,
    port: int,
    *,
    ssl: SSLContext | None = None,
    max_connections: int = 256,
    body_timeout: float = BODY_TIMEOUT,
) -> asyncio.Server:
    """Start the HTTP server (HTTPS with ``ssl``); return it (``sockets`` tells the port).

    Args:
        app: what answers the requests.
        host: address to listen on.
        port: port (0: a free one).
        ssl: serve HTTPS with this context.
        max_connections: open connections at most; when all are busy a new one gets 503 naming
            the budget, else the longest-idle keep-alive connection is closed to make room.
        body_timeout: seconds a request's body may take to arrive after its head (then 408).
    """
    connections = _Connections(max_connections)

    async def handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # a page's idle keep-alive connection is cancelled at shutdown (SIGTERM): end quietly
        # (asyncio's stream callback would log the cancellation as an error with a traceback)
        with contextlib.suppress(asyncio.CancelledError):
            await _serve_connection(app, reader, writer, connections, body_timeout)

    return await asyncio.start_server(handler, host, port, ssl=ssl)
