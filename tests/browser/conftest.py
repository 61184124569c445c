"""Fixtures of the browser tests: Debian's chromium driven by Playwright, a rosbridge watcher.

Playwright cannot download its own browsers here (and CI is offline): it drives the system
``/usr/bin/chromium`` (``scripts/setup-test-deps.sh`` installs it). Screenshots go to
``artifacts/screenshots/`` (kept by CI as artifacts; git-ignored).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import pytest
from playwright.async_api import Browser, ConsoleMessage, Page, async_playwright
from websockets.asyncio.client import ClientConnection, connect

from simbridge.app.runner import App
from tests.helpers import ROOT, TIMEOUT_FACTOR, http_url, ws_url


CHROMIUM = "/usr/bin/chromium"
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
SCREENSHOTS = ROOT / "artifacts" / "screenshots"


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    """A headless Debian chromium."""
    assert shutil.which(CHROMIUM), "chromium is missing: run `make deps` (apt-get install chromium)"
    async with async_playwright() as pw:
        b = await pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS, headless=True)
        yield b
        await b.close()


@dataclass
class PageLog:
    """What a page did: console errors, uncaught exceptions, every URL it asked for."""

    errors: list[str] = field(default_factory=list)
    urls: list[str] = field(default_factory=list)

    def foreign(self, allowed: tuple[str, ...]) -> list[str]:
        """Return the URLs outside ``allowed`` prefixes (``data:`` is in-page)."""
        return [u for u in self.urls if not u.startswith(allowed) and not u.startswith("data:")]


OpenPage = Callable[..., Awaitable[tuple[Page, PageLog]]]


@pytest.fixture
def open_page(browser: Browser) -> OpenPage:
    """Open the page of ``app`` (query ``query``) in a fresh context; log what it does."""

    async def opener(app: App, path: str = "/", **context: Any) -> tuple[Page, PageLog]:
        ctx = await browser.new_context(**context)
        page = await ctx.new_page()
        log = PageLog()

        def on_console(msg: ConsoleMessage) -> None:
            if msg.type == "error":
                log.errors.append(msg.text)

        page.on("console", on_console)
        page.on("pageerror", lambda err: log.errors.append(f"uncaught: {err}"))
        page.on("request", lambda req: log.urls.append(req.url))
        page.on("websocket", lambda ws: log.urls.append(ws.url))
        page.set_default_timeout(10_000 * TIMEOUT_FACTOR)
        await page.goto(http_url(app) + path)
        return page, log

    return opener


async def screenshot(page: Page, name: str, *, full_page: bool = False) -> None:
    """Save a screenshot as artifacts/screenshots/<name>.png."""
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    await page.screenshot(path=str(SCREENSHOTS / f"{name}.png"), full_page=full_page)


class Watcher:
    """A separate rosbridge client (plain WebSocket): the latest message of each topic."""

    def __init__(self, conn: ClientConnection) -> None:
        self.conn = conn
        self.latest: dict[str, Any] = {}
        self.history: dict[str, list[tuple[float, Any]]] = {}
        self.task = asyncio.create_task(self._run())

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        with contextlib.suppress(Exception):
            async for data in self.conn:
                msg = json.loads(data)
                if msg.get("op") == "publish":
                    self.latest[msg["topic"]] = msg["msg"]
                    self.history.setdefault(msg["topic"], []).append((loop.time(), msg["msg"]))

    async def subscribe(self, topic: str, type_name: str) -> None:
        await self.conn.send(json.dumps({"op": "subscribe", "topic": topic, "type": type_name}))

    def odom(self) -> dict[str, float] | None:
        """Return the latest /odom as {x, y, theta, v, w}, or None."""
        m = self.latest.get("/odom")
        if m is None:
            return None
        p = m["pose"]["pose"]
        import math

        q = p["orientation"]
        return {
            "x": p["position"]["x"],
            "y": p["position"]["y"],
            "theta": 2 * math.atan2(q["z"], q["w"]),
            "v": m["twist"]["twist"]["linear"]["x"],
            "w": m["twist"]["twist"]["angular"]["z"],
        }

    async def wait(self, predicate: Callable[[], bool], timeout: float = 5.0) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout * TIMEOUT_FACTOR
        while not predicate():
            if loop.time() > deadline:
                msg = f"condition not met within {timeout} s; latest /odom {self.odom()}"
                raise TimeoutError(msg)
            await asyncio.sleep(0.02)


@pytest.fixture
async def watcher(app: App) -> AsyncIterator[Watcher]:
    """A rosbridge client of ``app`` watching /odom."""
    async with connect(ws_url(app), max_size=None) as conn:
        w = Watcher(conn)
        await w.subscribe("/odom", "nav_msgs/msg/Odometry")
        await w.wait(lambda: w.odom() is not None)
        yield w
        w.task.cancel()
