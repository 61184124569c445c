"""The page in a classroom of two simbridge processes (ROS 2 over Zenoh).

Its robot picker lists the robot the other process simulates, and shows where that robot is.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from simbridge.config import ServerSettings
from simbridge.runner import App
from tests.browser.conftest import OpenPage
from tests.helpers import ROOT, TIMEOUT_FACTOR, ws_url
from tests.zenoh.conftest import Router, zenoh_options
from tests.zenoh.test_classroom import WORLD


pytestmark = pytest.mark.e2e


@pytest.fixture
async def classroom(tmp_path: Path) -> AsyncIterator[App]:
    """A router, a process simulating robot a1, and this process's app (its own robot)."""
    pytest.importorskip("zenoh")
    router = Router()
    await asyncio.to_thread(router.start)
    world = tmp_path / "room_a.yaml"
    world.write_text(WORLD)
    other = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "simbridge",
        "--zenoh",
        "--zenoh-connect",
        router.endpoint,
        "--zenoh-listen",
        "tcp/127.0.0.1:0",
        "--world",
        str(world),
        "--host",
        "127.0.0.1",
        "--port",
        "0",
        "--no-http",
        cwd=ROOT,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
    )
    assert other.stdout is not None
    await asyncio.wait_for(other.stdout.readline(), 20 * TIMEOUT_FACTOR)
    app = App(ServerSettings(host="127.0.0.1", port=0, http_port=0), zenoh=zenoh_options(router))
    await app.start()
    try:
        yield app
    finally:
        await app.stop()
        other.terminate()
        await other.communicate()
        router.stop()


async def test_page_picker_lists_and_shows_a_robot_of_another_process(
    classroom: App, open_page: OpenPage
) -> None:
    page, log = await open_page(classroom, f"/?url={ws_url(classroom)}")
    await page.wait_for_function("window.simbridge && window.simbridge.conn.connected")
    await page.wait_for_function(
        "[...document.getElementById('robot').options].some((o) => o.value === 'a1')",
        timeout=20_000 * TIMEOUT_FACTOR,
    )
    await page.select_option("#robot", "a1")
    # a1 starts at (-1, 0) in the other process's world; this process's robot is elsewhere
    await page.wait_for_function(
        "window.simbridge.state.pose && Math.abs(window.simbridge.state.pose.x + 1.0) < 1e-6",
        timeout=10_000 * TIMEOUT_FACTOR,
    )
    assert not log.errors
