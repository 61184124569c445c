"""The page publishes /cmd_vel in the type the robot takes (static/js/cmdvel.js).

The server here is started with ``robot.cmd_vel_stamped`` (its /cmd_vel is TwistStamped, as a
Jazzy diff_drive_controller's): the page asks rosapi and sends TwistStamped from every source,
seen by a separate client. The default server keeps Twist: ``test_page.py``'s teleop test.
"""

from __future__ import annotations

import time

import pytest
from playwright.async_api import Page

from simbridge.app.config import Params, RobotParams
from simbridge.app.runner import App
from tests.browser.conftest import OpenPage, PageLog, Watcher, screenshot
from tests.conftest import AppFactory
from tests.helpers import wait_for, ws_url


pytestmark = pytest.mark.e2e

STAMPED = "geometry_msgs/msg/TwistStamped"


@pytest.fixture
async def app(make_app: AppFactory) -> App:
    """A simbridge whose robot wants TwistStamped on /cmd_vel."""
    return await make_app(params=Params(robot=RobotParams(cmd_vel_stamped=True)))


async def open_ready(open_page: OpenPage, app: App, query: str = "") -> tuple[Page, PageLog]:
    page, log = await open_page(app, f"/?url={ws_url(app)}{query}")
    await page.wait_for_function(
        "window.simbridge && window.simbridge.conn.connected && window.simbridge.cmdVel.ready"
        " && window.simbridge.state.pose !== null"
    )
    return page, log


async def test_teleop_pid_and_estop_zero_publish_twist_stamped_to_a_stamped_robot(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    await watcher.subscribe("/cmd_vel", STAMPED)
    page, log = await open_ready(open_page, app)
    assert await page.evaluate("window.simbridge.cmdVel.type") == STAMPED
    assert await page.text_content("#cmdVelType option[value=auto]") == "auto (TwistStamped)"
    x0 = watcher.odom()["x"]  # type: ignore[index]
    await page.keyboard.down("ArrowUp")
    await watcher.wait(lambda: watcher.odom()["x"] > x0 + 0.1)  # type: ignore[index]
    await page.keyboard.up("ArrowUp")
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    cmds = [m for _, m in watcher.history["/cmd_vel"]]
    assert cmds[0]["twist"]["linear"]["x"] == pytest.approx(0.3)
    assert cmds[-1]["twist"]["linear"]["x"] == 0.0  # the one zero on release
    assert {m["header"]["frame_id"] for m in cmds} == {"base_link"}
    assert abs(cmds[-1]["header"]["stamp"]["sec"] - time.time()) < 5  # the page's clock
    # the PID lab drives through the same publisher
    await page.click("button[data-tab=pid]")
    await page.fill("#spTheta", "90")
    await page.click("#pidStart")
    await watcher.wait(lambda: watcher.odom()["w"] > 0.5)  # type: ignore[index]
    assert "TwistStamped" in (await page.text_content("#example") or "")
    # the e-stop's zero too: Space sends a stamped zero before latching
    n = len(watcher.history["/cmd_vel"])
    await page.keyboard.press("Space")
    await watcher.wait(lambda: watcher.odom()["w"] == 0.0)  # type: ignore[index]
    await watcher.wait(lambda: len(watcher.history["/cmd_vel"]) > n)
    zero = watcher.history["/cmd_vel"][-1][1]
    assert zero["twist"]["angular"]["z"] == 0.0 and "header" in zero
    await screenshot(page, "cmd-vel-stamped")
    assert log.errors == []


async def test_override_control_is_kept_in_the_url(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """?cmd_vel_type=Twist forces Twist (refused here, and the page says why); auto drives."""
    page, _ = await open_ready(open_page, app, "&cmd_vel_type=Twist")
    assert await page.input_value("#cmdVelType") == "Twist"
    assert await page.evaluate("window.simbridge.cmdVel.type") == "geometry_msgs/msg/Twist"
    await page.focus("#view")
    await page.keyboard.down("KeyW")
    await page.wait_for_function(
        "document.getElementById('toast').textContent.includes('already established with type"
        f" {STAMPED}')"
    )
    await page.keyboard.up("KeyW")
    await page.select_option("#cmdVelType", "auto")
    assert "cmd_vel_type" not in page.url
    assert await page.evaluate("window.simbridge.cmdVel.type") == STAMPED
    await page.focus("#view")
    await page.keyboard.down("KeyW")
    await watcher.wait(lambda: watcher.odom()["v"] > 0)  # type: ignore[index]
    await page.keyboard.up("KeyW")
    await page.select_option("#cmdVelType", "TwistStamped")
    assert "cmd_vel_type=TwistStamped" in page.url


async def test_pointing_the_page_at_a_stamped_robot_switches_the_type(
    app: App, make_app: AppFactory, open_page: OpenPage
) -> None:
    """The URL field is the sim-to-real switch: the new server is asked its type again."""
    plain = await make_app()
    page, log = await open_ready(open_page, plain)
    assert await page.evaluate("window.simbridge.cmdVel.type") == "geometry_msgs/msg/Twist"
    await page.click("#server summary")  # the server form
    await page.fill("#url", ws_url(app))
    await page.click("#urlForm button[type=submit]")
    await page.wait_for_function(
        f"window.simbridge.conn.url === '{ws_url(app)}' && window.simbridge.conn.connected"
        f" && window.simbridge.cmdVel.ready && window.simbridge.cmdVel.type === '{STAMPED}'"
    )
    await page.focus("#view")
    await page.keyboard.down("ArrowUp")
    await wait_for(lambda: app.world.robots[""].state.x > 0.05)
    await page.keyboard.up("ArrowUp")
    await wait_for(lambda: app.world.robots[""].cmd_v == 0.0)
    assert plain.world.robots[""].state.x == 0.0
    assert log.errors == []
