from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from simbridge.config import Params, WorldSpec, load_params, load_world
from simbridge.sim import World
from simbridge.sim.world import KinematicModel, Robot


def test_world_keeps_the_last_command_between_steps() -> None:
    """A command applies to every following step until replaced."""
    world = World(load_world(None), load_params(None))
    world.command("", 0.2, 0.0)
    for _ in range(20):
        world.step()
    assert world.robots[""].state.x == pytest.approx(0.2)
    assert world.time == pytest.approx(1.0)
    assert world.steps == 20


def test_command_returns_the_clamped_velocity() -> None:
    """Commands beyond the limits are clamped to max_linear/angular_velocity."""
    world = World(load_world(None), load_params(None))
    assert world.command("", 3.0, -7.0) == (0.5, -2.5)
    world.step()
    assert world.robots[""].state.v == 0.5
    assert world.robots[""].state.omega == -2.5


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_command_is_refused_and_the_previous_one_kept(bad: float) -> None:
    """NaN or infinity never reaches the robot's state."""
    world = World(load_world(None), load_params(None))
    world.command("", 0.1, 0.0)
    with pytest.raises(ValueError, match="finite"):
        world.command("", bad, 0.0)
    with pytest.raises(ValueError, match="finite"):
        world.command("", 0.0, bad)
    world.step()
    assert world.robots[""].state.v == 0.1


def test_limits_changed_at_run_time_apply_at_the_next_step() -> None:
    """Lowering max_linear_velocity slows a robot that keeps its old command."""
    world = World(load_world(None), load_params(None))
    world.command("", 0.5, 0.0)
    world.params = Params.from_flat({**world.params.flat(), "robot.max_linear_velocity": 0.1})
    world.step()
    assert world.robots[""].state.v == pytest.approx(0.1)


def test_reset_returns_every_robot_to_its_start_pose_stopped() -> None:
    """reset(): start pose, zero velocity, no pending command, time back to 0."""
    spec = WorldSpec.model_validate({"robot": {"pose": [1.0, 2.0, 0.5]}})
    world = World(spec, Params())
    world.command("", 0.3, 0.3)
    for _ in range(5):
        world.step()
    world.reset()
    robot = world.robots[""]
    assert (robot.state.x, robot.state.y, robot.state.theta) == (1.0, 2.0, 0.5)
    assert (robot.state.v, robot.state.omega, robot.cmd_v, robot.cmd_omega) == (0, 0, 0, 0)
    assert world.time == 0.0


def test_scan_comes_from_the_laser_mount_pose() -> None:
    """A laser mounted 0.1 m ahead sees the wall in front 0.1 m closer."""
    spec = WorldSpec.model_validate({"walls": [[1.0, -1.0, 1.0, 1.0]]})
    plain = World(spec, Params())
    mounted = World(spec, Params.from_flat({**Params().flat(), "lidar.mount": [0.1, 0.0, 0.0]}))
    assert plain.scan("")[0] == pytest.approx(1.0)
    assert mounted.scan("")[0] == pytest.approx(0.9)


def test_scan_is_float32_and_clipped_to_the_sensor_range() -> None:
    """Ranges are float32 within [range_min, range_max]; a wall closer than range_min saturates."""
    spec = WorldSpec.model_validate({"walls": [[0.05, -1.0, 0.05, 1.0]]})
    ranges = World(spec, Params()).scan("")
    assert ranges.dtype == np.float32
    assert ranges[0] == pytest.approx(0.12)
    assert float(ranges.max()) <= 3.5


def test_noise_is_seeded_and_repeatable() -> None:
    """Two worlds with the same seed produce the same noisy scan; reset restarts the noise."""
    params = Params.from_flat({**Params().flat(), "lidar.noise_stddev": 0.01})
    a = World(load_world(None), params, seed=7)
    b = World(load_world(None), params, seed=7)
    first = a.scan("")
    np.testing.assert_array_equal(first, b.scan(""))
    a.reset()
    np.testing.assert_array_equal(first, a.scan(""))
    assert not np.array_equal(first, World(load_world(None), Params()).scan(""))


def test_a_robot_whose_update_raises_is_reset_and_the_others_go_on() -> None:
    """World.step isolates robots: the failing one is logged and reset, the rest move."""
    world = World(load_world(None), Params())
    world.robots["r2"] = Robot("r2", (1.0, 1.0, 0.0))
    world.robots["r2"].place((1.0, 1.0, 0.0))
    for robot in world.robots.values():
        robot.cmd_v = 0.2

    class Flaky:
        name = "flaky"

        def step(self, state: Any, v: float, omega: float, dt: float, params: Any) -> None:
            if state.y == 1.0 and state.x > 1.05:
                raise ZeroDivisionError("a bug in the model")
            KinematicModel().step(state, v, omega, dt, params)

    world.motion = Flaky()
    for _ in range(20):
        world.step()
    assert world.failures >= 1
    assert world.robots["r2"].state.x <= 1.05 and world.robots["r2"].cmd_v == 0.0
    assert world.robots[""].state.x > 0.15  # the healthy robot kept driving
    assert world.steps == 20


def test_a_non_finite_state_is_treated_as_a_failure_and_reset() -> None:
    world = World(load_world(None), Params())
    world.robots[""].state.x = math.inf
    world.step()
    assert world.robots[""].state.x == world.robots[""].start[0] and world.failures == 1


@pytest.mark.parametrize(("v", "omega"), [(1e308, 0.0), (0.0, -2e3), (1001.0, 1.0)])
def test_absurd_command_is_refused_not_clamped(v: float, omega: float) -> None:
    world = World(load_world(None), Params())
    world.command("", 0.1, 0.0)
    with pytest.raises(ValueError, match="absurd"):
        world.command("", v, omega)
    assert world.robots[""].cmd_v == 0.1
