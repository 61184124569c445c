from __future__ import annotations

import math
import time

import numpy as np
import pytest

from simbridge.errors import ConversionError, ProtocolError, SimbridgeError
from simbridge.headless import Simulation


def test_drives_straight_and_reports_odom_as_dicts() -> None:
    """0.2 m/s for 5 s of sim time moves the robot 1 m; /odom reads as ROS-named dicts."""
    sim = Simulation()
    x0, _y0, th0 = sim.pose()
    odom = sim.subscribe("/odom")
    sim.publish("/cmd_vel", {"linear": {"x": 0.2}, "angular": {"z": 0.0}})
    sim.run(5.0)
    assert odom.count == 100
    msg = odom.latest
    assert msg is not None
    p = msg["pose"]["pose"]["position"]
    assert p["x"] - x0 == pytest.approx(1.0 * math.cos(th0), abs=1e-9)
    assert msg["twist"]["twist"]["linear"]["x"] == pytest.approx(0.2)
    assert msg["header"]["stamp"] == {"sec": 5, "nanosec": 0}  # sim time
    assert msg["child_frame_id"] == "base_link"


def test_scan_clock_and_latched_tf_static() -> None:
    sim = Simulation()
    scan = sim.subscribe("/scan")
    clock = sim.subscribe("/clock")
    static = sim.subscribe("/tf_static")
    sim.step(4)
    assert scan.count == 2  # 10 Hz of a 20 Hz loop
    ranges = scan.latest["ranges"] if scan.latest else None
    assert isinstance(ranges, np.ndarray)
    assert ranges.shape == (360,)
    assert clock.latest == {"clock": {"sec": 0, "nanosec": 200_000_000}}
    assert static.count == 1


def test_same_seed_and_commands_give_the_same_run() -> None:
    def run() -> tuple[float, float, float]:
        sim = Simulation(seed=3)
        for k in range(40):
            sim.command(0.3, math.sin(k / 5.0))
            sim.step()
        return sim.pose()

    assert run() == run()


def test_cmd_vel_limits_and_bad_messages() -> None:
    """Limits apply as over the wire; a bad message raises and leaves the command unchanged."""
    sim = Simulation()
    odom = sim.subscribe("/odom")
    sim.publish("/cmd_vel", {"linear": {"x": 9.0}})
    sim.step()
    assert odom.latest is not None
    assert odom.latest["twist"]["twist"]["linear"]["x"] == pytest.approx(0.5)
    with pytest.raises(ConversionError):
        sim.publish("/cmd_vel", {"linear": {"x": "fast"}})
    with pytest.raises(ProtocolError, match="finite"):
        sim.publish("/cmd_vel", {"linear": {"x": float("nan")}})
    with pytest.raises(SimbridgeError, match="no topic"):
        sim.subscribe("/nope")
    sim.step()
    assert odom.latest["twist"]["twist"]["linear"]["x"] == pytest.approx(0.5)


def test_services_reset_and_step() -> None:
    sim = Simulation()
    sim.command(0.5, 0.0)
    sim.run(1.0)
    assert sim.time == pytest.approx(1.0)
    sim.reset()
    assert sim.time == 0.0
    assert sim.pose() == pytest.approx(tuple(sim.world.spec.robot.pose))
    assert sim.call_service("/sim/step")["success"] is False  # not paused


def test_a_paused_sim_step_steps_once_and_runs_the_hooks_on_sim_time() -> None:
    """/sim/step headless is the server's single step: one step, its hooks, sim time."""
    sim = Simulation()
    sim.step()
    seen: list[tuple[int, float]] = []
    sim.tick_hooks.append(lambda now: seen.append((sim.world.steps, now)))
    assert sim.call_service("/sim/pause", {"data": True})["success"] is True
    assert sim.call_service("/sim/step")["success"] is True
    assert seen == [(2, pytest.approx(2 * sim.dt))]


def test_runs_much_faster_than_real_time() -> None:
    """20 s of sim time with /odom and /scan subscribed takes well under 20 s (bench: ~200x)."""
    sim = Simulation()
    sim.subscribe("/odom")
    sim.subscribe("/scan")
    sim.command(0.2, 0.3)
    start = time.perf_counter()
    sim.run(20.0)
    wall = time.perf_counter() - start
    assert wall < 5.0, f"20 s of sim time took {wall:.2f} s"


def test_estop_latches_and_stops_the_robot_headless() -> None:
    """The e-stop the server has works headless too: /estop stops the robot until reset."""
    sim = Simulation()
    sim.publish("/cmd_vel", {"linear": {"x": 0.2}, "angular": {"z": 0.0}})
    sim.step(2)
    sim.call_service("/estop")
    state = sim.subscribe("/estop/state")
    assert state.latest == {"data": True}
    x = sim.pose()[0]
    sim.run(1.0)
    assert sim.pose()[0] == x
