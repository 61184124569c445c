"""End to end: the tutorial nodes and ROS 1-era clients, with unmodified roslibjs 1.4.1 and 2.1."""

from __future__ import annotations

import math
from typing import Any

import pytest

from simbridge.config import WorldSpec
from tests.conftest import ClientRunner
from tests.helpers import ws_url


pytestmark = pytest.mark.e2e

#: A world file with the turtlesim tutorial's static frame, and the tutorial nodes on.
WORLD = WorldSpec.parse(
    {
        "demo_nodes": True,
        "frames": [{"parent": "world", "child": "turtle1", "pose": [1.0, 2.0, math.pi / 2]}],
    }
)


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_examples_work_against_the_tutorial_nodes(
    make_app: Any, run_js: ClientRunner, lib: str
) -> None:
    """chatter, add_two_ints, actionlib and ROS 2 fibonacci, and the default TFClient."""
    app = await make_app(world=WORLD)
    r = await run_js(lib, ws_url(app), "tutorials", {"order": 3}, timeout=30)
    chat = r["chatter"]
    assert chat["talker"][0].startswith("Hello World: ")
    assert "I heard: [hello from roslibjs]" in chat["heard"]
    assert r["sum"] == {"sum": 3}
    al = r["actionlib"]
    assert al["result"] == [0, 1, 1, 2]
    assert al["feedback"] == [[0, 1, 1], [0, 1, 1, 2]]
    assert 1 in al["statuses"] and 3 in al["statuses"]  # ACTIVE, then SUCCEEDED (ROS 1 numbers)
    tf = r["tf"]
    assert tf["translation"] == pytest.approx({"x": 1.0, "y": 2.0, "z": 0.0})
    half = math.sqrt(0.5)
    assert tf["rotation"] == pytest.approx({"x": 0.0, "y": 0.0, "z": half, "w": half})
    if lib == "roslib1":
        return
    ros2 = r["ros2"]
    assert ros2["ok"] == {"result": [0, 1, 1, 2], "feedback": [[0, 1, 1], [0, 1, 1, 2]]}
    assert "Action was canceled" in ros2["canceled"]["error"]


async def test_roslibpy_examples_work_against_the_tutorial_nodes(
    make_app: Any, run_roslibpy: ClientRunner
) -> None:
    """roslibpy: talker, add_two_ints, ROS 1 actionlib and ROS 2 fibonacci, TFClient (service)."""
    app = await make_app(world=WORLD)
    r = await run_roslibpy(ws_url(app), "tutorials", {"order": 3}, timeout=30)
    assert r["chatter"]["talker"][0].startswith("Hello World: ")
    assert r["sum"] == {"sum": 3}
    assert r["actionlib"] == {
        "result": [0, 1, 1, 2],
        "feedback": [[0, 1, 1], [0, 1, 1, 2]],
        "status": 3,
    }
    assert r["ros2"] == {"status": 4, "values": {"sequence": [0, 1, 1, 2]}}
    assert r["tf"] == pytest.approx({"x": 1.0, "y": 2.0, "z": 0.0})
