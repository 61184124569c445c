"""HTTP for simbridge: the page (``static/``), ``/healthz`` and routes added by extensions.

The same :class:`WebApp` answers on the HTTP port (a small HTTP/1.1 server with keep-alive,
:func:`serve_http`) and for plain HTTP requests on the WebSocket port (websockets'
``process_request``), so ``http://host:9090/`` shows the page too.

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
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from ssl import SSLContext
from typing import Any
from urllib.parse import parse_qs, unquote, urlsplit

import orjson


__all__ = ["HttpRequest", "HttpResponse", "Route", "WebApp", "serve_http"]

logger = logging.getLogger(__name__)

_REASONS = {
    200: "OK",
    204: "No Content",
    304: "Not Modified",
    400: "Bad Request",
    401: "Unauthorized",
    403: "Forbidden",
    404: "Not Found",
    405: "Method Not Allowed",
    413: "Payload Too Large",
    500: "Internal Server Error",
}
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
        #: Extra headers on every response (e.g. a Content-Security-Policy).
        self.extra_headers: dict[str, str] = {}

    def handle(self, request: HttpRequest) -> HttpResponse:
        """Answer one request."""
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
        for key, value in self.extra_headers.items():
            response.headers.setdefault(key, value)
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


def _encode(response: HttpResponse, head_only: bool, keep_alive: bool) -> bytes:
    reason = _REASONS.get(response.status, "OK")
    lines = [f"HTTP/1.1 {response.status} {reason}"]
    headers = dict(response.headers)
    headers["Content-Length"] = str(len(response.body))
    headers["Connection"] = "keep-alive" if keep_alive else "close"
    headers.setdefault("Server", "simbridge")
    lines.extend(f"{k}: {v}" for k, v in headers.items())
    head = ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")
    return head if head_only else head + response.body


async def _serve_connection(
    app: WebApp, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
) -> None:
    try:
        while True:
            try:
                head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), timeout=30)
            except (asyncio.IncompleteReadError, TimeoutError):
                return
            except asyncio.LimitOverrunError:
                writer.write(_encode(HttpResponse.text("header too large\n", 400), False, False))
                return
            lines = head.decode("latin-1").split("\r\n")
            parts = lines[0].split(" ")
            if len(parts) != 3 or not parts[2].startswith("HTTP/1."):
                writer.write(_encode(HttpResponse.text("bad request\n", 400), False, False))
                return
            method, target, version = parts
            headers: dict[str, str] = {}
            for line in lines[1:]:
                if ":" in line:
                    key, _, value = line.partition(":")
                    headers[key.strip().lower()] = value.strip()
            length = int(headers.get("content-length", "0") or 0)
            if length > _MAX_BODY:
                writer.write(_encode(HttpResponse.text("body too large\n", 413), False, False))
                return
            body = await reader.readexactly(length) if length > 0 else b""
            path, query = parse_target(target)
            response = app.handle(HttpRequest(method, path, query, headers, body))
            conn = headers.get("connection", "").lower()
            keep = conn != "close" and (version == "HTTP/1.1" or conn == "keep-alive")
            writer.write(_encode(response, method == "HEAD", keep))
            await writer.drain()
            if not keep:
                return
    except (ConnectionError, ValueError, asyncio.IncompleteReadError):
        return
    finally:
        with contextlib.suppress(Exception):
            writer.close()


async def serve_http(
    app: WebApp, host: str, port: int, *, ssl: SSLContext | None = None
) -> asyncio.Server:
    """Start the HTTP server (HTTPS with ``ssl``); return it (``sockets`` tells the port)."""

    async def handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # a page's idle keep-alive connection is cancelled at shutdown (SIGTERM): end quietly
        # (asyncio's stream callback would log the cancellation as an error with a traceback)
        with contextlib.suppress(asyncio.CancelledError):
            await _serve_connection(app, reader, writer)

    return await asyncio.start_server(handler, host, port, limit=_MAX_HEAD, ssl=ssl)
