from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from simbridge.app.config import Params, WorldSpec, load_params, load_world
from simbridge.sim import World, world as world_module
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
    spec = WorldSpec.parse({"robot": {"pose": [1.0, 2.0, 0.5]}})
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
    spec = WorldSpec.parse({"walls": [[1.0, -1.0, 1.0, 1.0]]})
    plain = World(spec, Params())
    mounted = World(spec, Params.from_flat({**Params().flat(), "lidar.mount": [0.1, 0.0, 0.0]}))
    assert plain.scan("")[0] == pytest.approx(1.0)
    assert mounted.scan("")[0] == pytest.approx(0.9)


def test_scan_is_float32_and_clipped_to_the_sensor_range() -> None:
    """Ranges are float32 within [range_min, range_max]; a wall closer than range_min saturates."""
    spec = WorldSpec.parse({"walls": [[0.05, -1.0, 0.05, 1.0]]})
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


BOX = {"walls": [[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]]}


def fleet(*robots: tuple[str, float, float, float]) -> World:
    spec = WorldSpec.parse(
        {**BOX, "robots": [{"name": n, "pose": [x, y, t]} for n, x, y, t in robots]}
    )
    return World(spec, Params())


def test_a_robots_list_gives_named_robots_at_their_poses() -> None:
    world = fleet(("r1", -1.0, 0.0, 0.0), ("r2", 1.0, 0.0, math.pi))
    assert list(world.robots) == ["r1", "r2"]
    assert (world.robots["r2"].state.x, world.robots["r2"].start) == (1.0, (1.0, 0.0, math.pi))
    assert world.robots["r1"].topic("odom") == "/r1/odom"
    assert world.robots["r1"].frame("base_link") == "r1/base_link"


def test_scans_see_other_robots_and_never_their_own_footprint() -> None:
    """r1 faces r2 2 m away: its front ray reads 2 - radius; r2's ray towards r1 likewise."""
    world = fleet(("r1", -1.0, 0.0, 0.0), ("r2", 1.0, 0.0, math.pi))
    r1, r2 = world.scans(["r1", "r2"])
    radius = world.params.robot.radius
    assert r1[0] == pytest.approx(2.0 - radius, abs=1e-5)
    assert r2[0] == pytest.approx(2.0 - radius, abs=1e-5)
    assert r1[180] == pytest.approx(3.5)  # 4 m to the west wall: range_max
    np.testing.assert_array_equal(world.scan("r1"), r1)


def test_a_parked_robots_scan_follows_every_change_around_it() -> None:
    """A parked robot's scan is reused while nothing moves, never when something does."""
    world = fleet(("r1", -1.0, 0.0, 0.0))
    empty = world.scan("r1")
    assert empty[0] == pytest.approx(3.5)  # nothing ahead within range_max
    world.spawn("r2", (1.0, 0.0, 0.0))
    assert world.scan("r1")[0] == pytest.approx(2.0 - world.params.robot.radius, abs=1e-5)
    world.command("r2", 0.5, 0.0)  # r2 drives away
    world.step()
    assert world.scan("r1")[0] == pytest.approx(2.025 - world.params.robot.radius, abs=1e-5)
    world.remove("r2")
    np.testing.assert_array_equal(world.scan("r1"), empty)
    world.params.lidar.range_max = 2.0  # a LiDAR setting changed at run time
    assert world.scan("r1")[0] == pytest.approx(2.0)
    world.params.lidar.noise_stddev = 0.01  # noise is drawn for every scan of a parked robot
    assert not np.array_equal(world.scan("r1"), world.scan("r1"))


def test_a_robot_driving_into_another_stops_at_contact_and_reports_it() -> None:
    world = fleet(("r1", -1.0, 0.0, 0.0), ("r2", 1.0, 0.0, math.pi))
    world.command("r1", 0.5, 0.0)
    for _ in range(200):
        world.step()
    r1 = world.robots["r1"].state
    assert r1.x == pytest.approx(1.0 - 2 * world.params.robot.radius, abs=1e-6)
    assert r1.v == pytest.approx(0.0)
    assert [(name, other) for name, other, _ in world.contacts] == [("r1", "r2")]
    assert world.touching == {"r1"}


def test_a_robot_driving_into_a_wall_stops_with_its_footprint_on_it() -> None:
    world = fleet(("r1", 4.0, 0.0, 0.0))
    world.command("r1", 0.5, 0.0)
    for _ in range(100):
        world.step()
    assert world.robots["r1"].state.x == pytest.approx(5.0 - world.params.robot.radius, abs=1e-3)
    assert [(n, o) for n, o, _ in world.contacts] == [("r1", "wall")]


def test_spawn_teleport_remove_and_reset() -> None:
    """Spawned robots reset to their spawn pose; teleport keeps the start; remove forgets."""
    world = fleet(("r1", -1.0, 0.0, 0.0))
    world.spawn("r2", (2.0, 2.0, 0.5))
    world.teleport("r2", (3.0, -2.0, 0.0))
    assert (world.robots["r2"].state.x, world.robots["r2"].state.y) == (3.0, -2.0)
    world.reset()
    assert (world.robots["r2"].state.x, world.robots["r2"].state.theta) == (2.0, 0.5)
    world.remove("r2")
    assert list(world.robots) == ["r1"]


@pytest.mark.parametrize(
    ("name", "pose", "error"),
    [
        ("r1", (3.0, 3.0, 0.0), "already exists"),
        ("2bad", (3.0, 3.0, 0.0), "not a valid ROS name"),
        ("r3", (4.95, 0.0, 0.0), "overlaps the wall"),
        ("r3", (-0.9, 0.0, 0.0), "overlaps another robot"),
        ("r3", (math.nan, 0.0, 0.0), "finite"),
    ],
)
def test_spawn_refuses_taken_names_bad_names_and_occupied_poses(
    name: str, pose: tuple[float, float, float], error: str
) -> None:
    world = fleet(("r1", -1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=error):
        world.spawn(name, pose)
    assert list(world.robots) == ["r1"]


def test_teleport_refuses_a_pose_inside_another_robots_start_pose() -> None:
    """Start poses count too, so /reset never puts two robots on top of each other."""
    world = fleet(("r1", -1.0, 0.0, 0.0), ("r2", 1.0, 0.0, 0.0))
    world.teleport("r1", (0.0, 2.0, 0.0))
    with pytest.raises(ValueError, match="overlaps another robot"):
        world.teleport("r2", (-1.0, 0.05, 0.0))


def test_a_robot_is_never_placed_outside_the_world() -> None:
    """Teleport and spawn far outside the walls' box (plus its margin) are refused."""
    world = fleet(("r1", -1.0, 0.0, 0.0))
    assert world.bounds() == (-6.0, -6.0, 6.0, 6.0)  # BOX's walls at +-5, margin 1 m
    with pytest.raises(ValueError, match="outside the world"):
        world.teleport("r1", (1000.0, -1000.0, 0.0))
    with pytest.raises(ValueError, match="outside the world"):
        world.spawn("r2", (0.0, 6.5, 0.0))
    world.teleport("r1", (5.5, 0.0, 0.0))  # in the margin: open layouts have no walls there


def test_a_parked_robots_ranges_are_reused_whichever_robots_scan_with_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Robots scan in turns: each robot's last ranges serve until a robot moves."""
    cast: list[int] = []
    real = world_module.raycast_batch

    def counted(origins: Any, *args: Any, **kwargs: Any) -> Any:
        cast.append(len(origins))
        return real(origins, *args, **kwargs)

    monkeypatch.setattr(world_module, "raycast_batch", counted)
    spec = WorldSpec.parse(
        {
            "walls": [[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]],
            "robots": [{"name": f"r{k}", "pose": [k - 2.0, 0.0, 0.0]} for k in range(4)],
        }
    )
    world = World(spec, Params())
    first = world.scans(["r0", "r2"])
    world.scans(["r1", "r3"])
    assert cast == [2, 2]
    again = world.scans(["r0", "r2"])
    mixed = world.scans(["r3", "r0"])
    assert cast == [2, 2]  # no raycast: every robot's ranges are kept
    assert np.array_equal(first, again) and np.array_equal(mixed[1], first[0])
    fresh = World(spec, Params()).scans(["r3"])
    assert np.array_equal(mixed[0], fresh[0])  # the kept ranges are the ones a cast gives
    world.robots["r0"].place((-2.0, 1.0, 0.0))  # a robot moved: it is in every other's scan
    moved = world.scans(["r0", "r2"])
    assert cast[2:] == [1, 2] and not np.array_equal(moved[0], first[0])
