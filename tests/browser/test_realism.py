"""The sim-to-real gap in Chromium (issue 26).

/admin gives one robot a worn profile; its page shows the true pose as a ghost and the odometry
error over time, exported as CSV.
"""

from __future__ import annotations

import csv
import io

import pytest

from simbridge.app.runner import App
from tests.browser.conftest import OpenPage, screenshot
from tests.conftest import AppFactory
from tests.helpers import ROOT, ws_url


pytestmark = pytest.mark.e2e
TOKEN = "class-2026"
CLASSROOM = ROOT / "config" / "worlds" / "classroom.yaml"
#: The worn robot: a right wheel 5 % larger than the odometry thinks, a wider wheelbase, slip.
WORN = {
    "realism.enabled": "true",
    "realism.wheel_radius_right": "0.03465",
    "realism.wheelbase": "0.168",
    "realism.slip": "0.05",
}


async def test_admin_worn_profile_on_one_robot_shows_its_ghost_and_error_plot(
    make_app: AppFactory, open_page: OpenPage
) -> None:
    app: App = await make_app(world=CLASSROOM, admin_token=TOKEN)
    admin, admin_log = await open_page(app, "/admin")
    await admin.fill("#token", TOKEN)
    await admin.click("#tokenForm button")
    await admin.wait_for_function(
        "document.getElementById('message').textContent.startsWith('Unlocked')"
    )
    await admin.select_option("#robotPick", "r2")
    for name, value in WORN.items():
        field = admin.locator(f"#robotParams input[name='{name}']")
        await field.fill(value)
        await field.dispatch_event("input")
    await admin.click("#robotForm button[type=submit]")
    await admin.wait_for_function(
        "document.getElementById('robotMsg').textContent.startsWith('Robot r2')"
    )
    world = app.world
    assert world.robots["r2"].realism(world.params.realism) is not None
    assert all(world.robots[n].realism(world.params.realism) is None for n in ("r1", "r3", "r4"))

    page, log = await open_page(app, f"/?url={ws_url(app)}&robot=r2")
    await page.wait_for_function(
        "window.simbridge.state.ns === 'r2' && window.simbridge.state.pose"
    )
    await page.wait_for_function(
        "document.getElementById('robotInfo').textContent.includes('realism profile')"
    )
    world.command("r2", 0.2, 0.5)
    # the encoders believe the nominal geometry: odometry drifts from the truth
    await page.wait_for_function(
        "window.simbridge.gap.latest && window.simbridge.gap.latest.position > 0.02"
        " && window.simbridge.view.ghost !== null",
        timeout=15_000,
    )
    world.command("r2", 0.0, 0.0)
    ghost = await page.evaluate("window.simbridge.view.ghost")
    truth = world.robots["r2"].state
    assert ghost["x"] == pytest.approx(truth.x, abs=0.05)
    assert ghost["y"] == pytest.approx(truth.y, abs=0.05)
    await page.click("nav.tabs [data-tab=plots]")
    await page.wait_for_function("window.simbridge.gap.plot.draws > 0")
    await screenshot(page, "realism-ghost-and-error")
    async with page.expect_download() as info:
        await page.click("#plotGap .plotbar button:text('CSV')")
    download = await info.value
    assert download.suggested_filename == "odometry-error.csv"
    path = await download.path()
    rows = list(csv.reader(io.StringIO(path.read_text())))
    assert rows[0] == ["t_s", "odom stamp", "position error (m)", "heading error (rad)"]
    errors = [float(r[2]) for r in rows[1:] if r[2]]
    assert len(errors) >= 10 and max(errors) > 0.02
    assert log.errors == [] and admin_log.errors == []
