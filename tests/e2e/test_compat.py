"""End to end, issue 3: every rosapi service, parameters, services, actions, encodings, TF.

Each test runs one grouped scenario per client (roslibjs 1.4.1, 2.1.0, roslibpy 2.1.0) so that
the suite stays short; the scenario results are checked here.
"""

from __future__ import annotations

import asyncio
import base64
import json
import math
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from tests.conftest import ClientRunner
from tests.helpers import ws_url


pytestmark = pytest.mark.e2e

CLIENTS = ["roslib1", "roslib2", "roslibpy"]


@pytest.fixture
def client(run_js: ClientRunner, run_roslibpy: ClientRunner, request: pytest.FixtureRequest) -> Any:
    """Run a scenario with the client named by the test parameter."""
    lib = request.param

    async def run(url: str, scenario: str, args: dict[str, Any] | None = None) -> Any:
        if lib == "roslibpy":
            return await run_roslibpy(url, scenario, args)
        return await run_js(lib, url, scenario, args)

    run.lib = lib  # type: ignore[attr-defined]
    return run


def parametrize_clients(fn: Any) -> Any:
    return pytest.mark.parametrize("client", CLIENTS, indirect=True)(fn)


@parametrize_clients
async def test_every_rosapi_service_and_parameter_interface(app: App, client: Any) -> None:
    """The rosapi helpers, rosapi services by name, Param, and /virtual_robot rcl_interfaces."""
    r = await client(ws_url(app), "rosapi_all")
    lib = client.lib
    assert "/rosout" in r["topics"]["topics"]
    assert set(r["topicsForType"]) == {"/tf", "/tf_static"}
    assert "/reset" in r["services"] and "/virtual_robot/get_parameters" in r["services"]
    assert r["servicesForType"] == ["/reset"]
    (addtwo,) = r["requestDetails"]["typedefs"]
    assert addtwo["fieldnames"] == ["a", "b"] and addtwo["fieldtypes"] == ["int64", "int64"]
    assert r["responseDetails"]["typedefs"][0]["fieldnames"] == ["value", "successful", "reason"]
    assert {"/virtual_robot", "/rosapi", "/rosbridge_websocket"} <= set(r["nodes"])
    details = r["nodeDetails"]
    assert "/odom" in details["publishing"] and details["subscribing"] == ["/cmd_vel"]
    assert "/reset" in details["services"]
    assert "/virtual_robot:robot.max_linear_velocity" in r["params"]
    assert r["topicType"] == "sensor_msgs/msg/LaserScan"
    assert r["serviceType"] == "std_srvs/srv/Empty"
    typedefs = r["messageDetails"]
    assert typedefs[0]["type"] == "nav_msgs/Odometry"
    nested = {t["type"] for t in typedefs}
    for t in typedefs:  # every nested fieldtype has its own entry (roslibjs decodeTypeDefs)
        for ftype in t["fieldtypes"]:
            assert "/" not in ftype or ftype in nested
    covariance = typedefs[[t["type"] for t in typedefs].index("geometry_msgs/PoseWithCovariance")]
    assert covariance["fieldarraylen"] == [-1, 36] and covariance["fieldtypes"][1] == "double"
    if lib != "roslibpy":
        assert r["decoded"]["pose"]["pose"]["position"] == {
            "x": "double",
            "y": "double",
            "z": "double",
        }
        assert r["decoded"]["child_frame_id"] == "string"
    raw = r["rawTypes"]
    listed = dict(zip(raw["topics"], raw["types"], strict=True))
    assert listed["/rosout"] == "rcl_interfaces/msg/Log"
    odom_text = raw["typedefs_full_text"][raw["topics"].index("/odom")]
    assert odom_text.startswith("std_msgs/Header header\n")
    assert "\n" + "=" * 80 + "\nMSG: geometry_msgs/PoseWithCovariance\n" in odom_text
    assert r["actionServers"] == ["/tf2_web_republisher"]
    if lib == "roslib2":
        assert r["publishers"] == ["/virtual_robot"]
    else:
        assert r.get("publishers", ["/virtual_robot"]) == ["/virtual_robot"]
    assert r["subscribers"] == {"subscribers": ["/virtual_robot"]}
    assert r["providers"] == {"providers": ["/virtual_robot"]}
    assert r["serviceNode"] == {"node": "/virtual_robot"}
    assert r["hasParam"] == {"exists": True}
    assert r["time"]["time"]["secs"] > 1_600_000_000
    if lib != "roslibpy":
        assert r["version"] == {"version": 2, "distro": "jazzy"}
        assert r["topicTypeList"] == {"type": "nav_msgs/msg/Odometry"}
    assert r["interfaces"] > 150
    assert r["paramGet"] == {"ok": True, "value": 1.25}
    assert app.world.params.robot.max_angular_velocity == 1.25
    if lib == "roslib2":  # 2.1.0 reads successful/reason
        assert r["paramDelete"]["ok"] is False and "cannot be deleted" in r["paramDelete"]["error"]
        assert (
            r["paramUnknown"]["ok"] is False and "no parameter 'nope'" in r["paramUnknown"]["error"]
        )
    else:  # 1.4.1 and roslibpy ignore them; the value is still valid JSON ('""')
        assert r["paramUnknown"] == {"ok": True, "value": ""}
    values = r["getParameters"]["values"]
    assert (values[0]["type"], values[0]["double_value"]) == (3, 1.5)
    assert (values[1]["type"], values[1]["integer_value"]) == (2, 360)
    first, second = r["setParameters"]["results"]
    assert first == {"successful": True, "reason": ""}
    assert second["successful"] is False and "range_min" in second["reason"]
    assert app.world.params.lidar.range_max == 3.0
    assert app.world.params.lidar.range_min == pytest.approx(0.12)
    names = r["listParameters"]["result"]["names"]
    assert "robot.mass" in names and not any(n.startswith("lidar") for n in names)
    (descriptor,) = r["describeParameters"]["descriptors"]
    assert descriptor["name"] == "lidar.range_max" and descriptor["type"] == 3


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_services_and_actions_between_clients(
    make_app: Any, run_js: ClientRunner, lib: str
) -> None:
    """Client-provided services in every reply shape, timeouts, and (2.x) ROS 2 actions."""
    app = await make_app(service_timeout=1.0)
    r = await run_js(lib, ws_url(app), "services_actions")
    s = r["services"]
    assert s["object"] == {"ok": True, "value": {"sum": 5}}
    assert s["list"] == {"ok": True, "value": {"sum": 42}}
    if lib == "roslib1":  # values without result: success
        assert s["quiet"] == {"ok": True, "value": {"success": True, "message": "no result key"}}
    else:  # 2.1 sends neither result nor values when the callback returns nothing: failure
        assert s["quiet"]["ok"] is False and "no result" in s["quiet"]["error"]
    if lib == "roslib1":  # values {} with result false: the values answer, as in rosbridge
        assert s["refuse"] == {"ok": True, "value": {"success": False, "message": ""}}
    else:  # 2.1 sends result false without values: failure
        assert s["refuse"]["ok"] is False
    assert s["topicsWhileWaiting"] is True
    assert s["slow"]["ok"] is False and "timed out" in s["slow"]["error"]
    # roslibjs 2.1 sends timeout 0.4 s; 1.4.1 gets the server default (1 s here)
    assert s["slowMs"] < (900 if lib == "roslib2" else 2500)
    if lib == "roslib1":
        return
    assert s["asyncFail"] == {"ok": False, "error": "Error: no can do"}
    a = r["actions"]
    assert a["actionServers"] == ["/fibonacci", "/tf2_web_republisher"]
    ok = a["succeeded"]
    assert ok["ok"] is True and ok["result"] == {"sequence": [0, 1, 1, 2, 3, 5, 8]}
    assert ok["feedback"][-1] == {"sequence": [0, 1, 1, 2, 3, 5, 8]} and len(ok["feedback"]) == 5
    assert a["failed"]["ok"] is False and "aborted" in a["failed"]["error"].lower()
    assert a["canceled"]["ok"] is False and "cancel" in a["canceled"]["error"].lower()
    assert a["canceled"]["feedback"]
    assert all(not x["ok"] and "cancel" in x["error"].lower() for x in a["cancelAll"])
    assert a["cancels"] == 3
    assert "does not exist" in a["missing"]


async def _fibonacci_server(url: str, ready: asyncio.Event) -> None:
    """A minimal ROS 2 action server speaking the protocol (roslibpy has none of its own)."""
    async with connect(url) as ws:
        await ws.send(
            json.dumps(
                {
                    "op": "advertise_action",
                    "action": "/fibonacci",
                    "type": "example_interfaces/action/Fibonacci",
                }
            )
        )
        ready.set()
        tasks: dict[str, asyncio.Task[None]] = {}

        async def result(goal_id: str, values: Any, status: int, ok: bool = True) -> None:
            body = {"op": "action_result", "id": goal_id, "action": "/fibonacci"}
            body |= {"values": values, "status": status, "result": ok}
            await ws.send(json.dumps(body))

        async def forever(goal_id: str) -> None:
            while True:
                feedback = {"op": "action_feedback", "id": goal_id, "action": "/fibonacci"}
                await ws.send(json.dumps(feedback | {"values": {"sequence": [0, 1]}}))
                await asyncio.sleep(0.02)

        async for frame in ws:
            msg = json.loads(frame)
            if msg["op"] == "send_action_goal":
                order, goal_id = msg["args"]["order"], msg["id"]
                if order < 0:
                    await result(goal_id, None, 6, ok=False)
                elif order > 50:
                    tasks[goal_id] = asyncio.create_task(forever(goal_id))
                else:
                    seq = [0, 1]
                    for i in range(2, order + 1):
                        seq.append(seq[i - 1] + seq[i - 2])
                        feedback = {"op": "action_feedback", "id": goal_id, "action": "/fibonacci"}
                        await ws.send(json.dumps(feedback | {"values": {"sequence": seq}}))
                    await result(goal_id, {"sequence": seq}, 4)
            elif msg["op"] == "cancel_action_goal":
                tasks.pop(msg["id"]).cancel()
                await result(msg["id"], {"sequence": [0, 1]}, 5)


async def test_roslibpy_services_and_action_client(
    make_app: Any, run_roslibpy: ClientRunner
) -> None:
    """Roslibpy serves and calls services (result null and false too) and runs action goals."""
    app = await make_app(service_timeout=1.0)
    ready = asyncio.Event()
    server = asyncio.create_task(_fibonacci_server(ws_url(app), ready))
    try:
        await asyncio.wait_for(ready.wait(), 5)
        r = await run_roslibpy(ws_url(app), "services_actions")
    finally:
        server.cancel()
    s = r["services"]
    assert s["object"] == {"ok": True, "value": {"sum": 5}}
    assert s["quiet"] == {"ok": True, "value": {"success": True, "message": "no result key"}}
    # the callback returned False with the response filled: rosbridge answers with the values
    assert s["refuse"] == {"ok": True, "value": {"success": False, "message": ""}}
    assert s["slow"]["ok"] is False and "timed out" in s["slow"]["error"]
    assert s["slowMs"] < 2500
    a = r["actions"]
    ok = a["succeeded"]
    assert (ok["ok"], ok["status"], ok["values"]) == (True, 4, {"sequence": [0, 1, 1, 2, 3, 5, 8]})
    assert len(ok["feedback"]) == 5
    assert (a["failed"]["ok"], a["failed"]["status"]) == (False, 6)
    assert (a["canceled"]["ok"], a["canceled"]["status"]) == (True, 5)
    assert a["canceled"]["feedback"]
    assert a["missing"]["ok"] is False and "does not exist" in a["missing"]["values"]
    assert r["latched"] == {"data": "kept for late subscribers"}


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_compressions_fragments_and_latching(
    app: App, run_js: ClientRunner, lib: str
) -> None:
    """none, cbor, png, cbor-raw side by side on /scan; fragments; a latched late message."""
    r = await run_js(lib, ws_url(app), "encodings")
    scan = r["scan"]
    for key in ("none", "cbor", "png"):
        assert (scan[key]["frame"], scan[key]["n"]) == ("laser", 360)
    assert scan["cbor"]["rangesTyped"] == "Float32Array"
    assert scan["cbor"]["first"] == pytest.approx(scan["png"]["first"], rel=1e-6)
    assert scan["cbor"]["intensities"] == []
    assert r["odomCbor"] == {"covariance": "Float64Array", "n": 36, "frame": "base_link"}
    data = base64.b64decode(scan["raw"]["bytes"])
    assert data[:4] == b"\x00\x01\x00\x00"
    decoded = app.graph.registry.store.deserialize_cdr(data, "sensor_msgs/msg/LaserScan")
    assert decoded.header.frame_id == "laser" and len(decoded.ranges) == 360
    assert scan["raw"]["secs"] > 1_600_000_000
    assert r["latched"] == {"data": "kept for late subscribers"}
    assert r["passThrough"] == {"a": 1, "nested": {"b": "x", "list": [1.5, None]}}
    assert r["fragIn"] == {"data": "reassembled"}
    if lib == "roslib2":
        frag = r["fragmented"]
        assert (frag["n"], frag["frame"]) == (360, "laser") and frag["pieces"] >= 2
        assert r["fragmentedService"] == {"result": True, "hasOdom": True}


@parametrize_clients
async def test_tf_clients_get_live_transforms_from_the_republisher(app: App, client: Any) -> None:
    """TFClient (service), ROS2TFClient (action), roslibpy TFClient: odom->base_link, ->laser."""
    r = await client(ws_url(app), "tf_clients")
    mx, my, myaw = app.world.params.lidar.mount
    first = r["first"]
    assert first["base_link"]["rotation"]["w"] == pytest.approx(1.0, abs=0.05)
    laser = first["laser"]["translation"]
    assert (laser["x"], laser["y"]) == (pytest.approx(mx, abs=0.05), pytest.approx(my, abs=0.05))
    assert first["laser"]["rotation"]["z"] == pytest.approx(math.sin(myaw / 2), abs=0.05)
    turned = r["turned"]["base_link"]["rotation"]
    assert turned["z"] > 0.1 and turned["z"] ** 2 + turned["w"] ** 2 == pytest.approx(1.0)
    assert r["counts"]["base_link"] >= 2


async def test_a_tf_client_with_negative_thresholds_gets_every_transform(
    app: App, run_js: ClientRunner
) -> None:
    """A negative threshold (roslibjs passes it through) gets a transform every tick."""
    r = await run_js("roslib1", ws_url(app), "tf_every", {"count": 5})
    assert r["count"] >= 5 and r["last"]["w"] == pytest.approx(1.0)
    assert r["seconds"] >= 0.2  # about one transform a tick at 10 Hz, not one burst
