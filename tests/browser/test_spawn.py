"""The page's spawn control in a real browser: a student adds a robot and drives it."""

from __future__ import annotations

import pytest

from simbridge.app.config import WorldSpec
from tests.browser.conftest import OpenPage, screenshot
from tests.conftest import AppFactory
from tests.helpers import wait_for, ws_url


pytestmark = pytest.mark.e2e

WORLD = WorldSpec.parse(
    {
        "walls": [[-3, -2, 3, -2], [3, -2, 3, 2], [3, 2, -3, 2], [-3, 2, -3, -2]],
        "robots": [{"name": "r1", "pose": [0, 0, 0]}],
    }
)


async def test_spawn_adds_a_robot_selects_it_and_drives_it(
    make_app: AppFactory, open_page: OpenPage
) -> None:
    """Typing a name and pressing Spawn calls /spawn; the new robot is selected and driven."""
    app = await make_app(world=WORLD)
    page, log = await open_page(app, f"/?url={ws_url(app)}")
    await page.wait_for_function("window.simbridge && window.simbridge.conn.connected")
    await page.wait_for_function("window.simbridge.state.pose !== null")
    await page.fill("#spawnName", "alice")
    await page.click("#spawnForm button[type=submit]")
    await wait_for(lambda: "alice" in app.world.robots, timeout=10)
    await page.wait_for_function("document.getElementById('robot').value === 'alice'")
    alice = app.world.robots["alice"].state
    assert 0.4 < abs(complex(alice.x, alice.y)) < 0.6  # on the first ring around r1
    await page.wait_for_function("window.simbridge.state.ns === 'alice'")
    await page.fill("#spawnName", "alice")
    await page.click("#spawnForm button[type=submit]")
    await page.wait_for_function(
        "document.getElementById('toast').textContent.includes('already exists')"
    )
    await screenshot(page, "page-spawn")
    assert log.errors == []
    x0 = alice.x
    await page.keyboard.down("ArrowUp")
    await wait_for(lambda: abs(app.world.robots["alice"].state.x - x0) > 0.02, timeout=10)
    await page.keyboard.up("ArrowUp")
    assert app.world.robots["r1"].state.x == 0.0  # r1 did not move
