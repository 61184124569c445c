"""The grader on a headless simulation: a run from the start pose, scored on the true pose."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from simbridge.errors import ServiceError
from simbridge.grading import default_tasks_dir
from simbridge.grading.grader import Grader
from simbridge.grading.results import ResultsLog
from simbridge.grading.task import parse_task
from simbridge.headless import Simulation
from simbridge.tools.bag import read_messages
from simbridge.tools.grade import grade_headless


HEADING = default_tasks_dir() / "heading_step.yaml"


def p_heading(
    kp: float, ki: float = 0.0
) -> Callable[[Any, str, dict[str, Any]], Callable[[], None]]:
    """A PI heading controller at 10 Hz (every other step) on the robot's /odom (no anti-windup)."""

    def make(sim: Any, robot: str, goal: dict[str, Any]) -> Callable[[], None]:
        odom = sim.subscribe("/odom", maxlen=1)
        steps = [0]
        integral = [0.0]

        def step() -> None:
            steps[0] += 1
            if steps[0] % 2 or odom.latest is None:
                return
            q = odom.latest["pose"]["pose"]["orientation"]
            yaw = 2 * math.atan2(q["z"], q["w"])
            err = math.atan2(math.sin(goal["heading"] - yaw), math.cos(goal["heading"] - yaw))
            integral[0] += err * 0.1
            w = kp * err + ki * integral[0]
            sim.publish("/cmd_vel", {"angular": {"z": max(-2.5, min(2.5, w))}})

        return step

    return make


def test_a_sensible_controller_passes_and_a_wild_one_fails_on_overshoot(tmp_path: Path) -> None:
    good = grade_headless(HEADING, p_heading(3.0), bags=tmp_path / "bags")
    assert good["status"] == "passed", good["rubric"]
    assert good["metrics"]["overshoot_pct"] < 10
    topics = {topic for topic, *_ in read_messages(good["bag"])}
    assert {"/odom", "/cmd_vel", "/tf"} <= topics
    wild = grade_headless(HEADING, p_heading(3.0, 6.0))
    assert wild["status"] == "failed"
    failed = {line["metric"]: line for line in wild["rubric"] if not line["passed"]}
    assert "overshoot_pct" in failed
    assert failed["overshoot_pct"]["value"] == wild["metrics"]["overshoot_pct"] > 10


def test_a_run_ends_at_its_time_limit_with_the_robot_stopped_and_its_params_back() -> None:
    sim = Simulation()
    grader = Grader(sim.graph, sim.world, ResultsLog(None), {})
    sim.robot.tick_hooks.append(grader.tick)
    task = parse_task(
        "goal: {position: [3, 0]}\ntime_limit: 1\n"
        "robot_params: {robot.mass: 4.0, realism.enabled: true}\n"
        "start: [0.5, 0.0, 0.0]\nrubric: {time_to_goal_s: {max: 5}}\n",
        task_id="t",
    )
    run = grader.start(None, "", task)
    assert sim.pose() == pytest.approx((0.5, 0.0, 0.0))
    assert sim.world.robot_params("").mass == 4.0
    assert sim.world.robots[""].realism_own == {"enabled": True}
    with pytest.raises(ServiceError, match="already running attempt a1"):
        grader.start(None, "", task)
    sim.run(0.5)
    assert run.phase == "waiting"  # no command yet: the clock has not started
    sim.publish("/cmd_vel", {"linear": {"x": 0.2}})
    sim.run(1.5)
    record = grader.results.attempts[run.attempt]
    assert record["status"] == "failed"
    assert record["duration_s"] == pytest.approx(1.0)
    assert 0.1 < record["metrics"]["path_length_m"] < 0.21  # 0.2 m/s for 1 s, a real motor
    assert sim.world.robots[""].cmd_v == 0.0
    assert sim.world.robot_params("").mass == 1.5
    assert sim.world.robots[""].realism_own == {}


def test_a_controller_that_never_comes_is_recorded_as_no_controller() -> None:
    sim = Simulation()
    grader = Grader(sim.graph, sim.world, ResultsLog(None), {}, max_attempts=1)
    sim.robot.tick_hooks.append(grader.tick)
    task = parse_task(
        "goal: {heading: 1}\ntime_limit: 1\nwait_for_controller: 0.5\n"
        "rubric: {overshoot_pct: {max: 5}}\n",
        task_id="t",
    )
    run = grader.start(None, "", task)
    sim.run(1.0)
    assert grader.results.attempts[run.attempt]["status"] == "no_controller"
    with pytest.raises(ServiceError, match=r"has 1 attempts .*grading_max_attempts 1"):
        grader.start(None, "", task)  # the budget: what one robot's attempts may hold
