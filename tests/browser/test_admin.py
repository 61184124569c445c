"""The instructor's /admin in a real browser: token refusals, and mass in the dynamic model.

The dynamic model's torque-limited acceleration is ``dv/dt = 2 tau_max / (r m)``
(:mod:`simbridge.sim.dynamics`): from rest toward 0.5 m/s both motors saturate while the
wheel-speed error exceeds ``tau_max / k`` (0.2 m/s), so each 50 ms step adds
``2 tau_max dt / (r m)`` to v; doubling the mass must halve that increment.
"""

from __future__ import annotations

import itertools
import json
import statistics

import pytest
from playwright.async_api import Page

from simbridge.app.runner import App
from tests.browser.conftest import OpenPage, Watcher, screenshot
from tests.conftest import AppFactory
from tests.helpers import ws_url


pytestmark = pytest.mark.e2e
TOKEN = "class-2026"


async def message(page: Page, starts: str) -> str:
    await page.wait_for_function(
        "(s) => document.getElementById('message').textContent.startsWith(s)", arg=starts
    )
    return await page.text_content("#message") or ""


async def feedback(page: Page, where: str, starts: str) -> str:
    """The feedback next to the control clicked."""
    await page.wait_for_function(
        "([id, s]) => document.getElementById(id).textContent.startsWith(s)", arg=[where, starts]
    )
    return await page.text_content(f"#{where}") or ""


async def test_admin_refuses_every_change_without_the_token(
    make_app: AppFactory, open_page: OpenPage
) -> None:
    app = await make_app(admin_token=TOKEN)
    page, log = await open_page(app, "/admin")
    # locked: only the token field, no empty boxes and no controls
    assert await page.is_hidden("#console") and await page.is_hidden("#applyModel")
    app.world.robots[""].place((0.5, 0.5, 0.0))
    await page.fill("#token", "guess")
    await page.click("#tokenForm button")
    assert "wrong admin token" in await message(page, "Refused: wrong")
    assert await page.is_hidden("#console")
    await screenshot(page, "admin-refused", full_page=True)
    assert app.world.motion.name == "kinematic"
    assert app.world.robots[""].state.x == 0.5  # not reset
    assert app.world.params.robot.mass == 1.5
    assert [e for e in log.errors if "401" not in e and "403" not in e] == []


async def test_admin_off_when_the_server_has_no_token(app: App, open_page: OpenPage) -> None:
    page, _ = await open_page(app, "/admin")
    await page.fill("#token", "anything")
    await page.click("#tokenForm button")
    assert "admin is disabled" in await message(page, "Refused")


def velocity_steps(odoms: list[dict[str, float]]) -> list[float]:
    """Per-step increments of v while both motors are torque-limited (v below 0.25 m/s)."""
    vs = [o["twist"]["twist"]["linear"]["x"] for o in odoms]
    return [b - a for a, b in itertools.pairwise(vs) if b > a and b < 0.25]


async def accelerate(app: App, watcher: Watcher) -> list[float]:
    """From rest, command 0.5 m/s; return the per-step v increments seen on /odom."""
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    start = len(watcher.history["/odom"]) - 1  # the last odom at rest
    cmd = {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.5}, "angular": {}}}
    await watcher.conn.send(json.dumps(cmd))
    await watcher.wait(lambda: watcher.odom()["v"] > 0.45)  # type: ignore[index]
    stop = {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.0}, "angular": {}}}
    await watcher.conn.send(json.dumps(stop))
    odoms = [m for _, m in watcher.history["/odom"][start:]]
    return velocity_steps(odoms)


async def test_admin_mass_change_slows_the_dynamic_models_acceleration(
    make_app: AppFactory, open_page: OpenPage
) -> None:
    """With the token: switch to the dynamic model, then doubling the mass halves dv/dt."""
    app = await make_app(admin_token=TOKEN)
    page, log = await open_page(app, "/admin")
    await page.fill("#token", TOKEN)
    await page.click("#tokenForm button")
    await message(page, "Unlocked")
    await page.select_option("#model", "dynamic")
    await page.click("#applyModel")
    await feedback(page, "worldMsg", "Motion model: dynamic")
    assert app.world.motion.name == "dynamic"

    from websockets.asyncio.client import connect

    async with connect(ws_url(app), max_size=None) as conn:
        watcher = Watcher(conn)
        await watcher.subscribe("/odom", "nav_msgs/msg/Odometry")
        await watcher.wait(lambda: watcher.odom() is not None)
        # the admin page lists this client and what it subscribed to
        await page.wait_for_function(
            "document.getElementById('clients').textContent.includes('/odom')"
        )
        robot = app.world.params.robot
        dt = app.world.dt
        expected_light = 2 * robot.max_wheel_torque * dt / (robot.wheel_radius * robot.mass)
        light = await accelerate(app, watcher)

        await page.fill("#params input[name='robot.mass']", str(2 * robot.mass))
        await page.click("#paramsForm button[type=submit]")
        assert "robot.mass = 3" in await feedback(page, "paramsMsg", "Applied")
        assert app.world.params.robot.mass == 3.0
        expected_heavy = expected_light / 2
        heavy = await accelerate(app, watcher)
        watcher.task.cancel()
    await screenshot(page, "admin-dynamic-mass", full_page=True)
    assert len(light) >= 2 and len(heavy) >= 4, (light, heavy)
    assert statistics.median(light) == pytest.approx(expected_light, rel=0.01)
    assert statistics.median(heavy) == pytest.approx(expected_heavy, rel=0.01)
    assert log.errors == []
