"""A class on one server: three students with three tokens run the published task.

Each student is a rosbridge client with its own token; the instructor publishes the task and
reads the class's attempts, the best of each and the CSV through /admin's API.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import json
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import pytest

from simbridge.app.config import resource_dir
from simbridge.app.runner import App
from simbridge.tools.client import ClientError, RosbridgeClient
from tests.conftest import AppFactory
from tests.helpers import http_url, wait_for, ws_url


ADMIN = "instructor-secret-1"
TOKENS = {"student-one-token": "r1", "student-two-token": "r2", "student-three-token": "r3"}
QUICK = """
name: quick turn
frame: start
goal: {heading: 0.5}
time_limit: 1.0
rubric: {overshoot_pct: {max: 10}, steady_state_error: {max: 0.05}}
"""


def http(app: App, path: str, body: Any = None, token: str | None = ADMIN) -> tuple[int, bytes]:
    data = None if body is None else json.dumps(body).encode()
    method = "GET" if data is None else "POST"
    req = urllib.request.Request(http_url(app) + path, data=data, method=method)
    if token is not None:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=5) as res:
            return res.status, res.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()


async def grade(ros: RosbridgeClient, service: str, **args: str) -> Any:
    values = await ros.call_service(f"/simbridge/grade/{service}", args)
    return json.loads(values["message"])


async def test_a_class_of_three_runs_the_published_task_and_admin_lists_them(
    make_app: AppFactory, tmp_path: Path
) -> None:
    tasks = tmp_path / "tasks"
    tasks.mkdir()
    (tasks / "quick.yaml").write_text(QUICK)
    app = await make_app(
        world=resource_dir("config") / "worlds" / "classroom.yaml",
        client_tokens=TOKENS,
        admin_token=ADMIN,
        tasks_dir=str(tasks),
        results_file=str(tmp_path / "results.jsonl"),
    )
    code, body = await asyncio.to_thread(http, app, "/api/admin/grading/publish", {"task": "x"})
    assert code == 400 and b"no task 'x'" in body
    code, _ = await asyncio.to_thread(http, app, "/api/admin/grading", None, "wrong")
    assert code == 403
    code, _ = await asyncio.to_thread(
        http, app, "/api/admin/grading/publish", {"task": "quick", "published": True}
    )
    assert code == 200
    students: dict[str, RosbridgeClient] = {}
    async with contextlib.AsyncExitStack() as stack:
        for token, robot in TOKENS.items():
            url = f"{ws_url(app)}/?token={token}"
            students[robot] = await stack.enter_async_context(RosbridgeClient.connect(url))
        r1, r2 = students["r1"], students["r2"]
        listed = await grade(r1, "tasks")
        assert [t["id"] for t in listed["tasks"]] == ["quick"]
        with pytest.raises(ClientError, match="own robot 'r1' only, not 'r2'"):
            await grade(r1, "start", task="quick", robot="r2")
        attempts = {}
        for robot, ros in students.items():
            started = await grade(ros, "start", task="quick")
            assert started["robot"] == robot and started["status"] == "waiting"
            attempts[robot] = started["attempt"]
            await ros.publish(
                f"/{robot}/cmd_vel",
                {"linear": {"x": 0.0}, "angular": {"z": 0.5}},
                "geometry_msgs/msg/Twist",
            )

        async def all_done() -> bool:
            states = [await grade(ros, "status") for ros in students.values()]
            return all(s["status"] not in ("waiting", "running") for s in states)

        for _ in range(100):
            if await all_done():
                break
            await asyncio.sleep(0.1)
        mine = await grade(r2, "results")
        assert [a["robot"] for a in mine["attempts"]] == ["r2"]
        with pytest.raises(ClientError, match="not this connection's"):
            await grade(r2, "status", attempt=attempts["r1"])
        own = await grade(r1, "status", attempt=attempts["r1"])
        assert own["status"] in ("passed", "failed") and "<svg" in own["plot_svg"]
    code, body = await asyncio.to_thread(http, app, "/api/admin/grading")
    state = json.loads(body)
    assert sorted(a["student"] for a in state["attempts"]) == ["r1", "r2", "r3"]
    assert sorted(b["student"] for b in state["best"]) == ["r1", "r2", "r3"]
    assert all(a["official"] for a in state["attempts"])
    code, body = await asyncio.to_thread(http, app, "/api/admin/grading.csv")
    rows = list(csv.DictReader(io.StringIO(body.decode())))
    assert sorted(r["student"] for r in rows) == ["r1", "r2", "r3"]
    assert all(r["best"] == "True" and r["overshoot_pct"] != "" for r in rows)
    code, body = await asyncio.to_thread(
        http, app, f"/api/admin/grading/report?id={attempts['r3']}"
    )
    assert code == 200 and b"<svg" in body and b"quick turn" in body
    await wait_for(lambda: not app.grader.runs)


async def test_a_students_task_sent_as_text_may_lower_its_robots_limits_never_raise_them(
    make_app: AppFactory,
) -> None:
    """Issue 29's rule for ``…/set_parameters`` holds for ``robot_params`` in ``task_yaml`` too.

    A student's own task made its robot 40 times as fast (``robot.max_linear_velocity: 20``).
    """
    app = await make_app(
        world=resource_dir("config") / "worlds" / "classroom.yaml",
        client_tokens=TOKENS,
        admin_token=ADMIN,
    )
    url = f"{ws_url(app)}/?token=student-one-token"
    async with RosbridgeClient.connect(url) as r1:
        fast = QUICK + "robot_params: {robot.max_linear_velocity: 20}\n"
        with pytest.raises(ClientError, match=r"max_linear_velocity 20 is above the robot's 0\.5"):
            await grade(r1, "start", task="practice", task_yaml=fast)
        assert not app.grader.runs and app.world.robot_params("r1").max_linear_velocity == 0.5
        # true wheels of 1 m on the nominal 0.033 m: the ground moved 30 times as fast
        wheels = "realism.wheel_radius_left: 1.0, realism.wheel_radius_right: 1.0"
        big = QUICK + "robot_params: {realism.enabled: true, " + wheels + "}\n"
        with pytest.raises(ClientError, match=r"times as fast \(linear\)"):
            await grade(r1, "start", task="practice", task_yaml=big)
        assert not app.grader.runs and app.world.robots["r1"].realism_own == {}
        worn = QUICK + "robot_params: {realism.enabled: true, realism.slip: 0.1}\n"
        await grade(r1, "start", task="practice", task_yaml=worn)
        await grade(r1, "cancel")
        slow = QUICK + "robot_params: {robot.max_linear_velocity: 0.2, robot.mass: 3.0}\n"
        started = await grade(r1, "start", task="practice", task_yaml=slow)
        assert started["robot"] == "r1" and app.world.robot_params("r1").max_linear_velocity == 0.2
        await grade(r1, "cancel")
    assert app.world.robot_params("r1").max_linear_velocity == 0.5
