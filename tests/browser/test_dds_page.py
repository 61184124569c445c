"""The page in front of a robot on DDS: ``simbridge --dds --no-sim`` and a Fast DDS robot.

The robot is the Fast DDS test peer's stand-in (``ddspeer --robot``: /odom, /scan, /tf, obeys
/cmd_vel), in a network namespace of the test's own with simbridge; Chromium stays outside and
reaches simbridge's ports through the namespace's forwarders.
"""

from __future__ import annotations

from typing import Any

import pytest
from playwright.async_api import Browser

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.ros2.dds.options import DdsOptions
from tests.helpers import wait_for
from tests.ros2.dds.harness import NetNamespace, dds_domain, ddspeer, ddspeer_bin, netns


pytestmark = pytest.mark.e2e

__all__ = ["dds_domain", "ddspeer", "ddspeer_bin", "netns"]


async def test_the_page_drives_a_fast_dds_robot_through_no_sim_dds(
    netns: NetNamespace, dds_domain: int, ddspeer: Any, browser: Browser
) -> None:
    robot = await ddspeer("--robot", node="robot_driver")
    with netns.entered():
        settings = ServerSettings(host="127.0.0.1", port=0, http_port=0)
        app = App(settings, no_sim=True, dds=DdsOptions(domain=dds_domain, distro="humble"))
        await app.start()
    try:
        await wait_for(lambda: "/cmd_vel" in app.graph.topics.topics, 10)
        assert app.ws_port is not None and app.http_port is not None
        ws_port, http_port = netns.forward(app.ws_port), netns.forward(app.http_port)
        page = await (await browser.new_context()).new_page()
        errors: list[str] = []
        page.on("pageerror", lambda err: errors.append(str(err)))
        await page.goto(f"http://127.0.0.1:{http_port}/?url=ws://127.0.0.1:{ws_port}")
        await page.wait_for_function(
            "window.simbridge && window.simbridge.conn.connected && window.simbridge.cmdVel.ready"
            " && window.simbridge.state.pose !== null"
        )
        x0 = await page.evaluate("window.simbridge.state.pose.x")
        await page.keyboard.down("ArrowUp")
        # the robot's own side: a Twist on its real /cmd_vel, from the page's teleop
        command = await robot.wait_for(
            lambda e: e.get("event") == "cmd_vel" and e["data"]["linear"]["x"] > 0,
            what="the page's /cmd_vel",
        )
        # the page shows the robot moving, from the robot's real /odom
        await page.wait_for_function(f"window.simbridge.state.pose.x > {x0} + 0.05")
        await page.keyboard.up("ArrowUp")
        assert command["data"]["linear"]["x"] == pytest.approx(0.3)
        assert not errors
    finally:
        with netns.entered():
            await app.stop()
