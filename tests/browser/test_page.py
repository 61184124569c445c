"""The page in a real browser (headless Debian chromium): connection, view, teleop, e-stop, PID.

Each test starts a real simbridge on 127.0.0.1 (free ports), opens the page with
``?url=ws://127.0.0.1:<port>`` and checks the robot's behaviour on /odom through a separate
rosbridge client, never through the page itself.
"""

from __future__ import annotations

import itertools
import json
import math
import statistics
from typing import Any

import psutil
import pytest
from playwright.async_api import Browser, Page

from simbridge.app.runner import App
from tests.browser.conftest import OpenPage, Watcher, screenshot
from tests.conftest import AppFactory
from tests.helpers import ROOT, http_url, wait_for, ws_url


pytestmark = pytest.mark.e2e


async def open_connected(open_page: OpenPage, app: App, **context: Any) -> tuple[Page, Any]:
    page, log = await open_page(app, f"/?url={ws_url(app)}", **context)
    await page.wait_for_function("window.simbridge && window.simbridge.conn.connected")
    await page.wait_for_function(
        "window.simbridge.state.pose !== null && window.simbridge.state.walls > 0"
        " && window.simbridge.cmdVel.ready"  # knows which type /cmd_vel takes
    )
    return page, log


async def canvas_colours(page: Page) -> dict[str, int]:
    """Count pixels of the view's wall, robot, scan and grid colours."""
    return await page.evaluate(
        """() => {
          const c = document.getElementById('view');
          const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
          const n = { wall: 0, robot: 0, scan: 0, other: 0 };
          for (let i = 0; i < d.length; i += 4) {
            const [r, g, b] = [d[i], d[i + 1], d[i + 2]];
            if (r < 70 && g < 70 && b < 90) n.wall++;
            else if (g > 100 && r < 60 && b < 90) n.robot++;
            else if (r > 160 && g < 90 && b > 170) n.scan++;  // LiDAR: fuchsia, no map colour
            else n.other++;
          }
          return n;
        }"""
    )


async def test_page_loads_without_errors_and_asks_only_its_server(
    app: App, open_page: OpenPage
) -> None:
    """No console error, no uncaught exception, and every request goes to this server."""
    page, log = await open_connected(open_page, app)
    await page.wait_for_function("window.simbridge.conn.rates().some(r => r.name === '/scan')")
    await page.wait_for_timeout(300)  # let late requests (params, rosapi) show up in the log
    await screenshot(page, "page-desktop")
    assert log.errors == []
    allowed = (http_url(app) + "/", ws_url(app))
    assert log.foreign(allowed) == []
    assert any(u.startswith(ws_url(app)) for u in log.urls)
    assert await page.text_content("#statusText") == "connected"


async def test_page_without_url_connects_to_the_port_its_server_names(
    app: App, open_page: OpenPage
) -> None:
    """With no ?url=, the page connects where its server's /api/rosbridge says (not 9090).

    The test's server listens on a free port, never 9090.
    """
    page, log = await open_page(app, "/")
    await page.wait_for_function("window.simbridge && window.simbridge.conn.connected")
    assert await page.evaluate("window.simbridge.conn.url") == ws_url(app)
    assert await page.input_value("#url") == ws_url(app)
    assert await page.text_content("#linkUrl") == ws_url(app)
    assert log.errors == []


async def test_canvas_draws_walls_robot_and_scan(app: App, open_page: OpenPage) -> None:
    """The view shows the world's walls, the robot footprint and the scan points."""
    page, _ = await open_connected(open_page, app)
    await page.wait_for_function("window.simbridge.view.scan.length > 50")
    await page.wait_for_timeout(100)
    counts = await canvas_colours(page)
    await screenshot(page, "view-world")
    assert counts["wall"] > 500, counts
    # the footprint's fill is drawn where the robot is (sampled off its heading arrow and the
    # origin axes), and the background where nothing is
    colours = await page.evaluate(
        """() => {
          const { view } = window.simbridge;
          const c = document.getElementById('view');
          const dpr = c.width / c.getBoundingClientRect().width;
          const at = (x, y) => {
            const r = c.getBoundingClientRect();
            const sx = (r.width / 2 + (x - view.center.x) * view.scale) * dpr;
            const sy = (r.height / 2 - (y - view.center.y) * view.scale) * dpr;
            return [...c.getContext('2d').getImageData(Math.round(sx), Math.round(sy), 1, 1).data];
          };
          const p = view.pose, k = view.radius * 0.5;
          return { robot: at(p.x - k, p.y - k), empty: at(p.x - 0.5, p.y - 0.7) };
        }"""
    )
    r, g, b, _ = colours["robot"]
    assert g > r + 30 and g > b + 15, colours  # green footprint
    assert colours["empty"][:3] == [251, 251, 248], colours  # the view's background
    assert counts["scan"] > 50, counts
    # the scan points lie on the walls: every point within 5 cm of some wall segment
    far = await page.evaluate(
        """() => {
          const { view } = window.simbridge;
          const dist = (p, [x1, y1, x2, y2]) => {
            const dx = x2 - x1, dy = y2 - y1;
            const u = ((p[0] - x1) * dx + (p[1] - y1) * dy) / (dx * dx + dy * dy || 1);
            const t = Math.max(0, Math.min(1, u));
            return Math.hypot(p[0] - x1 - t * dx, p[1] - y1 - t * dy);
          };
          const near = (p) => Math.min(...view.walls.map((w) => dist(p, w)));
          const pts = [];
          const s = view.scan;  // flat: x0, y0, x1, y1, ...
          for (let i = 0; i + 1 < s.length; i += 2) pts.push([s[i], s[i + 1]]);
          return pts.filter((p) => near(p) > 0.05).length;
        }"""
    )
    assert far == 0


async def count_cmd_vel(watcher: Watcher) -> int:
    return len(watcher.history.get("/cmd_vel", []))


async def test_holding_up_moves_robot_and_releasing_sends_one_zero(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """Up held: /cmd_vel at a fixed rate, the robot drives; released: one zero, then silence."""
    await watcher.subscribe("/cmd_vel", "geometry_msgs/msg/Twist")
    page, log = await open_connected(open_page, app)
    assert await page.evaluate("window.simbridge.cmdVel.type") == "geometry_msgs/msg/Twist"
    x0 = watcher.odom()["x"]  # type: ignore[index]
    await page.keyboard.down("ArrowUp")
    for _ in range(5):  # OS auto-repeat: further keydowns with repeat=true change nothing
        await page.keyboard.down("ArrowUp")
    await watcher.wait(lambda: watcher.odom()["x"] > x0 + 0.3)  # type: ignore[index]
    assert watcher.odom()["v"] == pytest.approx(0.3)  # type: ignore[index]
    await screenshot(page, "teleop-driving")
    await page.keyboard.up("ArrowUp")
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    cmds = [m for _, m in watcher.history["/cmd_vel"]]
    assert cmds[-1]["linear"]["x"] == 0.0
    assert all(m["linear"]["x"] == pytest.approx(0.3) for m in cmds[:-1])
    # the fixed rate, robust to arrival jitter: the median gap between held commands
    times = [t for t, _ in watcher.history["/cmd_vel"][:-1]]
    gap = statistics.median(b - a for a, b in itertools.pairwise(times))
    assert 0.07 < gap < 0.14, f"published every {gap * 1000:.0f} ms while held, expected 100"
    n = await count_cmd_vel(watcher)
    x1 = watcher.odom()["x"]  # type: ignore[index]
    await page.wait_for_timeout(500)  # silence after the one zero: nothing may arrive
    assert await count_cmd_vel(watcher) == n
    assert watcher.odom()["x"] == x1  # type: ignore[index]
    assert log.errors == []


async def test_focus_loss_stops_a_held_key(app: App, open_page: OpenPage, watcher: Watcher) -> None:
    """A key held while the window loses focus (no keyup ever comes) still ends in a zero."""
    page, _ = await open_connected(open_page, app)
    await page.keyboard.down("KeyA")  # turn left
    await watcher.wait(lambda: watcher.odom()["w"] > 0)  # type: ignore[index]
    await page.evaluate("window.dispatchEvent(new Event('blur'))")
    await watcher.wait(lambda: watcher.odom()["w"] == 0.0)  # type: ignore[index]


async def test_estop_halts_latches_ignores_commands_until_reset(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """Space latches the server's e-stop: halted at once; /cmd_vel from anyone is ignored."""
    await watcher.subscribe("/estop/state", "std_msgs/msg/Bool")
    page, _ = await open_connected(open_page, app)
    await page.keyboard.down("KeyW")
    await watcher.wait(lambda: watcher.odom()["v"] > 0)  # type: ignore[index]
    await page.keyboard.press("Space")
    await watcher.wait(lambda: watcher.latest.get("/estop/state", {}).get("data") is True)
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    await page.wait_for_selector("#estopBanner", state="visible")
    assert app.world.estopped
    # another client commands the robot: ignored while latched
    await watcher.conn.send(
        '{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":0.4},"angular":{"z":1.0}}}'
    )
    await page.keyboard.up("KeyW")
    await page.keyboard.down("KeyW")  # and the page's own keys are disabled
    steps = app.world.steps
    pose = watcher.odom()
    await wait_for(lambda: app.world.steps >= steps + 10)
    now = watcher.odom()
    assert (now["x"], now["y"], now["theta"]) == (pose["x"], pose["y"], pose["theta"])  # type: ignore[index]
    await page.keyboard.up("KeyW")
    await screenshot(page, "estop-latched")
    # only an explicit reset releases it
    await page.click("#release")
    await watcher.wait(lambda: watcher.latest["/estop/state"]["data"] is False)
    await page.wait_for_selector("#estopBanner", state="hidden")
    await watcher.conn.send(
        '{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":0.2},"angular":{"z":0.0}}}'
    )
    await watcher.wait(lambda: watcher.odom()["v"] == pytest.approx(0.2))  # type: ignore[index]


async def test_pid_lab_settles_a_90_degree_heading_step(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """Heading PID at 10 Hz in the page: a 90 deg step settles within +-2 deg, shown settled."""
    page, _ = await open_connected(open_page, app)
    await page.click("button[data-tab=pid]")
    await page.fill("#spTheta", "90")
    await page.fill("#kp", "3")
    await page.fill("#ki", "0.1")
    await page.fill("#kd", "0.05")
    await page.click("#pidStart")
    target = math.pi / 2
    tolerance = math.radians(2)

    def settled() -> bool:
        o = watcher.odom()
        return o is not None and abs(o["theta"] - target) < tolerance and abs(o["w"]) < 0.05

    await watcher.wait(settled, timeout=8)
    await page.wait_for_function(
        "window.simbridge.lab.figures().settlingTime !== null"
        " && window.simbridge.plots.step.marks.length > 0"
    )
    figures = await page.evaluate("window.simbridge.lab.figures()")
    # a 90 deg step at <= 2.5 rad/s takes > 0.6 s; the 2 % band of 90 deg is 1.8 deg
    assert 0.6 < figures["settlingTime"] < 6
    assert 0 <= figures["overshootPct"] < 20
    assert figures["band"] == pytest.approx(math.radians(1.8))
    assert abs(figures["error"]) < tolerance
    text = await page.text_content("#pidFigures")
    assert "overshoot" in text and "settling" in text  # type: ignore[operator]
    example = await page.text_content("#example")
    assert "class PID" in example and "update(error, dt)" in example  # type: ignore[operator]
    await screenshot(page, "pid-heading-step")
    # the step response exports for a lab report: CSV of every sample, and a PNG
    rows = (await page.evaluate("window.simbridge.plots.step.csv()")).splitlines()
    assert rows[0] == "t_s,command,setpoint (deg),measured (deg)"
    last = [float(v) for v in rows[-1].split(",")]
    assert len(rows) > 10 and last[2] == pytest.approx(90, abs=0.01)
    assert abs(last[3] - 90) < 2
    png = await page.evaluate("window.simbridge.plots.step.png()")
    assert png.startswith("data:image/png;base64,") and len(png) > 2000
    await page.click("#pidStop")
    await watcher.wait(lambda: watcher.odom()["w"] == 0.0)  # type: ignore[index]
    assert abs(watcher.odom()["theta"] - target) < tolerance  # type: ignore[index]


async def test_phone_viewport_touch_joystick_and_estop(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """A 390x844 touch phone: e-stop in view, 44 px targets, the joystick drives and stops."""
    page, log = await open_connected(
        open_page,
        app,
        viewport={"width": 390, "height": 844},
        device_scale_factor=3,
        is_mobile=True,
        has_touch=True,
    )
    small = await page.evaluate(
        """() => [...document.querySelectorAll('button, select, input')]
            .filter((el) => el.offsetParent !== null)
            .map((el) => [el.id || el.textContent.trim(), el.getBoundingClientRect()])
            .filter(([, r]) => r.width < 44 || r.height < 44)
            .map(([name, r]) => `${name}: ${r.width}x${r.height}`)"""
    )
    assert small == []
    box = await page.locator("#estop").bounding_box()
    assert box is not None and box["y"] + box["height"] <= 844 and box["x"] + box["width"] <= 390
    touch = await page.evaluate(
        "['view', 'joystick']"
        ".map((id) => getComputedStyle(document.getElementById(id)).touchAction)"
    )
    assert touch == ["none", "none"]
    # the view is crisp: its backing store uses the device pixel ratio
    ratio = await page.evaluate(
        "(() => { const c = document.getElementById('view');"
        " return c.width / c.getBoundingClientRect().width; })()"
    )
    assert ratio == pytest.approx(3, abs=0.05)
    await page.locator("#joystick").scroll_into_view_if_needed()
    pad = await page.locator("#joystick").bounding_box()
    assert pad is not None
    cx, cy = pad["x"] + pad["width"] / 2, pad["y"] + pad["height"] / 2
    cdp = await page.context.new_cdp_session(page)

    async def touch_event(kind: str, x: float, y: float) -> None:
        points = [] if kind == "touchEnd" else [{"x": x, "y": y}]
        await cdp.send("Input.dispatchTouchEvent", {"type": kind, "touchPoints": points})

    await touch_event("touchStart", cx, cy)
    await touch_event("touchMove", cx, cy - pad["height"] * 0.45)  # push up: forward
    await watcher.wait(lambda: watcher.odom()["v"] > 0.1)  # type: ignore[index]
    await screenshot(page, "phone-joystick")
    await touch_event("touchEnd", cx, cy)
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    await page.tap("#estop")
    await wait_for(lambda: app.world.estopped, timeout=5)
    await page.wait_for_selector("#estopBanner", state="visible")
    await screenshot(page, "phone-estop")
    assert log.errors == []


async def test_page_reconnects_with_backoff_and_resubscribes(
    make_app: AppFactory, open_page: OpenPage
) -> None:
    """Server gone: 'reconnecting' shows; server back on the same port: data flows again."""
    first = await make_app()
    port = first.ws_port
    page, log = await open_connected(open_page, first)
    await first.stop()
    await page.wait_for_function("window.simbridge.conn.state === 'reconnecting'")
    assert (await page.text_content("#statusText")).startswith("reconnecting")  # type: ignore[union-attr]
    await screenshot(page, "reconnecting")
    second = await make_app(port=port)
    second.world.robots[""].place((1.0, 0.5, 0.0))  # tell the two servers' odometry apart
    await page.wait_for_function(
        "window.simbridge.conn.connected && window.simbridge.state.pose"
        " && Math.abs(window.simbridge.state.pose.x - 1.0) < 1e-9",
        timeout=20_000,
    )
    await page.wait_for_function("window.simbridge.view.scan.length > 0")
    assert await page.text_content("#statusText") == "connected"
    # the browser logs the refused connection attempts itself (the socket's, and the fetch of
    # /api/access with which the page asks a server that did not answer why); nothing else
    refused = ("WebSocket connection", "net::ERR_CONNECTION_REFUSED")
    assert [e for e in log.errors if not any(r in e for r in refused)] == []


async def test_hidden_tab_and_page_hide_each_end_in_a_zero(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    page, _ = await open_connected(open_page, app)
    await page.keyboard.down("ArrowLeft")
    await watcher.wait(lambda: watcher.odom()["w"] > 0)  # type: ignore[index]
    await page.evaluate(
        "Object.defineProperty(document, 'hidden', { value: true, configurable: true });"
        "document.dispatchEvent(new Event('visibilitychange'))"
    )
    await watcher.wait(lambda: watcher.odom()["w"] == 0.0)  # type: ignore[index]
    await page.keyboard.up("ArrowLeft")
    await page.evaluate("delete document.hidden")
    await page.keyboard.down("ArrowDown")
    await watcher.wait(lambda: watcher.odom()["v"] < 0)  # type: ignore[index]
    await page.evaluate("window.dispatchEvent(new Event('pagehide'))")
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]


async def test_gamepad_drives_only_while_the_deadman_is_held(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """A (simulated) standard gamepad: stick alone does nothing; LB + stick drives; LB up stops."""
    page, _ = await open_connected(open_page, app)
    await page.evaluate(
        """() => {
          const button = () => ({ pressed: false, value: 0 });
          window.fakePad = { id: 'test pad', axes: [0, 0, 0, 0],
                             buttons: Array.from({ length: 16 }, button) };
          navigator.getGamepads = () => [window.fakePad];
          window.dispatchEvent(new Event('gamepadconnected'));
        }"""
    )
    await page.evaluate("window.fakePad.axes[1] = -1")  # stick forward, no deadman
    await page.wait_for_function(
        "document.getElementById('gamepad').textContent.includes('hold LB/RB')"
    )
    assert watcher.odom()["v"] == 0.0  # type: ignore[index]
    await page.evaluate("window.fakePad.buttons[4].pressed = true")
    await watcher.wait(lambda: watcher.odom()["v"] > 0.2)  # type: ignore[index]
    await page.evaluate("window.fakePad.buttons[4].pressed = false")
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]


async def test_plots_status_rates_and_view_pan_zoom_follow(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """Plots fill with commanded and measured values; status shows rates; the view pans/zooms."""
    page, _ = await open_connected(open_page, app)
    await page.click("button[data-tab=plots]")
    await page.keyboard.down("KeyD")  # turn right
    await watcher.wait(lambda: watcher.odom()["w"] < -1.0)  # type: ignore[index]
    await page.wait_for_function(
        "window.simbridge.plots.w.latest(0) === -1.5 && window.simbridge.plots.w.latest(1) === -1.5"
    )
    await page.keyboard.up("KeyD")
    await page.wait_for_function("window.simbridge.plots.range.latest(0) > 0.1")
    await page.wait_for_function("window.simbridge.plots.w.latest(1) === 0")
    # published at 20 Hz; the page's rate is measured on its own receive times, which a loaded
    # machine delays for a moment: wait (bounded) for a reading in range rather than one sample
    await page.wait_for_function(
        "(() => { const r = window.simbridge.conn.rates().find((x) => x.name === '/odom');"
        " return r !== undefined && r.rate > 12 && r.rate < 25; })()"
    )
    await page.wait_for_function(  # the status line is refreshed twice a second
        "/odom 1[0-9]|odom 2[0-9]/.test(document.getElementById('statusInfo').textContent)"
    )
    await screenshot(page, "plots")
    # pan: dragging the view turns follow off and moves the centre
    view = page.locator("#view")
    box = await view.bounding_box()
    assert box is not None
    before = await page.evaluate("({...window.simbridge.view.center})")
    await page.mouse.move(box["x"] + 200, box["y"] + 200)
    await page.mouse.down()
    await page.mouse.move(box["x"] + 300, box["y"] + 250, steps=5)
    await page.mouse.up()
    after = await page.evaluate("({...window.simbridge.view.center})")
    scale = await page.evaluate("window.simbridge.view.scale")
    assert after["x"] == pytest.approx(before["x"] - 100 / scale, abs=1e-6)
    assert after["y"] == pytest.approx(before["y"] + 50 / scale, abs=1e-6)
    await page.mouse.wheel(0, -300)
    await page.wait_for_function(f"window.simbridge.view.scale > {scale * 1.2}")
    await page.click("#follow")
    assert await page.get_attribute("#follow", "aria-pressed") == "true"
    pose = await page.evaluate("window.simbridge.state.pose")
    centre = await page.evaluate("window.simbridge.view.center")
    assert (centre["x"], centre["y"]) == pytest.approx((pose["x"], pose["y"]))


async def test_robot_selector_lists_namespaced_robots_and_drives_the_chosen_one(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    page, _ = await open_connected(open_page, app)
    spawn = {
        "op": "call_service",
        "service": "/spawn",
        "args": {"x": 1.0, "y": -1.0, "theta": 0.0, "name": "r1"},
    }
    await watcher.conn.send(json.dumps(spawn))
    await watcher.subscribe("/r1/odom", "nav_msgs/msg/Odometry")
    await page.wait_for_function(
        "[...document.getElementById('robot').options].some((o) => o.value === 'r1')",
        timeout=10_000,
    )
    assert await page.input_value("#robot") == ""  # the default robot stays selected
    await page.select_option("#robot", "r1")
    await page.wait_for_function(
        "window.simbridge.state.pose && Math.abs(window.simbridge.state.pose.x - 1.0) < 1e-6"
    )
    await page.focus("#view")
    await page.keyboard.down("ArrowUp")
    await watcher.wait(
        lambda: (
            watcher.latest.get("/r1/odom", {})
            .get("twist", {})
            .get("twist", {})
            .get("linear", {})
            .get("x", 0)
            > 0
        )
    )
    assert watcher.odom()["v"] == 0.0  # type: ignore[index]  # the default robot stays put
    await page.wait_for_function("window.simbridge.view.others.has('')")  # drawn in grey
    await page.keyboard.up("ArrowUp")
    await watcher.wait(lambda: watcher.latest["/r1/odom"]["twist"]["twist"]["linear"]["x"] == 0)
    await screenshot(page, "robot-r1")


async def test_pid_lab_position_mode_reaches_a_goal_1_m_ahead(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """Position control: goal 1 m ahead is reached within 2 cm and held, then Stop sends zero."""
    page, _ = await open_connected(open_page, app)
    await page.click("button[data-tab=pid]")
    await page.select_option("#pidMode", "position")
    await page.fill("#spX", "1.0")
    await page.fill("#spY", "0.0")
    await page.fill("#kp", "1.5")
    await page.fill("#ki", "0")
    await page.fill("#kd", "0")
    assert "goal = { x: 1.00, y: 0.00 }" in (await page.text_content("#example") or "")
    await page.click("#pidStart")

    def arrived() -> bool:
        o = watcher.odom()
        return o is not None and math.hypot(o["x"] - 1.0, o["y"]) < 0.02 and abs(o["v"]) < 0.02

    await watcher.wait(arrived, timeout=10)
    await page.wait_for_function("window.simbridge.lab.figures().settlingTime !== null")
    await screenshot(page, "pid-position-step")
    await page.click("#pidStop")
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]


async def test_pid_lab_stops_with_one_zero_on_blur_hidden_tab_and_page_hide(
    app: App, open_page: OpenPage, watcher: Watcher
) -> None:
    """A position step at full speed: each way of leaving the page stops the robot at once."""
    page, _ = await open_connected(open_page, app)
    await page.click("button[data-tab=pid]")
    await page.select_option("#pidMode", "position")
    await page.fill("#spY", "0.0")
    await page.fill("#kp", "3")
    hide = "Object.defineProperty(document, 'hidden', { value: true, configurable: true });"
    leaving = {
        "window.dispatchEvent(new Event('blur'))": "the window lost focus",
        f"{hide} document.dispatchEvent(new Event('visibilitychange'))": "the tab was hidden",
        "window.dispatchEvent(new Event('pagehide'))": "the page was left",
    }
    await page.fill("#spX", "2.0")
    for event, why in leaving.items():
        app.world.reset()  # back to x = 0, facing the goal 2 m ahead
        await watcher.wait(lambda: watcher.odom()["x"] == 0.0)  # type: ignore[index]
        await page.click("#pidStart")
        await watcher.wait(lambda: watcher.odom()["v"] == pytest.approx(0.5))  # type: ignore[index]
        await page.evaluate(event)
        await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
        assert watcher.odom()["x"] < 1.5  # type: ignore[index]
        assert not await page.evaluate("window.simbridge.lab.running")
        assert why in (await page.text_content("#pidFigures") or "")
        await page.evaluate("delete document.hidden")


async def test_a_killed_browser_leaves_no_robot_driving(
    app: App, browser: Browser, open_page: OpenPage, watcher: Watcher
) -> None:
    """Killed with a key held: no keyup, no page hide, no zero, no close frame.

    The server finds the link lost and stops the robot (``safety.stop_on_lost_link``, on by
    default); without it the robot would keep the page's last command.
    """
    page, _ = await open_connected(open_page, app)
    await page.keyboard.down("ArrowUp")
    await watcher.wait(lambda: watcher.odom()["v"] > 0)  # type: ignore[index]
    (chromium,) = [
        p
        for p in psutil.Process().children(recursive=True)
        if p.name() == "chromium" and not any(a.startswith("--type=") for a in p.cmdline())
    ]
    for process in [chromium, *chromium.children(recursive=True)]:  # its network service too
        process.kill()  # SIGKILL: the browser says nothing more
    await watcher.wait(lambda: watcher.odom()["v"] == 0.0)  # type: ignore[index]
    assert app.safety.stops == 1


LAYOUT_CHECK = """async () => {
  const box = (el) => el.getBoundingClientRect();
  const stop = () => box(document.getElementById('estop'));
  const covered = [], wrapped = [];
  const parts = 'button, input, select, output, .u-legend, .uplot canvas, .figures, summary';
  for (const details of document.querySelectorAll('.panel details')) details.open = true;
  for (const tab of document.querySelectorAll('.tabs button')) {
    tab.click();
    const range = document.createRange();
    range.selectNodeContents(tab);
    if (range.getClientRects().length !== 1) wrapped.push(`tab ${tab.textContent}`);
    for (const el of document.querySelectorAll(`.panel .tab:not([hidden]) :is(${parts})`)) {
      if (!el.checkVisibility()) continue;
      el.scrollIntoView({ block: 'nearest' });  // as a student scrolls to it
      const s = box(el), t = stop();
      if (s.bottom > t.top + 1 && s.top < t.bottom - 1 && s.right > t.left && s.left < t.right) {
        covered.push(`${tab.textContent}: ${el.id || el.className || el.textContent}`);
      }
    }
    for (const bar of document.querySelectorAll('.panel .tab:not([hidden]) .plotbar')) {
      const tops = [...bar.querySelectorAll('button')].map((b) => Math.round(box(b).top));
      const rows = new Set(tops).size;
      if (rows > 1) wrapped.push(`${bar.textContent}: buttons on ${rows} rows`);
    }
  }
  document.querySelector('.tabs button[data-tab=plots]').click();
  // a residual 1e-4 rad/s: the axis must neither read "0" twice nor blow the residual up
  const w = window.simbridge.plots.w;
  w.clear();
  for (let k = 0; k < 40; k++) w.push(k * 0.05, [0, k % 2 ? 0.0002 : -0.0001]);
  w.draw();
  const { tickLabels } = await import('./js/plots.js');
  const ticks = tickLabels([-0.0002, -0.0001, 0, 0.0001, 0.0002]);
  return { covered, wrapped, labels: w.u.axes[1]._values, ticks };
}"""


@pytest.mark.parametrize(
    "context",
    [
        {"viewport": {"width": 1280, "height": 800}},
        {"viewport": {"width": 390, "height": 844}, "is_mobile": True, "has_touch": True},
    ],
    ids=["1280x800", "phone"],
)
async def test_no_plot_legend_or_control_is_under_stop_and_plots_read_clearly(
    app: App, open_page: OpenPage, context: dict[str, Any]
) -> None:
    """Every tab scrolled through: nothing under STOP, one-line tabs, plot bars on one row."""
    page, log = await open_connected(open_page, app, **context)
    await page.wait_for_timeout(300)  # the plots have their size
    found = await page.evaluate(LAYOUT_CHECK)
    assert found["covered"] == [] and found["wrapped"] == [], found
    labels = found["labels"]
    assert len(set(labels)) == len(labels) and len(labels) <= 5, labels
    assert found["ticks"] == ["-0.0002", "-0.0001", "0.0000", "0.0001", "0.0002"]
    assert log.errors == []


async def test_the_readmes_page_works_saved_to_disk(
    app: App, browser: Browser, watcher: Watcher, tmp_path: Any
) -> None:
    """The README's roslibjs page, opened from a file as a student would: the robot drives."""
    readme = (ROOT / "README.md").read_text()
    html = readme.split("```html\n", 1)[1].split("```", 1)[0]
    assert "127.0.0.1:8080" in html and "127.0.0.1:9090" in html
    html = html.replace("127.0.0.1:8080", f"127.0.0.1:{app.http_port}")
    html = html.replace("127.0.0.1:9090", f"127.0.0.1:{app.ws_port}")
    (tmp_path / "my_page.html").write_text(html)
    ctx = await browser.new_context()
    page = await ctx.new_page()
    logged: list[str] = []
    page.on("console", lambda msg: logged.append(msg.text))
    await page.goto(f"file://{tmp_path}/my_page.html")
    await watcher.wait(lambda: watcher.odom()["w"] == pytest.approx(0.5))  # type: ignore[index]
    await wait_for(lambda: bool(logged), timeout=5)
    assert all(len(line.split()) == 2 for line in logged), logged  # "x y"
    await ctx.close()  # the page goes: its link is lost, the robot stops
    await watcher.wait(lambda: watcher.odom()["w"] == 0.0)  # type: ignore[index]
