"""``simbridge grade`` on a running server, with examples/pid_goto.py as the controller.

One end-to-end test per real client path: the CLI (a rosbridge client) starts the task on the
server, starts the roslibpy controller, polls the result and writes report.json and
report.html. Three runs at once, each on its own server: the example's own gains twice (they
pass, and score alike), and gains whose integral carries the robot past the goal (they fail on
the overshoot line).
"""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path
from typing import Any

from simbridge.grading import default_tasks_dir
from tests.conftest import AppFactory
from tests.helpers import ROOT, finish_process, ws_url


#: The example's own gains; it stops once within 2 cm.
SENSIBLE = ["--tolerance", "0.02"]
#: Gains that carry the robot past the goal (the integral holds the command at the limit), and
#: a tolerance it cannot meet on the way through (it would stop there and hide the overshoot).
#: At 0.45 m/s the kinematic steps are 2.25 cm: it passes the goal by 1.25 cm at least before
#: it sees that it did, and by up to 7 cm (its 10 Hz period and the link's latency).
OVERSHOOTING = [
    *("--position-gains", "3", "2", "0"),
    *("--max-speed", "0.45", "--tolerance", "0.0001"),
]
KEYS = ("task", "robot", "passed", "metrics", "thresholds")
METRICS = (
    "overshoot_pct",
    "rise_time_s",
    "settling_time_s",
    "steady_state_error",
    "time_to_goal_s",
    "path_length_m",
    "min_clearance_m",
    "collisions",
)


def short_task(tmp_path: Path) -> Path:
    """The bundled position task with a shorter time limit (the robot is there in 3.6 s)."""
    text = (default_tasks_dir() / "goto_position.yaml").read_text()
    path = tmp_path / "goto_position.yaml"
    path.write_text(text.replace("time_limit: 20", "time_limit: 5"))
    return path


async def grade(url: str, task: Path, out: Path, gains: list[str]) -> tuple[int, Any, str]:
    cmd = [sys.executable, "-m", "simbridge", "grade", str(task), "--url", url, "-o", str(out)]
    controller = [sys.executable, "examples/pid_goto.py", *gains]
    proc = await asyncio.create_subprocess_exec(
        *cmd, "--", *controller, cwd=ROOT, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    code, stdout, stderr = await finish_process(proc, 60)
    report = (
        json.loads((out / "report.json").read_text()) if (out / "report.json").exists() else None
    )
    return code, report, stdout + stderr


async def test_pid_goto_passes_with_its_gains_and_fails_on_overshoot_with_others(
    make_app: AppFactory, tmp_path: Path
) -> None:
    task = short_task(tmp_path)
    apps = [await make_app() for _ in range(3)]
    runs = await asyncio.gather(
        *(
            grade(ws_url(app), task, tmp_path / f"run{i}", gains)
            for i, (app, gains) in enumerate(
                zip(apps, [SENSIBLE, SENSIBLE, OVERSHOOTING], strict=True)
            )
        )
    )
    (code1, good1, out1), (code2, good2, out2), (code3, bad, out3) = runs
    assert code1 == 0, out1
    assert code2 == 0, out2
    assert code3 == 1, out3
    for report in (good1, good2, bad):
        assert all(k in report for k in KEYS)
        assert set(METRICS) <= set(report["metrics"])
        assert report["thresholds"]["overshoot_pct"] == {"max": 1.0, "min": None}
    assert (tmp_path / "run0" / "report.html").read_text().count("<svg") == 1
    failed = [line for line in bad["rubric"] if not line["passed"]]
    assert [line["metric"] for line in failed] == ["overshoot_pct"], failed
    assert failed[0]["value"] == bad["metrics"]["overshoot_pct"] > 1.0
    assert "FAIL overshoot_pct" in out3
    # the same controller twice: the loop's timing (10 Hz controller, 20 Hz simulation, a
    # loaded machine) is all that differs
    m1, m2 = good1["metrics"], good2["metrics"]
    assert abs(m1["time_to_goal_s"] - m2["time_to_goal_s"]) < 1.0
    assert abs(m1["steady_state_error"] - m2["steady_state_error"]) < 0.02
    assert abs(m1["path_length_m"] - m2["path_length_m"]) < 0.05
    print(
        "same controller twice:",
        {k: (m1[k], m2[k]) for k in ("time_to_goal_s", "steady_state_error", "path_length_m")},
        "overshooting:",
        bad["metrics"]["overshoot_pct"],
    )


def test_grade_headless_runs_a_simulation_controller_in_sim_time(tmp_path: Path) -> None:
    """``--headless``: the controller of examples/grade_headless.py, no server, report written."""
    from simbridge.tools.grade import grade_main

    task = str(default_tasks_dir() / "heading_step.yaml")
    controller = str(ROOT / "examples" / "grade_headless.py") + ":heading"
    assert grade_main([task, "--headless", "--controller", controller, "-o", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["passed"] is True and all(k in report for k in KEYS)
    assert report["metrics"]["settling_time_s"] < 4
    assert grade_main([task, "--headless", "--controller", "nowhere.py:x"]) == 2
