"""The 10 Hz PID examples drive the simulated robot to a goal position and heading.

examples/pid_goto.py (roslibpy) and examples/pid_goto.mjs (roslibjs 1.4.1 and 2.1.0): their own
measure must be within 0.05 m and 0.05 rad, and the simulator's true pose after they stop
within 0.07 m and 0.1 rad (the stop command takes up to one control period to arrive).
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from simbridge.app.config import Params, RobotParams
from simbridge.app.runner import App
from tests.conftest import AppFactory
from tests.helpers import JS_DIR, ROOT, finish_process, ws_url


GOAL = (1.0, 0.5)
HEADING = 1.57
LIBS = {
    "roslib1": JS_DIR / "node_modules" / "roslib1" / "src" / "RosLibNode.js",
    "roslib2": JS_DIR / "node_modules" / "roslib2" / "dist" / "RosLib.js",
}


async def run_example(cmd: list[str], env: dict[str, str] | None = None) -> Any:
    proc = await asyncio.create_subprocess_exec(
        *cmd,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
    )
    code, out, err = await finish_process(proc, 45)
    lines = out.strip().splitlines()
    assert lines, f"no output (exit {code}):\n{err[-2000:]}"
    result = json.loads(lines[-1])
    assert code == 0, f"{result}\n{err[-2000:]}"
    return result


def goal_args(app: App) -> list[str]:
    return ["--url", ws_url(app), "--goal", *map(str, GOAL), "--heading", str(HEADING)]


def check(result: Any, app: App) -> None:
    assert result["reached"] is True
    assert result["distance_error"] < 0.05
    assert result["heading_error"] < 0.05
    s = app.world.robots[""].state
    assert math.hypot(s.x - GOAL[0], s.y - GOAL[1]) < 0.07
    assert abs(math.atan2(math.sin(s.theta - HEADING), math.cos(s.theta - HEADING))) < 0.1


@pytest.mark.usefixtures("node_ready")
async def test_pid_examples_reach_the_goal_in_python_and_javascript(make_app: AppFactory) -> None:
    """All three run at once, each against its own simulator.

    The Python and roslib 2 runs face a robot whose /cmd_vel is TwistStamped
    (robot.cmd_vel_stamped): the examples ask rosapi for the type and publish that.
    """
    stamped = Params(robot=RobotParams(cmd_vel_stamped=True))
    py_app = await make_app(params=stamped)
    runs = [run_example([sys.executable, "examples/pid_goto.py", *goal_args(py_app)])]
    apps = [py_app]
    for lib, module in LIBS.items():
        app = await make_app(params=stamped if lib == "roslib2" else None)
        apps.append(app)
        cmd = ["node", "examples/pid_goto.mjs", *goal_args(app)]
        runs.append(run_example(cmd, {"ROSLIB_MODULE": str(module)}))
    results = await asyncio.gather(*runs)
    for result, app in zip(results, apps, strict=True):
        check(result, app)


def test_without_their_client_library_the_examples_say_what_to_install(tmp_path: Path) -> None:
    """No roslibpy (python -S: no site-packages) or no roslib: one line with the command."""
    for script, needs in [("pid_goto.py", "roslibpy"), ("velocity_sequence.py", "roslibpy")]:
        done = subprocess.run(
            [sys.executable, "-S", str(ROOT / "examples" / script)],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert done.returncode == 1
        assert f"{script} needs {needs}" in done.stderr and "pip install roslibpy" in done.stderr
    alone = tmp_path / "pid_goto.mjs"  # away from any node_modules
    shutil.copy(ROOT / "examples" / "pid_goto.mjs", alone)
    done = subprocess.run(["node", str(alone)], capture_output=True, text=True, timeout=30)
    assert done.returncode == 1
    assert "run `npm ci` in examples/" in done.stderr
