"""A class of students on one server (issue 13), in headless Debian chromium.

One real simbridge (the classroom world, three client tokens and an admin token) and one
browser are shared by the module's tests (each test opens its own pages): three student pages
with three tokens and the instructor's /admin. What the robots do is checked on the server's
topics through a separate rosbridge client, not through the pages.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import itertools
import math
import re
import signal
import subprocess
import sys
from collections.abc import AsyncIterator
from typing import Any

import pytest
import pytest_asyncio
from playwright.async_api import Browser, BrowserContext, Page, async_playwright
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from tests.browser.conftest import CHROMIUM, FLAGS, PageLog, Watcher, screenshot
from tests.helpers import ROOT, TIMEOUT_FACTOR, http_url, wait_for, ws_url


pytestmark = [pytest.mark.e2e, pytest.mark.asyncio(loop_scope="module")]

CLASSROOM = ROOT / "config" / "worlds" / "classroom.yaml"
TOKENS = {"alice-token-r1": "r1", "bob-token-r2x": "r2", "carol-token-r3": "r3"}
STUDENTS = dict(zip(("r1", "r2", "r3"), TOKENS, strict=True))
ADMIN = "teacher-secret-77"


def network_noise(text: str) -> bool:
    """The browser's own reports of a failed connection (not errors of the page's code)."""
    return "WebSocket connection" in text or "net::ERR" in text or "Failed to load resource" in text


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def app() -> AsyncIterator[App]:
    settings = ServerSettings(
        host="127.0.0.1", port=0, http_port=0, client_tokens=TOKENS, admin_token=ADMIN
    )
    server = App(settings, world=CLASSROOM)
    await server.start()
    yield server
    await server.stop()


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def browser() -> AsyncIterator[Browser]:
    async with async_playwright() as pw:
        b = await pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS, headless=True)
        yield b
        await b.close()


@pytest_asyncio.fixture(loop_scope="module")
async def contexts(browser: Browser) -> AsyncIterator[list[BrowserContext]]:
    """Contexts opened by a test (closed after it)."""
    opened: list[BrowserContext] = []
    yield opened
    for ctx in opened:
        with contextlib.suppress(Exception):
            await ctx.close()


async def open_page(
    browser: Browser, contexts: list[BrowserContext], url: str, **options: Any
) -> tuple[Page, PageLog]:
    ctx = await browser.new_context(**options)
    contexts.append(ctx)
    page = await ctx.new_page()
    log = PageLog()
    page.on("console", lambda m: log.errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda err: log.errors.append(f"uncaught: {err}"))
    page.set_default_timeout(15_000 * TIMEOUT_FACTOR)
    await page.goto(url)
    return page, log


async def student(
    app: App, browser: Browser, contexts: list[BrowserContext], robot: str, **options: Any
) -> tuple[Page, PageLog]:
    """A student's page, opened as the instructor hands it out (token in the link, no ?url=)."""
    url = f"{http_url(app)}/?token={STUDENTS[robot]}"
    page, log = await open_page(browser, contexts, url, **options)
    await page.wait_for_function(
        "(r) => window.simbridge && window.simbridge.state.ns === r"
        " && window.simbridge.state.pose !== null && window.simbridge.cmdVel.ready",
        arg=robot,
    )
    return page, log


async def admin_console(app: App, browser: Browser, contexts: list[BrowserContext]) -> Page:
    page, _ = await open_page(browser, contexts, f"{http_url(app)}/admin")
    await page.fill("#token", ADMIN)
    await page.click("#tokenForm button")
    await page.wait_for_selector("#console", state="visible")
    return page


@contextlib.asynccontextmanager
async def watching(app: App, *topics: tuple[str, str]) -> AsyncIterator[Watcher]:
    async with connect(f"{ws_url(app)}/?token={ADMIN}", max_size=None) as conn:
        w = Watcher(conn)
        for name, type_name in topics:
            await w.subscribe(name, type_name)
        try:
            yield w
        finally:
            w.task.cancel()


def speed(w: Watcher, robot: str) -> float:
    m = w.latest.get(f"/{robot}/odom")
    return math.nan if m is None else float(m["twist"]["twist"]["linear"]["x"])


async def release_everything(app: App) -> None:
    for latch_id in list(app.estop.latches):
        app.estop.release_latch(latch_id)
    app.world.reset()


async def test_each_student_lands_on_their_own_robot_without_admin_controls_or_token(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    for robot, token in STUDENTS.items():
        page, log = await student(app, browser, contexts, robot)
        assert await page.is_hidden("#reset") and await page.is_hidden("#spawnForm")
        assert await page.text_content("#role") == f"your robot: {robot}"
        # the token is nowhere a projector would show it: text, URL field, address bar
        text = await page.evaluate("document.body.innerText")
        assert token not in text and token not in page.url
        assert token not in await page.input_value("#url")
        assert await page.get_attribute("#token", "type") == "password"
        assert await page.text_content("#statusText") == "connected"
        assert await page.evaluate("window.simbridge.conn.url") == ws_url(app)  # asked, not 9090
        # the PID lab's example to copy drives their robot on this server, token left for them
        example = await page.text_content("#example") or ""
        assert f"name: '/{robot}/cmd_vel'" in example and f"name: '/{robot}/odom'" in example
        assert f"url: \"{ws_url(app)}\" + '?token=' + encodeURIComponent(TOKEN)" in example
        assert "const TOKEN = 'YOUR_TOKEN';" in example and token not in example
        await screenshot(page, f"class-student-{robot}")
        assert log.errors == []
    # nothing moves: the view is not redrawn (the plots are not shown); it was 20 times a
    # second. At most a frame or two: a loaded machine may delay /odom past the stale mark.
    frames = await page.evaluate("window.simbridge.view.frames")
    await asyncio.sleep(1.0)
    assert await page.evaluate("window.simbridge.view.frames") - frames <= 2
    console = await admin_console(app, browser, contexts)
    await console.wait_for_function(
        "['r1', 'r2', 'r3'].every((r) =>"
        " document.getElementById('clients').textContent.includes(r + \"'s token\"))"
    )
    # a heavier robot for one group: set where the instructor clicks, shown on that student's page
    await console.select_option("#robotPick", "r3")
    await console.fill("#robotParams input[name='robot.mass']", "3")
    await console.click("#robotForm button[type=submit]")
    await console.wait_for_function(
        "document.getElementById('robotMsg').textContent === 'Robot r3: robot.mass = 3.'"
    )
    assert app.world.robot_params("r3").mass == 3.0 and app.world.robot_params("r1").mass == 1.5
    await page.wait_for_function(  # carol's page (r3), refreshed every 3 s
        "document.getElementById('robotInfo').textContent.includes('mass 3 kg (this robot')",
        timeout=10_000 * TIMEOUT_FACTOR,
    )
    await screenshot(console, "class-admin", full_page=True)
    app.world.set_robot_params("r3", {"mass": None})


async def test_a_students_estop_stops_only_their_robot_and_they_release_it(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    alice, alice_log = await student(app, browser, contexts, "r1")
    bob, _ = await student(app, browser, contexts, "r2")
    topics = [(f"/{r}/odom", "nav_msgs/msg/Odometry") for r in ("r1", "r2")]
    async with watching(app, *topics) as w:
        for page in (alice, bob):
            await page.locator("#view").click()
            await page.keyboard.down("KeyA")  # turn on the spot: never reaches a wall
            await page.keyboard.down("KeyW")
        await w.wait(lambda: speed(w, "r1") > 0.25 and speed(w, "r2") > 0.25)
        await alice.focus("#speedV")  # Space works wherever the focus is (a slider here)
        await alice.keyboard.press("Space")
        await w.wait(lambda: speed(w, "r1") == 0.0)
        await alice.wait_for_selector("#estopBanner", state="visible")
        assert "held by client" in (await alice.text_content("#estopText") or "")
        await asyncio.sleep(0.3)  # bob drives on, unaffected
        await w.wait(lambda: speed(w, "r2") > 0.25)
        assert not app.world.halted("r2")
        assert await bob.is_hidden("#estopBanner")
        await screenshot(alice, "class-estop-own-robot")
        for page in (alice, bob):
            await page.keyboard.up("KeyW")
            await page.keyboard.up("KeyA")
        await alice.click("#release")
        await alice.wait_for_selector("#estopBanner", state="hidden")
        assert not app.world.halted("r1")
    assert alice_log.errors == []


async def test_a_students_copied_pid_example_with_their_token_drives_their_robot(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    """The PID lab's example, copied with the student's token filled in, drives their robot.

    Run in a page of their own, it connects to this server and takes r2 to the goal; r1 stays.
    """
    bob, _ = await student(app, browser, contexts, "r2")
    await bob.click("button[data-tab=pid]")
    await bob.select_option("#pidMode", "position")  # goal (1.0, 0.0) from r2's (2.0, -1.0)
    example = await bob.text_content("#example") or ""
    code = example.replace("'YOUR_TOKEN'", repr(STUDENTS["r2"]))
    theirs, log = await open_page(browser, contexts, f"{http_url(app)}/healthz")
    await theirs.set_content(f'<script src="{http_url(app)}/vendor/roslib.min.js"></script>')
    await theirs.wait_for_function("typeof ROSLIB !== 'undefined'")
    await theirs.evaluate("(code) => new Function(code)()", code)
    robots = app.world.robots
    r1 = (robots["r1"].state.x, robots["r1"].state.y)
    try:
        await wait_for(
            lambda: math.hypot(robots["r2"].state.x - 1.0, robots["r2"].state.y) < 0.07,
            timeout=20 * TIMEOUT_FACTOR,
        )
        assert (robots["r1"].state.x, robots["r1"].state.y) == r1
    finally:
        await theirs.context.close()
        await release_everything(app)
    assert [e for e in log.errors if not network_noise(e)] == []  # its /favicon.ico is a 404


async def test_contacts_are_drawn_and_put_my_robot_back_teleports_to_the_start(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    alice, log = await student(app, browser, contexts, "r1")
    app.world.teleport("r1", (-0.6, 0.0, 0.0))  # facing the box in the middle, 0.3 m away
    await alice.locator("#view").click()
    await alice.keyboard.down("KeyW")
    await alice.wait_for_function("window.simbridge.view.contacts > 0")
    await alice.wait_for_function("window.simbridge.view.contact !== null")
    await screenshot(alice, "class-contact")
    await alice.keyboard.up("KeyW")
    await alice.click("#putBack")
    await wait_for(lambda: app.world.robots["r1"].state.x == -2.0, timeout=5)
    s = app.world.robots["r1"].state
    assert (s.x, s.y, s.theta) == (-2.0, -1.0, 0.0)
    assert log.errors == []


async def test_admin_releases_a_global_estop_students_cannot(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    carol, log = await student(app, browser, contexts, "r3")
    console = await admin_console(app, browser, contexts)
    await console.click("#estopAll")
    await console.wait_for_function(
        "document.getElementById('estopMsg').textContent.startsWith('Every robot is stopped')"
    )
    assert all(app.world.halted(r) for r in app.world.robots)
    await carol.wait_for_selector("#estopBanner", state="visible")
    await carol.wait_for_function(
        "document.getElementById('estopText').textContent.includes('the instructor')"
    )
    assert await carol.is_hidden("#release")  # not hers to release
    await screenshot(carol, "class-estop-global-student")
    await console.wait_for_selector("#estops button[data-latch]")
    await screenshot(console, "class-estop-global-admin", full_page=True)
    await console.click("#estops button[data-latch]")
    await console.wait_for_function(
        "document.getElementById('estopMsg').textContent.startsWith('Released')"
    )
    assert not any(app.world.halted(r) for r in app.world.robots)
    await carol.wait_for_selector("#estopBanner", state="hidden")
    assert log.errors == []


async def test_spawn_keeps_every_robot_drawn(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    url = f"{http_url(app)}/?url={ws_url(app)}&token={ADMIN}"
    page, log = await open_page(browser, contexts, url)
    await page.wait_for_function("window.simbridge && window.simbridge.state.ns === 'r1'")
    assert await page.is_visible("#spawnForm") and await page.is_visible("#reset")
    await page.fill("#spawnName", "extra")
    await page.click("#spawnForm button")
    await page.wait_for_function(
        "window.simbridge.state.ns === 'extra' && window.simbridge.view.pose"
    )
    # the robot left behind and every other one are drawn
    await page.wait_for_function(
        "['r1', 'r2', 'r3', 'r4'].every((r) => window.simbridge.view.others.has(r))"
    )
    await screenshot(page, "class-spawned")
    assert log.errors == []
    app.world.remove("extra")
    app.bridge.remove_robot("extra")


async def test_a_refused_token_and_a_dead_server_each_say_so(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    page, log = await open_page(
        browser, contexts, f"{http_url(app)}/?url={ws_url(app)}&token=not-a-real-token"
    )
    await page.wait_for_function("window.simbridge && window.simbridge.conn.state === 'refused'")
    assert "refused this token" in (await page.text_content("#statusInfo") or "")
    assert await page.text_content("#statusText") == "token refused"
    await screenshot(page, "class-token-refused")
    with socket_closed_port() as port:
        dead, dead_log = await open_page(
            browser, contexts, f"{http_url(app)}/?url=ws://127.0.0.1:{port}"
        )
        await dead.wait_for_function(
            "document.getElementById('statusInfo').textContent.includes('no server answers')"
        )
        assert (await dead.text_content("#statusText") or "").startswith("reconnecting")
        await screenshot(dead, "class-dead-server")
    # no token where one is needed: connected, but told to enter one
    none, _ = await open_page(browser, contexts, f"{http_url(app)}/?url={ws_url(app)}")
    await none.wait_for_function("window.simbridge && window.simbridge.state.needsToken")
    await none.wait_for_function("window.simbridge.conn.state === 'disconnected'")  # no retry loop
    assert await none.text_content("#statusText") == "token needed"
    # a full server
    full = App(ServerSettings(host="127.0.0.1", port=0, http_port=0, max_clients=1))
    await full.start()
    try:
        async with connect(ws_url(full)):
            page_full, _ = await open_page(
                browser, contexts, f"{http_url(full)}/?url={ws_url(full)}"
            )
            await page_full.wait_for_function(
                "document.getElementById('statusInfo').textContent.includes('server is full')"
            )
            await screenshot(page_full, "class-server-full")
    finally:
        await full.stop()
    bad, _ = await open_page(browser, contexts, f"{http_url(app)}/?url=localhost:9090")
    await bad.wait_for_function("window.simbridge && window.simbridge.conn.state === 'badurl'")
    assert "ws://" in (await bad.text_content("#statusInfo") or "")
    errors = [e for e in log.errors + dead_log.errors if not network_noise(e)]
    assert errors == []


@contextlib.contextmanager
def socket_closed_port() -> Any:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        yield s.getsockname()[1]  # bound, not listening: connections are refused


async def test_plot_csv_rows_match_the_recorded_odom(
    app: App, browser: Browser, contexts: list[BrowserContext]
) -> None:
    page, log = await student(app, browser, contexts, "r2", accept_downloads=True)
    async with watching(app, ("/r2/odom", "nav_msgs/msg/Odometry")) as w:
        await page.click("button[data-tab=plots]")
        await page.locator("#view").click()
        await page.keyboard.down("KeyD")  # turn right: heading wraps past -180
        await w.wait(lambda: len(w.history.get("/r2/odom", [])) > 60, timeout=8)
        await page.keyboard.up("KeyD")
        await w.wait(lambda: speed(w, "r2") == 0.0)
        await asyncio.sleep(0.2)
        async with page.expect_download() as info:
            await page.click("#plotW .plotbar button:has-text('CSV')")
        download = await info.value
        text = (await download.path()).read_text()  # type: ignore[union-attr]
        async with page.expect_download() as png_info:
            await page.click("#plotHeading .plotbar button:has-text('PNG')")
        png = (await (await png_info.value).path()).read_bytes()  # type: ignore[union-attr]
        heading_csv = await page.evaluate("window.simbridge.plots.heading.csv()")
        await screenshot(page, "class-plots")
        # pause: the plot is frozen (no draw) while samples keep being recorded; Live resumes
        plot = "window.simbridge.plots.v"
        await page.click("#plotV .plotbar button:has-text('Pause')")
        draws, samples = await page.evaluate(f"[{plot}.draws, {plot}.xs.length]")
        await page.wait_for_function(f"{plot}.xs.length > {samples + 10}")
        assert await page.evaluate(f"{plot}.draws") == draws
        await page.click("#plotV .plotbar button:has-text('Live')")
        await page.wait_for_function(f"{plot}.draws > {draws}")
        # zoom: dragging across the plot selects a time span and stops following
        over = page.locator("#plotV .u-over")
        box = await over.bounding_box()
        assert box is not None
        await page.mouse.move(box["x"] + 0.3 * box["width"], box["y"] + 20)
        await page.mouse.down()
        await page.mouse.move(box["x"] + 0.6 * box["width"], box["y"] + 20, steps=4)
        await page.mouse.up()
        await page.wait_for_function(f"{plot}.zoomed")
        span = await page.evaluate(f"{plot}.u.scales.x.max - {plot}.u.scales.x.min")
        assert 0 < span < 20 * 0.5, span
        await page.dblclick("#plotV .u-over")
        await page.wait_for_function(f"!{plot}.zoomed")
        # the other robots' odometry comes throttled for the view (4 Hz, not 20)
        rate = await page.evaluate(
            "window.simbridge.conn.rates().find((r) => r.name === '/r1/odom').rate"
        )
        assert 1 < rate < 6, rate
    assert png.startswith(b"\x89PNG")
    recorded = {}
    for _, m in w.history["/r2/odom"]:
        s = m["header"]["stamp"]
        recorded[f"{s['sec']}.{s['nanosec']:09d}"] = m
    rows = list(csv.DictReader(io.StringIO(text)))
    assert list(rows[0]) == ["t_s", "odom stamp", "ω cmd (rad/s)", "ω meas (rad/s)"]
    matched = [r for r in rows if r["odom stamp"] in recorded]
    assert len(matched) >= 50, (len(rows), len(matched))
    for r in matched:
        odom = recorded[r["odom stamp"]]
        assert float(r["ω meas (rad/s)"]) == odom["twist"]["twist"]["angular"]["z"]
    # heading is unwrapped: it keeps decreasing past -180 degrees, never jumps by 360
    values = [float(r["heading (deg)"]) for r in csv.DictReader(io.StringIO(heading_csv))]
    steps = [b - a for a, b in itertools.pairwise(values)]
    assert max(abs(s) for s in steps) < 30 and values[-1] < values[0] - 90, values[-5:]
    assert log.errors == []


async def test_no_console_error_through_a_server_restart(
    browser: Browser, contexts: list[BrowserContext]
) -> None:
    settings = ServerSettings(host="127.0.0.1", port=0, http_port=0)
    first = App(settings, world=CLASSROOM)
    await first.start()
    port = first.ws_port
    page, log = await open_page(browser, contexts, f"{http_url(first)}/?url={ws_url(first)}")
    try:
        await page.wait_for_function(
            "window.simbridge && window.simbridge.state.pose && window.simbridge.cmdVel.ready"
        )
        await page.locator("#view").click()
        await page.keyboard.down("KeyA")
        await page.wait_for_function("window.simbridge.state.meas.w > 1")
        await first.stop()
        await page.wait_for_function("window.simbridge.conn.state === 'reconnecting'")
        await page.wait_for_function("document.body.classList.contains('stale')")
        assert await page.text_content("#cmdW") == "0.00"  # no stale 1.50 rad/s readout
        await page.keyboard.up("KeyA")
        await screenshot(page, "class-server-down")
        again = App(ServerSettings(host="127.0.0.1", port=port, http_port=0), world=CLASSROOM)
        await again.start()
        try:
            await page.wait_for_function(
                "window.simbridge.conn.connected && !document.body.classList.contains('stale')",
                timeout=30_000 * TIMEOUT_FACTOR,
            )
            # the trail breaks at the reconnect: no line joins the old pose to the new one
            assert await page.evaluate("window.simbridge.view.trail.includes(null)")
        finally:
            await again.stop()
    finally:
        with contextlib.suppress(Exception):
            await first.stop()
    assert [e for e in log.errors if not network_noise(e)] == []


@pytest.mark.parametrize(
    ("name", "viewport"),
    [("phone", {"width": 390, "height": 844}), ("tablet", {"width": 820, "height": 1180})],
)
async def test_phone_and_tablet_layouts_fit_with_touch(
    app: App, browser: Browser, contexts: list[BrowserContext], name: str, viewport: Any
) -> None:
    page, log = await student(
        app,
        browser,
        contexts,
        "r1",
        viewport=viewport,
        has_touch=True,
        is_mobile=True,
        device_scale_factor=2,
    )
    geometry = await page.evaluate(
        """() => {
          const box = (el) => el.getBoundingClientRect();
          const stop = box(document.getElementById('estop'));
          const covered = [];
          const controls = '.panel button, .panel input, .panel select, .panel output';
          for (const el of document.querySelectorAll(controls)) {
            const r = box(el);
            if (!r.width || !r.height) continue;
            // scroll the control into view, as a student would, and look again
            el.scrollIntoView({ block: 'nearest' });
            const s = box(el), t = box(document.getElementById('estop'));
            const over = s.bottom > t.top + 1 && s.top < t.bottom - 1
              && s.right > t.left && s.left < t.right;
            if (over) covered.push(el.id || el.textContent);
          }
          document.querySelector('.layout').scrollTop = 0;
          const { view } = window.simbridge;
          return {
            header: box(document.querySelector('.bar')).height,
            view: box(document.getElementById('view')),
            panelTop: box(document.querySelector('.panel')).top,
            covered,
            robotPx: 2 * Math.max(view.radius * view.scale, 8),
            stopHeight: stop.height,
          };
        }"""
    )
    assert geometry["header"] < 110, geometry
    assert geometry["view"]["top"] < geometry["panelTop"], "the map comes first"
    assert geometry["view"]["height"] > 0.45 * viewport["height"], geometry
    assert geometry["covered"] == [], geometry
    assert geometry["robotPx"] >= 16, geometry
    await screenshot(page, f"class-{name}")
    await page.tap("#estop")
    await wait_for(lambda: app.world.halted("r1"), timeout=5)
    assert not app.world.halted("r2")
    await page.wait_for_selector("#estopBanner", state="visible")
    await screenshot(page, f"class-{name}-estop")
    await page.tap("#release")
    await wait_for(lambda: not app.world.halted("r1"), timeout=5)
    assert log.errors == []


async def test_sigterm_with_pages_connected_prints_no_traceback(
    browser: Browser, contexts: list[BrowserContext]
) -> None:
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "simbridge",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--http-port",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = await asyncio.to_thread(proc.stdout.readline)
        match = re.search(r"ws://[^:]+:(\d+)/\s+page http://[^:]+:(\d+)", line)
        assert match, line
        ws, http = match.groups()
        for path in ("/", "/", "/admin"):
            page, _ = await open_page(
                browser, contexts, f"http://127.0.0.1:{http}{path}?url=ws://127.0.0.1:{ws}"
            )
        await page.wait_for_load_state("networkidle")
        proc.send_signal(signal.SIGTERM)
        _, err = await asyncio.to_thread(proc.communicate, timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0
    assert "Traceback" not in err and "ERROR" not in err, err[-3000:]
