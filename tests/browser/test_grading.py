"""The Tasks tab and /admin's grading in Chromium: a heading step driven by the page's PID lab.

The instructor publishes the task on /admin; the student's page lists it, Start puts the robot
at the start pose, the PID lab's heading step drives it, the server scores it on the true pose
and the page shows the verdict and the plot; /admin lists the attempt and draws it.
"""

from __future__ import annotations

from pathlib import Path

from simbridge.app.config import resource_dir
from tests.browser.conftest import OpenPage, screenshot
from tests.conftest import AppFactory
from tests.helpers import ws_url


ADMIN = "teacher-secret-31"


async def test_a_heading_step_from_the_pid_lab_is_graded_on_the_page_and_on_admin(
    make_app: AppFactory, open_page: OpenPage, tmp_path: Path
) -> None:
    tasks = tmp_path / "tasks"
    tasks.mkdir()
    text = (resource_dir("config") / "tasks" / "heading_step.yaml").read_text()
    (tasks / "heading_step.yaml").write_text(text.replace("time_limit: 8", "time_limit: 2.5"))
    app = await make_app(
        admin_token=ADMIN, tasks_dir=str(tasks), results_file=str(tmp_path / "results.jsonl")
    )
    app.world.robots[""].place((0.0, 0.0, 0.0))
    admin, admin_log = await open_page(app, "/admin")
    await admin.fill("#token", ADMIN)
    await admin.click("#tokenForm button")
    await admin.click("#gradingTasks button[data-publish=heading_step]")
    await admin.wait_for_selector("#gradingMsg.ok")
    assert "published" in await admin.text_content("#gradingMsg")

    page, log = await open_page(app, f"/?url={ws_url(app)}")
    await page.wait_for_function(
        "window.simbridge && window.simbridge.state.pose !== null && window.simbridge.cmdVel.ready"
    )
    app.world.robots[""].place((0.3, 0.2, 0.4))  # Start puts it back at its start pose
    await page.click(".tabs button[data-tab=tasks]")
    await page.click("#taskList button[data-start=heading_step]")
    await page.wait_for_function("/Attempt|Could not/.test(taskStatus.textContent)")
    assert "Attempt a1" in await page.text_content("#taskStatus")
    assert app.world.robots[""].state.x == 0.0  # back at its start pose (the task's start)
    await page.click(".tabs button[data-tab=pid]")
    await page.select_option("#pidMode", "heading")
    await page.fill("#spTheta", "90")  # the task: 90 degrees left of the start heading (0)
    await page.click("#pidStart")
    await page.click(".tabs button[data-tab=tasks]")
    await page.wait_for_function(
        "/PASSED|FAILED/.test(document.querySelector('#taskStatus').textContent)", timeout=30_000
    )
    status = await page.text_content("#taskStatus")
    assert "PASSED" in status, status
    assert await page.locator("#taskResult svg polyline").count() == 1
    assert await page.locator("#taskResult tr[data-metric=overshoot_pct]").count() == 1
    await screenshot(page, "grading-page", full_page=True)

    await admin.evaluate("window.simbridgeGrading.refresh()")
    row = admin.locator("#gradingAttempts tr[data-attempt=a1]")
    await row.wait_for()
    assert "pass" in await row.text_content()
    assert await admin.locator("#gradingBest tr[data-attempt=a1]").count() == 1
    await row.locator("button[data-plot]").click()
    await admin.wait_for_selector("#gradingPlot svg polyline")
    await screenshot(admin, "grading-admin", full_page=True)
    assert log.errors == [] and admin_log.errors == []
