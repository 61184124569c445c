"""End to end: unmodified roslibjs 1.4.1, roslibjs 2.1.0 and roslibpy 2.1.0 drive simbridge."""

from __future__ import annotations

import itertools
import math
import statistics
from typing import Any

import pytest

from simbridge.app.runner import App
from tests.conftest import ClientRunner
from tests.helpers import ws_url


pytestmark = pytest.mark.e2e

CLIENTS = ["roslib1", "roslib2", "roslibpy"]
SIM_TOPICS = {
    "/cmd_vel": "geometry_msgs/msg/Twist",
    "/odom": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/scan": "sensor_msgs/msg/LaserScan",
    "/rosout": "rcl_interfaces/msg/Log",
}


@pytest.fixture
def client(run_js: ClientRunner, run_roslibpy: ClientRunner, request: pytest.FixtureRequest) -> Any:
    """Run a scenario with the client named by the test parameter."""
    lib = request.param

    async def run(url: str, scenario: str, args: dict[str, Any] | None = None) -> Any:
        if lib == "roslibpy":
            return await run_roslibpy(url, scenario, args)
        return await run_js(lib, url, scenario, args)

    return run


def parametrize_clients(fn: Any) -> Any:
    return pytest.mark.parametrize("client", CLIENTS, indirect=True)(fn)


@parametrize_clients
async def test_client_lists_every_simulated_topic_with_its_type(app: App, client: Any) -> None:
    """The client lists the robot's topics, with ROS 2 type names, /rosout included."""
    result = await client(ws_url(app), "topics", {"with_topic_type": True})
    listed = dict(zip(result["topics"], result["types"], strict=True))
    for name, type_name in SIM_TOPICS.items():
        assert listed.get(name) == type_name
    assert result["topic_types"]["/odom"] == "nav_msgs/msg/Odometry"


@parametrize_clients
async def test_odom_arrives_at_20_hz(app: App, client: Any) -> None:
    """/odom is published every 50 ms and reaches the client at that rate, odom -> base_link.

    The server's rate is checked on the header stamps (its publish times), tightly; the receive
    times only loosely, as a loaded machine delays the client process, not the server.
    """
    result = await client(ws_url(app), "odom_rate", {"count": 41})
    stamp_gaps = [b - a for a, b in itertools.pairwise(result["stamps"])]
    assert statistics.mean(stamp_gaps) == pytest.approx(50.0, abs=2.5)
    receive_gaps = [b - a for a, b in itertools.pairwise(result["times"])]
    assert statistics.mean(receive_gaps) == pytest.approx(50.0, abs=10.0)
    first = result["first"]
    assert first["header"]["frame_id"] == "odom"
    assert first["child_frame_id"] == "base_link"
    assert len(first["pose"]["covariance"]) == 36


@parametrize_clients
async def test_cmd_vel_for_two_seconds_advances_x_by_0_6_m(app: App, client: Any) -> None:
    """0.3 m/s for 2 s moves the robot 0.6 m along x, within one tick (0.015 m)."""
    result = await client(ws_url(app), "drive", {"v": 0.3, "w": 0.0, "seconds": 2.0})
    dx = result["final"]["x"] - result["start"]["x"]
    assert dx == pytest.approx(0.6, abs=0.3 * 0.05 + 1e-9)
    assert result["final"]["y"] == pytest.approx(0.0, abs=1e-9)
    assert result["twist_during_motion"]["max_linear_x"] == pytest.approx(0.3)


@parametrize_clients
async def test_turn_at_half_a_radian_per_second(app: App, client: Any) -> None:
    """0.5 rad/s for 2 s turns the robot by 1 rad (within one tick), in place."""
    result = await client(ws_url(app), "drive", {"v": 0.0, "w": 0.5, "seconds": 2.0})
    turned = result["final"]["yaw"] - result["start"]["yaw"]
    assert turned == pytest.approx(1.0, abs=0.5 * 0.05 + 1e-9)
    assert math.hypot(result["final"]["x"], result["final"]["y"]) == pytest.approx(0.0, abs=1e-9)
    assert result["twist_during_motion"]["max_angular_z"] == pytest.approx(0.5)


@parametrize_clients
async def test_cmd_vel_is_clamped_to_the_robot_limits(app: App, client: Any) -> None:
    """A 2 m/s command moves the robot at max_linear_velocity (0.5 m/s) and odom says so."""
    result = await client(ws_url(app), "drive", {"v": 2.0, "w": 0.0, "seconds": 1.0})
    assert result["twist_during_motion"]["max_linear_x"] == pytest.approx(0.5)


@parametrize_clients
async def test_scan_has_360_consistent_rays(app: App, client: Any) -> None:
    """/scan: 360 ranges within [range_min, range_max], angle_max = 359 increments, frame laser."""
    scan = await client(ws_url(app), "scan")
    assert scan["header"]["frame_id"] == "laser"
    assert len(scan["ranges"]) == 360
    assert scan["angle_min"] == 0.0
    assert scan["angle_increment"] == pytest.approx(2 * math.pi / 360)
    assert scan["angle_max"] == pytest.approx(359 * 2 * math.pi / 360)
    assert scan["range_min"] == pytest.approx(0.12)
    assert scan["range_max"] == pytest.approx(3.5)
    assert scan["scan_time"] == pytest.approx(0.1)
    assert all(0.12 - 1e-6 <= r <= 3.5 + 1e-6 for r in scan["ranges"])
    # default world: the wall 2 m to the left (north) of the robot at the origin
    assert scan["ranges"][90] == pytest.approx(2.0, abs=1e-4)


@parametrize_clients
async def test_tf_and_latched_tf_static(app: App, client: Any) -> None:
    """/tf carries odom -> base_link; a late subscriber still gets /tf_static base_link -> laser."""
    result = await client(ws_url(app), "tf")
    tf = result["tf"]["transforms"][0]
    assert (tf["header"]["frame_id"], tf["child_frame_id"]) == ("odom", "base_link")
    static = result["tf_static"]["transforms"][0]
    assert (static["header"]["frame_id"], static["child_frame_id"]) == ("base_link", "laser")


@parametrize_clients
async def test_chatter_round_trip_reaches_the_publisher_once(app: App, client: Any) -> None:
    """A client publishing std_msgs/String on /chatter receives its own message exactly once."""
    result = await client(ws_url(app), "chatter", {"text": "hello simbridge"})
    assert result["messages"] == [{"data": "hello simbridge"}]


@parametrize_clients
async def test_reset_puts_the_robot_back_at_its_start_pose(app: App, client: Any) -> None:
    """After driving, /reset (std_srvs/Empty) returns the robot to the start pose, stopped."""
    app.world.command("", 0.4, 0.3)
    for _ in range(10):
        app.world.step()
    assert app.world.robots[""].state.x > 0.1
    result = await client(ws_url(app), "reset")
    assert result["response"] == {}
    state = app.world.robots[""].state
    assert (state.x, state.y, state.theta, state.v, state.omega) == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert (app.world.robots[""].cmd_v, app.world.robots[""].cmd_omega) == (0.0, 0.0)


@parametrize_clients
async def test_unknown_service_fails_at_once_with_a_reason(app: App, client: Any) -> None:
    """Calling a service nobody provides gives result false and a message, not a hang."""
    result = await client(ws_url(app), "unknown_service")
    assert result["fail_called"] is True
    assert result["timed_out"] is False
    assert "does not exist" in result["fail_value"]


@parametrize_clients
async def test_param_reads_and_sets_a_robot_limit_live(app: App, client: Any) -> None:
    """ROSLIB.Param / roslibpy.Param read and change /virtual_robot's speed limit at once."""
    name = "/virtual_robot:robot.max_linear_velocity"
    result = await client(ws_url(app), "param", {"name": name, "value": 0.25})
    assert result["before"] == pytest.approx(0.5)
    assert result["after"] == pytest.approx(0.25)
    assert app.world.params.robot.max_linear_velocity == pytest.approx(0.25)
    assert app.world.command("", 1.0, 0.0) == (0.25, 0.0)


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_bad_publishes_get_status_errors_and_nothing_breaks(
    app: App, run_js: ClientRunner, lib: str
) -> None:
    """Ill-typed, non-finite, unknown-field /cmd_vel from roslibjs: status errors, robot still."""
    result = await run_js(lib, ws_url(app), "bad_publish")
    texts = [s["msg"] for s in result["statuses"]]
    assert all(s["level"] == "error" for s in result["statuses"])
    assert any("linear.x must be a float64" in t for t in texts)
    assert any("finite" in t for t in texts)
    assert any("does not have a field wings" in t for t in texts)
    assert result["echoed"] == {"data": "still alive"}
    assert result["x"] == 0.0 and app.world.robots[""].cmd_v == 0.0


async def test_roslibpy_bad_publishes_leave_the_connection_and_robot_intact(
    app: App, run_roslibpy: ClientRunner
) -> None:
    """Roslibpy's bad publishes (a string, a NaN) change nothing; the session goes on."""
    result = await run_roslibpy(ws_url(app), "bad_publish")
    assert result["echoed"] == {"data": "still alive"}
    assert result["x"] == 0.0 and app.world.robots[""].cmd_v == 0.0


@pytest.mark.parametrize(
    ("frames", "expected"),
    [
        (["{not json"], "could not decode the text frame"),
        (['{"op": "levitate"}'], "unknown operation 'levitate'"),
        (['{"op": "subscribe"}'], "expected a topic field"),
        (['{"op": "subscribe", "topic": "/odom", "throttle_rate": "fast"}'], "throttle_rate"),
        ([{"binary": "//79"}], "could not decode the binary frame"),
    ],
)
async def test_raw_bad_frames_get_one_status_error_each(
    app: App, run_js: ClientRunner, frames: list[Any], expected: str
) -> None:
    """Invalid JSON, unknown ops, missing or wrong-typed fields: a status error, socket open."""
    result = await run_js("roslib2", ws_url(app), "raw", {"frames": frames, "collect_ms": 300})
    assert result["close"] is None
    (reply,) = result["replies"]
    assert reply["op"] == "status" and reply["level"] == "error"
    assert expected in reply["msg"]


@parametrize_clients
async def test_throttle_rate_limits_what_a_subscriber_receives(app: App, client: Any) -> None:
    """throttle_rate 200 ms on the 20 Hz /odom: one message per 200 ms (4 of 5 dropped)."""
    result = await client(ws_url(app), "throttle", {"throttle_rate": 200, "count": 6})
    # on the publish stamps: the client's own scheduling delays are not the server's throttle
    gaps = [b - a for a, b in itertools.pairwise(result["stamps"])]
    assert min(gaps) >= 150  # never two inside the window (one tick of jitter allowed)
    assert statistics.mean(gaps) == pytest.approx(200, abs=30)
    assert len(result["times"]) == len(result["stamps"])
