from __future__ import annotations

import asyncio
import json
import socket
import urllib.error
import urllib.request
from typing import Any

import pytest

from simbridge.runner import App
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
