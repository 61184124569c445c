"""A graded run whose controller is a ROS 2 node over Zenoh (zenoh-ros2-sdk).

The student starts the run with their token (as the page's Tasks tab does); their controller is
a ROS 2 node: it subscribes to its robot's /odom and publishes /cmd_vel. In class mode ROS 2
peers drive nothing by default, so the instructor gives them the robot (``ros2_role``).
"""

from __future__ import annotations

import contextlib
import json
import math
import threading
from collections.abc import AsyncIterator, Iterator
from typing import Any

import pytest

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.tools.client import RosbridgeClient
from tests.helpers import ROOT, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router, zenoh_options


pytestmark = pytest.mark.e2e

CLASSROOM = ROOT / "config" / "worlds" / "classroom.yaml"
ADMIN = "instructor-token-zz"
TOKENS = {"student-token-r1": "r1"}
#: A heading step of 1 rad from the start pose, scored over 2.5 s, on a slower-turning robot.
TASK = """
name: heading step by a ROS 2 node
frame: start
goal: {heading: 1.0, tolerance: 0.05}
time_limit: 2.5
robot_params: {robot.max_angular_velocity: 2.0}
rubric:
  overshoot_pct: {max: 10}
  settling_time_s: {max: 2.0}
  steady_state_error: {max: 0.03}
"""


@contextlib.asynccontextmanager
async def class_server(router: Router, **settings: Any) -> AsyncIterator[App]:
    """The classroom world in class mode (r1's token, an admin token) on the router."""
    app = App(
        ServerSettings(
            host="127.0.0.1",
            port=0,
            http_port=0,
            client_tokens=TOKENS,
            admin_token=ADMIN,
            **settings,
        ),
        world=CLASSROOM,
        zenoh=zenoh_options(router),
    )
    await app.start()
    try:
        yield app
    finally:
        await app.stop()


async def start_run(app: App) -> dict[str, Any]:
    """Start the task on r1 with r1's token (a rosbridge client, as the page does)."""
    async with RosbridgeClient.connect(ws_url(app) + "/?token=student-token-r1", 5.0) as ros:
        values = await ros.call_service("/simbridge/grade/start", {"task_yaml": TASK, "task": "h"})
    state: dict[str, Any] = json.loads(values["message"])
    return state


@contextlib.contextmanager
def heading_node(router: Router, robot: str, goal: float) -> Iterator[list[float]]:
    """A ROS 2 node: a P controller on the heading of ``robot``'s /odom, /cmd_vel at its rate.

    Yields the commanded angular speeds (one per /odom message).
    """
    from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber, get_message_class

    kw = {"router_ip": "127.0.0.1", "router_port": router.port, "node_name": "heading_p"}
    vector = get_message_class("geometry_msgs/msg/Vector3")
    pub = ROS2Publisher(f"/{robot}/cmd_vel", "geometry_msgs/msg/Twist", **kw)
    sent: list[float] = []
    lock = threading.Lock()

    def on_odom(msg: Any) -> None:
        q = msg.pose.pose.orientation
        yaw = 2.0 * math.atan2(q.z, q.w)
        err = math.atan2(math.sin(goal - yaw), math.cos(goal - yaw))
        w = max(-2.5, min(2.5, 3.0 * err))
        with lock:  # the SDK calls back on Zenoh's threads
            pub.publish(linear=vector(x=0.0, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=w))
            sent.append(w)

    sub = ROS2Subscriber(f"/{robot}/odom", "nav_msgs/msg/Odometry", on_odom, **kw)
    try:
        yield sent
    finally:
        sub.close()
        with lock:
            pub.close()


async def test_a_ros2_node_given_the_robot_is_graded_and_one_without_it_cannot_drive_the_run(
    router: Router, ros2: Any
) -> None:
    # the class default: ROS 2 peers have no robot; the node's /cmd_vel never reaches the run
    async with class_server(router) as app:
        link = app.zenoh
        assert link is not None
        state = await start_run(app)
        r1 = app.world.robots["r1"]
        pose = (r1.state.x, r1.state.y, r1.state.theta)
        with heading_node(router, "r1", state["goal"]["heading"]) as sent:
            await wait_for(lambda: "/r1/cmd_vel" in link._by_name and len(sent) >= 10, timeout=8)
        assert "/r1/cmd_vel" not in link._subscribers  # refused: never subscribed
        assert app.grader.runs["r1"].phase == "waiting"
        assert (r1.state.x, r1.state.y, r1.state.theta) == pose
        assert app.world.robot_params("r1").max_angular_velocity == 2.0
    # the server stopped mid-run: the attempt is interrupted, the robot's parameters are back
    assert app.grader.results.attempts[state["attempt"]]["status"] == "interrupted"
    assert r1.overrides == {}
    # the instructor gives ROS 2 peers robot r1 (a trusted network): the node is graded
    async with class_server(router, ros2_role="robot:r1") as app:
        state = await start_run(app)
        attempt = state["attempt"]
        with heading_node(router, "r1", state["goal"]["heading"]):
            await wait_for(lambda: "r1" not in app.grader.runs, timeout=10)
            # the time limit ended while the node still sends: its own parameters are back
            assert app.world.robots["r1"].overrides == {}
        record = app.grader.results.attempts[attempt]
        assert record["status"] == "passed", record["rubric"]
        assert record["duration_s"] == pytest.approx(2.5)
        assert abs(record["metrics"]["steady_state_error"]) < 0.03
