"""End to end: the tutorial nodes and ROS 1-era clients, with unmodified roslibjs 1.4.1 and 2.1."""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import sys
from collections.abc import AsyncIterator
from typing import Any

import pytest

from simbridge.app.config import WorldSpec
from simbridge.app.runner import App
from tests.conftest import ClientRunner
from tests.helpers import ROOT, finish_process, ws_url


pytestmark = pytest.mark.e2e

#: A world file with the turtlesim tutorial's static frame, and the tutorial nodes on.
WORLD = WorldSpec.parse(
    {
        "demo_nodes": True,
        "frames": [{"parent": "world", "child": "turtle1", "pose": [1.0, 2.0, math.pi / 2]}],
    }
)


#: What roslibjs's own test launch files start beside rosbridge: ``rostopic pub /listener
#: std_msgs/String "Hello, World"`` (ROS 1), ``ros2 topic pub --rate 1 /listener ...`` (ROS 2).
LISTENER_FIXTURE = ("topic", "pub", "/listener", "std_msgs/msg/String", "data: Hello, World")
FIB = [0, 1, 1, 2, 3, 5, 8]


@contextlib.asynccontextmanager
async def listener_fixture(app: App) -> AsyncIterator[None]:
    """``simbridge topic pub -r 1 /listener ...`` running, as roslibjs's fixture (stopped after)."""
    proc = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "simbridge", *LISTENER_FIXTURE, "-r", "1", "--url", ws_url(app)),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    try:
        yield
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGINT)
        code, _out, err = await finish_process(proc, 10)
        assert code == 0, err


def check_tutorials(r: dict[str, Any], order: int) -> None:
    """What every client gets of the tutorial nodes (the ROS 1 and the shared parts)."""
    assert r["chatter"]["talker"][0].startswith("Hello World: ")
    assert r["sum"] == {"sum": 3}
    al = r["actionlib"]
    # actionlib_tutorials' fibonacci_server: `order` feedbacks, order + 2 numbers
    assert al["result"] == FIB[: order + 2]
    assert al["feedback"] == [FIB[: n + 3] for n in range(order)]
    # every ROS 2 node's use_sim_time, through rosapi (roslibjs 2.x's params example)
    assert r["simTime"] == {"values": [False, True, False], "listed": True}


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_examples_work_against_the_tutorial_nodes(
    make_app: Any, run_js: ClientRunner, lib: str
) -> None:
    """chatter, add_two_ints, both Fibonacci servers, use_sim_time, the default TFClient.

    roslib2 runs with roslibjs's /listener fixture, as its check-topics example expects.
    """
    app = await make_app(world=WORLD)
    args = {"order": 2, "listener_fixture": lib == "roslib2"}
    async with listener_fixture(app) if lib == "roslib2" else contextlib.nullcontext():
        r = await run_js(lib, ws_url(app), "tutorials", args, timeout=30)
    check_tutorials(r, 2)
    assert "I heard: [hello from roslibjs]" in r["chatter"]["heard"]
    assert 1 in r["actionlib"]["statuses"] and 3 in r["actionlib"]["statuses"]  # ROS 1 numbers
    tf = r["tf"]
    assert tf["translation"] == pytest.approx({"x": 1.0, "y": 2.0, "z": 0.0})
    half = math.sqrt(0.5)
    assert tf["rotation"] == pytest.approx({"x": 0.0, "y": 0.0, "z": half, "w": half})
    if lib == "roslib1":
        # the tutorials' world has the node /listener, not a topic of that name
        assert r["listener"] == {"node": True, "topic": False}
        return
    assert r["listener"] == {"node": True, "topic": True, "message": {"data": "Hello, World"}}
    ros2 = r["ros2"]
    assert ros2["ok"] == {"result": [0, 1, 1], "feedback": [[0, 1, 1]]}
    assert "Action was canceled" in ros2["canceled"]["error"]
    # a goal typed action_tutorials_interfaces gets that type's feedback field
    assert ros2["tutorialType"] == {
        "result": {"sequence": [0, 1, 1]},
        "feedback": [{"partial_sequence": [0, 1, 1]}],
    }


async def test_roslibpy_examples_work_against_the_tutorial_nodes(
    make_app: Any, run_roslibpy: ClientRunner
) -> None:
    """roslibpy: talker, add_two_ints, actionlib and ROS 2 Fibonacci, use_sim_time, TFClient.

    The ROS 2 goals are sent with both Fibonacci types; the TFClient is roslibpy's (service).
    """
    app = await make_app(world=WORLD)
    r = await run_roslibpy(ws_url(app), "tutorials", {"order": 2}, timeout=30)
    check_tutorials(r, 2)
    assert r["actionlib"]["status"] == 3
    assert r["ros2"] == {
        "example_interfaces": {
            "status": 4,
            "values": {"sequence": [0, 1, 1]},
            "feedback": [{"sequence": [0, 1, 1]}],
        },
        "action_tutorials_interfaces": {
            "status": 4,
            "values": {"sequence": [0, 1, 1]},
            "feedback": [{"partial_sequence": [0, 1, 1]}],
        },
    }
    assert r["tf"] == pytest.approx({"x": 1.0, "y": 2.0, "z": 0.0})
    assert r["listener"] == {"node": True, "topic": False}
