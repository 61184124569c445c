"""The gamepad's configurable mapping, deadman and rate (static/js/teleop.js), in a real browser.

Playwright cannot attach a real gamepad: the page's ``navigator.getGamepads`` is replaced by a
fake standard pad whose axes and buttons the test sets; everything after it is the page's own
code, and the robot's motion is seen on /odom by a separate client.
"""

from __future__ import annotations

import itertools
import statistics

import pytest

from simbridge.app.runner import App
from tests.browser.conftest import OpenPage, Watcher, screenshot
from tests.helpers import ws_url


pytestmark = pytest.mark.e2e

FAKE_PAD = """() => {
  const button = () => ({ pressed: false, value: 0 });
  const buttons = Array.from({ length: 16 }, button);
  window.fakePad = { id: 'test pad', axes: [0, 0, 0, 0], buttons };
  navigator.getGamepads = () => [window.fakePad];
  window.dispatchEvent(new Event('gamepadconnected'));
}"""


async def test_gamepad_axis_inversion_deadman_and_rate_follow_the_url_and_the_panel(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    await watcher.subscribe("/cmd_vel", "geometry_msgs/msg/Twist")
    query = "gp_linear_axis=3&gp_invert_linear=1&gp_deadman=7&teleop_rate=20"
    page, log = await open_page(app, f"/?url={ws_url(app)}&{query}")
    await page.wait_for_function(
        "window.simbridge && window.simbridge.conn.connected && window.simbridge.cmdVel.ready"
        " && window.simbridge.state.pose !== null"
    )
    await page.evaluate(FAKE_PAD)
    # RT (button 7) held, the default stick axis 1 pushed: not the configured axis, no motion
    await page.evaluate("window.fakePad.axes[1] = -1; window.fakePad.buttons[7].pressed = true")
    status = "document.getElementById('gamepad').textContent"
    await page.wait_for_function(f"{status}.includes('driving')")
    assert await page.evaluate("window.simbridge.driver.last") == {"v": 0, "w": 0}
    # axis 3, inverted: pulled back (+1) drives forward, at 20 Hz
    await page.evaluate("window.fakePad.axes[3] = 1")
    await watcher.wait(lambda: watcher.odom()["v"] == pytest.approx(0.3))  # type: ignore[index]
    await watcher.wait(
        lambda: sum(m["linear"]["x"] > 0 for _, m in watcher.history["/cmd_vel"]) >= 12
    )
    await page.evaluate("window.fakePad.buttons[7].pressed = false")  # deadman released: zero
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    moving = [t for t, m in watcher.history["/cmd_vel"] if m["linear"]["x"] > 0]
    gap = statistics.median(b - a for a, b in itertools.pairwise(moving))
    assert 0.03 < gap < 0.075, f"published every {gap * 1000:.0f} ms, expected 50"
    assert watcher.history["/cmd_vel"][-1][1]["linear"]["x"] == 0.0
    # the panel shows the settings; a change applies at once and goes into the URL
    await page.click("#gpSettings summary")
    assert await page.input_value("#gpLinearAxis") == "3"
    assert await page.is_checked("#gpInvertLinear")
    await page.fill("#teleopRate", "500")  # out of range: refused, the old value stays
    await page.press("#teleopRate", "Enter")
    await page.wait_for_function("document.getElementById('toast').textContent.includes('rate')")
    assert await page.input_value("#teleopRate") == "20"
    await page.fill("#gpDeadman", "none")
    await page.press("#gpDeadman", "Enter")
    await page.wait_for_function("location.search.includes('gp_deadman=none')")
    await watcher.wait(lambda: watcher.odom()["v"] > 0.2)  # type: ignore[index]  # stick alone
    await screenshot(page, "gamepad-settings")
    await page.evaluate("window.fakePad.axes[3] = 0")  # centred: the one zero
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    assert log.errors == []
