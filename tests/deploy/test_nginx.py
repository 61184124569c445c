"""config/nginx.conf with the real Debian nginx, in front of a real simbridge.

The test runs the repository's server block as it is, with three values substituted so that it
runs beside other test runs on this machine: the listen port (a free 127.0.0.1 port instead of
8080), the upstream (the test's simbridge on a free port instead of ros2-web-bridge:9090) and the
document root (static/ instead of the container's /usr/share/nginx/html).
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import urllib.error
import urllib.request
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from simbridge.app.runner import App
from tests.conftest import ClientRunner
from tests.deploy.stack import free_port
from tests.helpers import ROOT, TIMEOUT_FACTOR


pytestmark = pytest.mark.e2e

NGINX_CONF = ROOT / "config" / "nginx.conf"
STATIC = ROOT / "static"


def render_server_block(ws_port: int, web_port: int) -> str:
    """config/nginx.conf with the test's ports and document root; each value must be there once."""
    text = NGINX_CONF.read_text()
    for old, new in {
        "listen 8080;": f"listen 127.0.0.1:{web_port};",
        "ros2-web-bridge:9090": f"127.0.0.1:{ws_port}",
        "root /usr/share/nginx/html;": f"root {STATIC};",
    }.items():
        assert text.count(old) == 1, f"config/nginx.conf should contain {old!r} once"
        text = text.replace(old, new)
    return text


def main_conf(tmp: Path) -> str:
    """A main nginx.conf around the server block, every file in ``tmp`` (no root paths)."""
    temp_paths = "\n".join(
        f"    {kind}_temp_path {tmp / kind};" for kind in ("client_body", "proxy", "fastcgi")
    )
    user = "user root;\n" if os.geteuid() == 0 else ""
    return f"""{user}daemon off;
worker_processes 1;
pid {tmp / "nginx.pid"};
error_log {tmp / "error.log"} info;
events {{ worker_connections 256; }}
http {{
    include /etc/nginx/mime.types;
    default_type application/octet-stream;
    access_log {tmp / "access.log"};
{temp_paths}
    uwsgi_temp_path {tmp / "uwsgi"};
    scgi_temp_path {tmp / "scgi"};
    include {tmp / "default.conf"};
}}
"""


class Nginx:
    """A running nginx: its port and its files."""

    def __init__(self, port: int, tmp: Path) -> None:
        self.port = port
        self.tmp = tmp

    @property
    def http(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws(self) -> str:
        return f"ws://127.0.0.1:{self.port}/ws"


async def _listening(port: int) -> bool:
    try:
        _, writer = await asyncio.open_connection("127.0.0.1", port)
    except OSError:
        return False
    writer.close()
    await writer.wait_closed()
    return True


@pytest.fixture
async def nginx(app: App, tmp_path: Path) -> AsyncIterator[Nginx]:
    """Debian's nginx serving static/ and proxying /ws to ``app``, on a free port."""
    binary = shutil.which("nginx") or "/usr/sbin/nginx"
    assert Path(binary).exists(), "nginx is not installed; run `make deps` (apt-get install nginx)"
    port = free_port()
    (tmp_path / "default.conf").write_text(render_server_block(app.ws_port, port))
    conf = tmp_path / "nginx.conf"
    conf.write_text(main_conf(tmp_path))
    error_log = tmp_path / "error.log"
    cmd = [binary, "-p", str(tmp_path), "-c", str(conf), "-e", str(error_log)]
    proc = await asyncio.create_subprocess_exec(
        *cmd, stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE
    )
    try:
        async with asyncio.timeout(10 * TIMEOUT_FACTOR):
            while not await _listening(port):
                if proc.returncode is not None:
                    break
                await asyncio.sleep(0.05)
        if proc.returncode is not None:
            assert proc.stderr is not None
            err = (await proc.stderr.read()).decode()
            log = error_log.read_text() if error_log.exists() else ""
            pytest.fail(f"nginx exited {proc.returncode}: {err}\n{log}")
        yield Nginx(port, tmp_path)
    finally:
        if proc.returncode is None:
            proc.terminate()
            await proc.wait()


def get(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status, response.headers.get("Content-Type", ""), response.read()
    except urllib.error.HTTPError as err:
        return err.code, err.headers.get("Content-Type", ""), err.read()


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_receives_odom_and_scan_through_ws(
    nginx: Nginx, run_js: ClientRunner, lib: str
) -> None:
    """Roslibjs at ws://HOST:PORT/ws receives the bridge's /odom and /scan through nginx."""
    odom = await run_js(lib, nginx.ws, "odom_rate", {"count": 5})
    assert odom["first"]["header"]["frame_id"] == "odom"
    assert odom["count"] == 5
    scan = await run_js(lib, nginx.ws, "scan")
    assert len(scan["ranges"]) == 360


async def test_roslibpy_with_the_ws_url_as_host_receives_scan(
    nginx: Nginx, run_roslibpy: ClientRunner
) -> None:
    """A roslibpy 2.1.0 ``Ros("ws://HOST:PORT/ws")`` (no port) works through nginx too."""
    scan = await run_roslibpy(nginx.ws, "scan")
    assert len(scan["ranges"]) == 360


async def test_cmd_vel_published_through_ws_drives_the_robot(
    nginx: Nginx, run_js: ClientRunner
) -> None:
    """The proxy carries the client's frames too: /cmd_vel through /ws moves the robot."""
    result = await run_js("roslib2", nginx.ws, "drive", {"v": 0.3, "w": 0.0, "seconds": 1.0})
    assert result["final"]["x"] - result["start"]["x"] == pytest.approx(0.3, abs=0.03)


async def test_ws_clients_through_nginx_show_in_the_bridges_health(nginx: Nginx, app: App) -> None:
    """/healthz through nginx is the bridge's own document."""
    status, ctype, body = await asyncio.to_thread(get, f"{nginx.http}/healthz")
    assert status == 200 and ctype.startswith("application/json")
    health = json.loads(body)
    assert health["status"] == "ok"
    assert health["world"] == "default"


async def test_nginx_serves_static_files_as_they_are(nginx: Nginx) -> None:
    """The page and its vendored library from static/, byte for byte, with their types."""
    status, ctype, body = await asyncio.to_thread(get, f"{nginx.http}/")
    assert status == 200 and ctype.startswith("text/html")
    assert body == (STATIC / "index.html").read_bytes()
    status, ctype, body = await asyncio.to_thread(get, f"{nginx.http}/vendor/roslib.min.js")
    assert status == 200 and "javascript" in ctype
    assert body == (STATIC / "vendor" / "roslib.min.js").read_bytes()


async def test_nginx_answers_404_outside_static(nginx: Nginx) -> None:
    """A missing file is a 404; nothing outside static/ is reachable."""
    status, _, _ = await asyncio.to_thread(get, f"{nginx.http}/no-such-page.html")
    assert status == 404
    status, _, body = await asyncio.to_thread(get, f"{nginx.http}/../config/pi4b_params.yaml")
    assert status in (400, 404)
    assert b"robot" not in body


async def test_page_from_nginx_connects_through_its_ws_by_default_and_where_told(
    nginx: Nginx,
) -> None:
    """In chromium, the page nginx serves connects to nginx's /ws unasked; ?url= still wins.

    nginx's /api/rosbridge names /ws. Only the WebSocket traffic is checked (not the page's
    markup, which has its own tests).
    """
    from playwright.async_api import WebSocket, async_playwright

    from tests.browser.conftest import CHROMIUM, FLAGS

    status, _, body = await asyncio.to_thread(get, f"{nginx.http}/api/rosbridge")
    assert (status, json.loads(body)) == (200, {"path": "/ws"})
    assert shutil.which(CHROMIUM), "chromium is missing: run `make deps` (apt-get install chromium)"
    async with async_playwright() as pw:
        browser = await pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS, headless=True)
        try:
            sockets: list[WebSocket] = []
            frames: list[str] = []

            def on_socket(ws: WebSocket) -> None:
                sockets.append(ws)
                ws.on("framereceived", lambda data: frames.append(str(data)))

            page = await browser.new_page()
            page.on("websocket", on_socket)
            await page.goto(f"{nginx.http}/")
            async with asyncio.timeout(10 * TIMEOUT_FACTOR):
                while not any('"/odom"' in f for f in frames):
                    await asyncio.sleep(0.05)
            assert sockets[0].url == nginx.ws
            await page.close()

            sockets.clear()
            page = await browser.new_page()
            page.on("websocket", on_socket)
            await page.goto(f"{nginx.http}/?url=ws://127.0.0.1:9")  # told: no guessing
            async with asyncio.timeout(10 * TIMEOUT_FACTOR):
                while not sockets:
                    await asyncio.sleep(0.05)
            assert sockets[0].url.rstrip("/") == "ws://127.0.0.1:9"
        finally:
            await browser.close()
