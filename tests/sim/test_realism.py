"""The realism profile (issue 26): headless and seeded, on the world alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.app.config import (
    FloorPatch,
    LidarParams,
    Params,
    RealismParams,
    WorldSpec,
    load_world,
)
from simbridge.sim import World


R, B = 0.033, 0.160  # the nominal wheel radius and wheelbase (robot.*)


def world(spec: WorldSpec | None = None, **realism: object) -> World:
    real = RealismParams(**{"enabled": True, **realism}) if realism else RealismParams()
    return World(spec or WorldSpec(), Params(realism=real))


def run(w: World, v: float, omega: float, steps: int, name: str = "") -> None:
    w.command(name, v, omega)
    for _ in range(steps):
        w.step()


def square(w: World) -> float:
    """Drive a 1 m square open loop (counter-clockwise); return |odometry - truth| at the end."""
    for _ in range(4):
        run(w, 0.2, 0.0, 100)  # 5 s at 0.2 m/s
        run(w, 0.0, math.pi / 4, 40)  # 2 s at pi/4 rad/s: a quarter turn
    robot = w.robots[""]
    odom, truth = robot.odometry(), robot.state
    return math.hypot(odom.x - truth.x, odom.y - truth.y)


def test_the_default_is_exact_odometry_is_the_truth() -> None:
    """No profile: no plant, /odom is the very state the kinematic model integrates."""
    w = world()
    run(w, 0.3, 0.7, 50)
    robot = w.robots[""]
    assert robot.plant is None and robot.odometry() is robot.state


def test_a_profile_at_its_nominal_values_moves_as_the_ideal_model() -> None:
    """Enabled with every value at its default: the same path as the kinematic model."""
    ideal, real = world(), world(enabled=True)
    for w in (ideal, real):
        run(w, 0.3, 0.7, 50)
        run(w, -0.1, -1.2, 30)
    a, b = ideal.robots[""].state, real.robots[""]
    for got in (b.state, b.odometry()):
        assert (got.x, got.y, got.theta) == pytest.approx((a.x, a.y, a.theta), abs=1e-12)


def test_square_odometry_error_grows_with_the_geometry_error_and_vanishes_at_nominal() -> None:
    """UMBmark: a larger right wheel and a wider true wheelbase; odometry keeps the nominal."""
    errors = [
        square(world(wheel_radius_right=R * (1 + e), wheelbase=B * (1 + e)))
        for e in (0.0, 0.01, 0.02)
    ]
    assert errors[0] < 1e-9
    assert 0.01 < errors[1] < errors[2]
    # set back to the nominal values (0 = nominal, or the nominal figures themselves)
    assert square(world(wheel_radius_right=R, wheelbase=B)) < 1e-9


def test_motor_lag_is_a_first_order_step_response() -> None:
    """63.2 % of the commanded wheel speed at one time constant; the position its integral."""
    tau = 0.5
    w = world(motor_time_constant=tau)
    run(w, 0.2, 0.0, 10)  # 0.5 s at 20 Hz
    plant = w.robots[""].plant
    assert plant is not None
    assert plant.wheel[0] == pytest.approx(0.2 * (1 - math.exp(-1)), rel=1e-9)
    expected = 0.2 * (tau - tau * (1 - math.exp(-1)))  # integral of 0.2 (1 - e^(-t/tau))
    assert w.robots[""].state.x == pytest.approx(expected, rel=1e-9)


def test_latency_holds_a_command_back() -> None:
    """A command takes effect cmd_latency after it arrives, not before."""
    w = world(cmd_latency=0.2)
    run(w, 0.2, 0.0, 4)  # 0.2 s: not yet
    assert w.robots[""].state.x == 0.0
    for _ in range(2):
        w.step()
    assert w.robots[""].state.x == pytest.approx(0.2 * 0.1)


def test_the_deadband_stops_a_slow_command_and_passes_a_fast_one() -> None:
    w = world(deadband=0.05)
    run(w, 0.04, 0.0, 20)
    assert w.robots[""].state.x == 0.0
    run(w, 0.1, 0.0, 20)
    assert w.robots[""].state.x == pytest.approx(0.1)


def test_encoder_ticks_quantize_odometry() -> None:
    """/odom moves in whole ticks (2 pi r / ticks) while the truth moves smoothly."""
    ticks = 20
    w = world(encoder_ticks=ticks)
    run(w, 0.123, 0.0, 20)
    tick = 2 * math.pi * R / ticks
    odom, truth = w.robots[""].odometry(), w.robots[""].state
    assert truth.x == pytest.approx(0.123)
    assert odom.x / tick == pytest.approx(round(odom.x / tick), abs=1e-9)
    assert truth.x - tick < odom.x <= truth.x


def test_the_same_seed_gives_the_same_run_and_another_seed_another() -> None:
    def drive(seed: int) -> tuple[float, float, float]:
        w = world(slip=0.1, slip_stddev=0.05, seed=seed)
        run(w, 0.2, 0.5, 60)
        s = w.robots[""].state
        return s.x, s.y, s.theta

    assert drive(7) == drive(7)
    assert drive(7) != drive(8)


def test_slip_loses_travel_the_encoders_do_not_see_and_a_patch_has_its_own() -> None:
    w = world(slip=0.1)
    run(w, 0.2, 0.0, 20)
    robot = w.robots[""]
    assert robot.state.x == pytest.approx(0.18)
    assert robot.odometry().x == pytest.approx(0.2)
    rug = FloorPatch(polygon=[(0.5, -1.0), (5.0, -1.0), (5.0, 1.0), (0.5, 1.0)], slip=0.5)
    w = world(WorldSpec(floor=[rug]), slip=0.1)
    run(w, 0.2, 0.0, 100)  # 1 m of wheel travel: 0.5 m off the rug, then half lost on it
    x = w.robots[""].state.x
    assert 0.5 < x < 0.5 + 0.5 * 0.5 + 0.02


def test_one_robot_only_drives_its_own_profile() -> None:
    spec = WorldSpec.parse({"robots": [{"name": "r1"}, {"name": "r2", "pose": [0, 1, 0]}]})
    w = World(spec, Params())
    w.set_robot_realism("r2", {"enabled": True, "slip": 0.5})
    w.command("r1", 0.2, 0.0)
    run(w, 0.2, 0.0, 20, "r2")
    r1, r2 = w.robots["r1"], w.robots["r2"]
    assert r1.plant is None and r1.state.x == pytest.approx(0.2)
    assert r2.state.x == pytest.approx(0.1) and r2.odometry().x == pytest.approx(0.2)
    with pytest.raises(ValueError, match=r"realism.slip"):
        w.set_robot_realism("r2", {"slip": 2.0})
    w.set_robot_realism("r2", {"enabled": None, "slip": None})
    w.step()
    assert r2.plant is None and r2.odometry() is r2.state


def test_a_world_file_gives_a_robot_its_own_profile(tmp_path: object) -> None:
    spec = WorldSpec.parse(
        {
            "robots": [
                {"name": "r1"},
                {"name": "worn", "pose": [0, 1, 0], "realism": {"enabled": True, "deadband": 0.3}},
            ],
            "floor": [{"name": "rug", "polygon": [[0, 0], [1, 0], [1, 1]], "slip": 0.2}],
        }
    )
    w = World(spec, Params())
    assert w.robots["worn"].realism_own == {"enabled": True, "deadband": 0.3}
    run(w, 0.2, 0.0, 10, "worn")
    assert w.robots["worn"].state.x == 0.0


def test_collisions_use_the_truth_and_the_odometry_keeps_counting() -> None:
    """Against a wall the wheels spin: the truth stops, the encoders go on (slip-free)."""
    spec = WorldSpec.parse({"walls": [[0.5, -1, 0.5, 1]]})
    w = World(spec, Params(realism=RealismParams(enabled=True)))
    run(w, 0.2, 0.0, 60)  # 0.6 m of travel; the wall stops the footprint at 0.5 - radius
    robot = w.robots[""]
    assert robot.state.x == pytest.approx(0.5 - w.params.robot.radius, abs=1e-6)
    assert robot.odometry().x == pytest.approx(0.6)
    assert w.touching == {""}


def test_estop_and_reset_stop_the_plant_and_put_odometry_back_on_the_truth() -> None:
    w = world(motor_time_constant=0.3, cmd_latency=0.1, slip=0.2)
    run(w, 0.2, 0.3, 30)
    w.estop()
    w.step()
    plant = w.robots[""].plant
    assert plant is not None and plant.wheel == [0.0, 0.0] and not plant.pending
    w.release_estop()
    w.reset()
    robot = w.robots[""]
    assert (robot.odometry().x, robot.odometry().y) == (robot.state.x, robot.state.y) == (0, 0)


def test_lidar_dropout_reads_range_max_for_that_fraction_of_rays() -> None:
    spec = load_world(None)
    w = World(spec, Params(lidar=LidarParams(dropout=0.25)), seed=3)
    ranges = np.concatenate([w.scan("") for _ in range(20)])
    exact = np.tile(World(spec, Params()).scan(""), 20)
    dropped = ranges != exact
    assert np.all(ranges[dropped] == np.float32(3.5))
    assert 0.2 < np.mean(ranges == np.float32(3.5)) - np.mean(exact == np.float32(3.5)) < 0.3
