"""The page in a classroom of two simbridge processes (ROS 2 over Zenoh).

Its robot picker lists the robot the other process simulates, and shows where that robot is.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from tests.browser.conftest import OpenPage
from tests.helpers import TIMEOUT_FACTOR, ws_url
from tests.ros2.zenoh.conftest import Router, room_a_process, zenoh_options


pytestmark = pytest.mark.e2e


@pytest.fixture
async def classroom(tmp_path: Path) -> AsyncIterator[App]:
    """A router, a process simulating robot a1, and this process's app (its own robot)."""
    pytest.importorskip("zenoh")
    router = Router()
    await asyncio.to_thread(router.start)
    try:
        async with room_a_process(router, tmp_path):
            app = App(
                ServerSettings(host="127.0.0.1", port=0, http_port=0),
                zenoh=zenoh_options(router),
            )
            await app.start()
            try:
                yield app
            finally:
                await app.stop()
    finally:
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
