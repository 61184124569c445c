"""The HTTP/1.1 server simbridge had before h11 (simbridge/web.py at 65d96de).

Kept only as the baseline of ``python -m bench http``: the same :class:`WebApp` answers, parsed
and framed by hand (no body timeout, no connection budget; a NUL in the path reached the disk).
"""

from __future__ import annotations

import asyncio
import contextlib
from ssl import SSLContext

from simbridge.web.http import HttpRequest, HttpResponse, WebApp, parse_target


__all__ = ["serve_http"]

_MAX_HEAD = 16_384
_MAX_BODY = 1_000_000
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
        await _serve_connection(app, reader, writer)

    return await asyncio.start_server(handler, host, port, limit=_MAX_HEAD, ssl=ssl)
