"""roslibpy 2.1.0 client scenarios, mirroring tests/js/scenarios/*.mjs.

Every scenario is ``fn(roslibpy, ros, args) -> JSON-serialisable result`` and is
run by ``roslibpy_run.py`` in the main thread while Twisted's reactor runs in
roslibpy's own thread. roslibpy calls subscription/service callbacks on the
reactor thread, so the helpers here hand results over with ``threading``
primitives and always wait with a timeout (seconds, like roslibpy itself).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any


JSON = Any


def now_ms() -> float:
    """Monotonic clock in milliseconds (the receive timestamps we report)."""
    return time.perf_counter() * 1000.0


class ServiceFailure(Exception):
    """The service's errback fired (``result: false``); ``values`` is what it got."""

    def __init__(self, service: str, values: JSON) -> None:
        super().__init__(f"service {service} failed: {values!r}")
        self.values = values


def wait_for(predicate: Callable[[], Any], timeout_s: float, what: str = "condition") -> Any:
    """Poll ``predicate`` until it returns something truthy; return that value."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() >= deadline:
            raise TimeoutError(f"timeout: {what} not met within {timeout_s} s")
        time.sleep(0.005)


def collect(
    roslibpy: Any,
    ros: Any,
    name: str,
    message_type: str,
    n: int,
    timeout_s: float,
    keep: bool = False,
) -> tuple[list[JSON], list[float]]:
    """Subscribe to ``name`` and return ``(messages, receive_times_ms)`` once n arrived.

    Unsubscribes afterwards unless ``keep``. Note that roslibpy's
    ``Topic.unsubscribe`` removes *every* callback registered for that topic
    name on the Ros object, not just this Topic's.
    """
    topic = roslibpy.Topic(ros, name, message_type)
    messages: list[JSON] = []
    times: list[float] = []
    done = threading.Event()
    lock = threading.Lock()

    def on_message(msg: JSON) -> None:
        t = now_ms()
        with lock:
            if len(messages) >= n:
                return
            messages.append(msg)
            times.append(t)
            if len(messages) >= n:
                done.set()

    topic.subscribe(on_message)
    try:
        if not done.wait(timeout_s):
            raise TimeoutError(
                f"timeout: got {len(messages)} of {n} message(s) on {name} within {timeout_s} s"
            )
    finally:
        if not keep:
            topic.unsubscribe()
    with lock:
        return list(messages), list(times)


def first_message(roslibpy: Any, ros: Any, name: str, message_type: str, timeout_s: float) -> JSON:
    messages, _ = collect(roslibpy, ros, name, message_type, 1, timeout_s)
    return messages[0]


def call_service(
    roslibpy: Any,
    ros: Any,
    name: str,
    service_type: str,
    request: dict[str, Any] | None = None,
    timeout_s: float = 5.0,
) -> JSON:
    """Call a service through ``Service.call(request, callback, errback)``.

    Returns the response values (a plain dict), raises ServiceFailure when the
    errback fires, TimeoutError when neither fires in time. (roslibpy's
    errback only fires if the failed response carries ``values``; without it
    roslibpy raises KeyError on the reactor thread and neither callback runs.)
    """
    service = roslibpy.Service(ros, name, service_type)
    done = threading.Event()
    outcome: dict[str, Any] = {}

    def callback(response: Any) -> None:
        outcome["response"] = dict(response)
        done.set()

    def errback(values: Any) -> None:
        outcome["failure"] = values
        done.set()

    service.call(roslibpy.ServiceRequest(request or {}), callback, errback)
    if not done.wait(timeout_s):
        raise TimeoutError(f"timeout: call of service {name} did not finish within {timeout_s} s")
    if "failure" in outcome:
        raise ServiceFailure(name, outcome["failure"])
    return outcome["response"]


def yaw_from_quaternion(q: dict[str, float]) -> float:
    x, y, z, w = q.get("x", 0.0), q.get("y", 0.0), q.get("z", 0.0), q.get("w", 1.0)
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def pose_of(odom: JSON) -> dict[str, float]:
    p = odom["pose"]["pose"]
    return {
        "x": p["position"]["x"],
        "y": p["position"]["y"],
        "yaw": yaw_from_quaternion(p["orientation"]),
        "qz": p["orientation"]["z"],
        "qw": p["orientation"]["w"],
    }


def same_pose(a: JSON, b: JSON) -> bool:
    pa, pb = a["pose"]["pose"], b["pose"]["pose"]
    return bool(pa["position"] == pb["position"] and pa["orientation"] == pb["orientation"])


# --------------------------------------------------------------------------- scenarios


def topics(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """``{topics, types}``; optional ``topic_types`` via ``Ros.get_topic_type``.

    roslibpy's ``Ros.get_topics()`` returns only the ``topics`` list, so the
    ``types`` come from calling ``/rosapi/topics`` directly (the same request
    get_topics sends).
    """
    timeout_s = args.get("timeout_ms", 5000) / 1000
    names = ros.get_topics()
    full = call_service(roslibpy, ros, "/rosapi/topics", "rosapi/Topics", {}, timeout_s)
    out: dict[str, Any] = {"topics": names, "types": full.get("types")}
    if args.get("with_topic_type"):
        out["topic_types"] = {name: ros.get_topic_type(name) for name in names}
    return out


def odom_rate(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    count = args.get("count", 41)
    timeout_s = args.get("timeout_ms", 5000 + count * 150) / 1000
    messages, times = collect(roslibpy, ros, "/odom", "nav_msgs/msg/Odometry", count, timeout_s)
    return {
        "count": len(messages),
        "times": times,
        "stamps": [_stamp_ms(m) for m in messages],
        "first": messages[0],
        "last": messages[-1],
    }


def _stamp_ms(msg: JSON) -> float:
    stamp = msg["header"]["stamp"]
    return float(stamp["sec"] * 1e3 + stamp["nanosec"] / 1e6)


def scan(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    timeout_s = args.get("timeout_ms", 5000) / 1000
    return first_message(roslibpy, ros, "/scan", "sensor_msgs/msg/LaserScan", timeout_s)


def tf(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """First message on /tf and on /tf_static, both subscribed at once."""
    timeout_s = args.get("timeout_ms", 5000) / 1000
    results: dict[str, Any] = {}
    errors: list[BaseException] = []

    def grab(key: str, name: str) -> None:
        try:
            results[key] = first_message(roslibpy, ros, name, "tf2_msgs/msg/TFMessage", timeout_s)
        except BaseException as exc:
            errors.append(exc)

    threads = [
        threading.Thread(target=grab, args=("tf", "/tf")),
        threading.Thread(target=grab, args=("tf_static", "/tf_static")),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout_s + 1)
    if errors:
        raise errors[0]
    return {"tf": results["tf"], "tf_static": results["tf_static"]}


def drive(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Same protocol and result shape as tests/js/scenarios/drive.mjs."""
    v = args.get("v", 0.5)
    w = args.get("w", 0.0)
    seconds = args.get("seconds", 1.0)
    full = bool(args.get("full_twist"))
    first_timeout_s = args.get("timeout_ms", 5000) / 1000
    stop_timeout_s = args.get("stop_timeout_ms", 3000) / 1000

    def twist(lin: float, ang: float) -> dict[str, Any]:
        if full:
            return {
                "linear": {"x": lin, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": ang},
            }
        return {"linear": {"x": lin}, "angular": {"z": ang}}

    odom_topic = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
    cmd_topic = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
    st: dict[str, Any] = {"phase": "wait", "first": None, "last": None, "stopped": None}
    motion = {"count": 0, "lin": [], "ang": []}
    lock = threading.Lock()

    def on_odom(msg: JSON) -> None:
        with lock:
            if st["first"] is None:
                st["first"] = msg
            if st["phase"] == "moving":
                t = msg["twist"]["twist"]
                motion["count"] += 1
                motion["lin"].append(t["linear"]["x"])
                motion["ang"].append(t["angular"]["z"])
            elif (
                st["phase"] == "stopping"
                and st["stopped"] is None
                and st["last"] is not None
                and same_pose(st["last"], msg)
            ):
                st["stopped"] = msg
            st["last"] = msg

    odom_topic.subscribe(on_odom)
    wait_for(lambda: st["first"], first_timeout_s, "first /odom message")
    cmd_topic.advertise()
    with lock:
        st["phase"] = "moving"

    # 10 Hz, first tick immediately, scheduled against a monotonic clock.
    cmd = roslibpy.Message(twist(v, w))
    t0 = time.monotonic()
    ticks = 0
    while time.monotonic() - t0 < seconds:
        cmd_topic.publish(cmd)
        ticks += 1
        next_tick = t0 + ticks * 0.1
        time.sleep(max(0.0, min(next_tick, t0 + seconds) - time.monotonic()))

    cmd_topic.publish(roslibpy.Message(twist(0.0, 0.0)))
    with lock:
        st["phase"] = "stopping"
    stop_start = now_ms()
    wait_for(
        lambda: st["stopped"], stop_timeout_s, "two consecutive /odom messages with identical pose"
    )
    stop_ms = now_ms() - stop_start

    odom_topic.unsubscribe()
    cmd_topic.unadvertise()
    lin, ang = motion["lin"], motion["ang"]
    return {
        "start": pose_of(st["first"]),
        "final": pose_of(st["stopped"]),
        "ticks": ticks,
        "twist_during_motion": {
            "max_linear_x": max(lin) if lin else None,
            "min_linear_x": min(lin) if lin else None,
            "max_angular_z": max(ang) if ang else None,
            "min_angular_z": min(ang) if ang else None,
        },
        "odom_during_motion": motion["count"],
        "stop_ms": stop_ms,
    }


def chatter(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Publish once on /chatter with one Topic, receive with another, check no duplicates.

    The wait of ``dup_window_ms`` after the first echo is an absence check.
    """
    text = args.get("text", "hello from roslibpy")
    timeout_s = args.get("timeout_ms", 5000) / 1000
    dup_window_s = args.get("dup_window_ms", 500) / 1000
    msg_type = "std_msgs/msg/String"

    pub = roslibpy.Topic(ros, "/chatter", msg_type)
    sub = roslibpy.Topic(ros, "/chatter", msg_type)
    messages: list[JSON] = []
    times: list[float] = []

    def on_message(msg: JSON) -> None:
        times.append(now_ms())
        messages.append(msg)

    sub.subscribe(on_message)
    pub.advertise()
    sent_at = now_ms()
    pub.publish(roslibpy.Message({"data": text}))
    wait_for(lambda: messages, timeout_s, f"echo of {text!r} on /chatter")
    time.sleep(dup_window_s)

    sub.unsubscribe()
    pub.unadvertise()
    return {
        "sent": text,
        "messages": list(messages),
        "times": list(times),
        "latency_ms": times[0] - sent_at,
    }


def reset(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    timeout_s = args.get("timeout_ms", 5000) / 1000
    name = args.get("name", "/reset")
    return {"response": call_service(roslibpy, ros, name, "std_srvs/srv/Empty", {}, timeout_s)}


def unknown_service(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Same result shape as tests/js/scenarios/unknown_service.mjs."""
    timeout_s = args.get("timeout_ms", 5000) / 1000
    name = args.get("name", "/no_such_service")
    service_type = args.get("type", "std_srvs/srv/Empty")
    out: dict[str, Any] = {
        "fail_called": False,
        "fail_value": None,
        "success_called": False,
        "response": None,
        "timed_out": False,
    }
    try:
        out["response"] = call_service(roslibpy, ros, name, service_type, {}, timeout_s)
        out["success_called"] = True
    except ServiceFailure as exc:
        out["fail_called"] = True
        out["fail_value"] = exc.values
    except TimeoutError:
        out["timed_out"] = True
    return out


def param(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """roslibpy.Param get, set, get (same result shape as tests/js/scenarios/param.mjs)."""
    timeout_s = args.get("timeout_ms", 5000) / 1000
    p = roslibpy.Param(ros, args["name"])
    before = p.get(timeout=timeout_s)
    p.set(args["value"], timeout=timeout_s)
    after = p.get(timeout=timeout_s)
    return {"before": before, "setResult": None, "after": after}


def bad_publish(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Publish ill-typed /cmd_vel messages, then prove the connection and the robot are fine.

    roslibpy logs the server's status replies ("No handler registered for operation status")
    and carries on; the result reports the round trip and the robot's x.
    """
    timeout_s = args.get("timeout_ms", 5000) / 1000
    cmd = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
    cmd.publish(roslibpy.Message({"linear": {"x": "fast"}}))
    cmd.publish(roslibpy.Message({"linear": {"x": float("nan")}}))
    echoed: list[Any] = []
    chatter = roslibpy.Topic(ros, "/chatter_after_bad", "std_msgs/msg/String")
    chatter.subscribe(echoed.append)
    chatter.publish(roslibpy.Message({"data": "still alive"}))
    wait_for(lambda: echoed, timeout_s, "round trip after bad input")
    odoms: list[Any] = []
    odom = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
    odom.subscribe(odoms.append)
    wait_for(lambda: odoms, timeout_s, "an /odom")
    chatter.unsubscribe()
    odom.unsubscribe()
    return {"echoed": echoed[0], "x": odoms[-1]["pose"]["pose"]["position"]["x"]}


def throttle(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """/odom with throttle_rate (ms): same result shape as tests/js/scenarios/throttle.mjs."""
    count = args.get("count", 6)
    rate = args.get("throttle_rate", 200)
    topic = roslibpy.Topic(
        ros, "/odom", "nav_msgs/msg/Odometry", throttle_rate=rate, queue_length=1
    )
    times: list[float] = []
    stamps: list[float] = []

    def on_message(msg: JSON) -> None:
        times.append(now_ms())
        stamps.append(_stamp_ms(msg))

    topic.subscribe(on_message)
    wait_for(lambda: len(times) >= count, args.get("timeout_ms", 5000 + count * rate * 2) / 1000)
    topic.unsubscribe()
    return {"times": times[:count], "stamps": stamps[:count]}


def rosapi_all(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Every rosapi helper of roslibpy, Param, other rosapi and rcl_interfaces services.

    Same result keys as tests/js/scenarios/rosapi_all.mjs where the library has the feature.
    """
    timeout_s = args.get("timeout_ms", 5000) / 1000

    def call(name: str, type_name: str, request: Any) -> JSON:
        return call_service(roslibpy, ros, name, type_name, request, timeout_s)

    out: dict[str, Any] = {}
    out["topics"] = {"topics": ros.get_topics()}
    out["topicsForType"] = ros.get_topics_for_type("tf2_msgs/msg/TFMessage")
    out["services"] = ros.get_services()
    out["servicesForType"] = ros.get_services_for_type("std_srvs/srv/Empty")
    out["requestDetails"] = dict(
        ros.get_service_request_details("example_interfaces/srv/AddTwoInts")
    )
    out["responseDetails"] = dict(ros.get_service_response_details("rosapi_msgs/srv/GetParam"))
    out["nodes"] = ros.get_nodes()
    out["nodeDetails"] = dict(ros.get_node_details("/virtual_robot"))
    out["params"] = ros.get_params()
    out["topicType"] = ros.get_topic_type("/scan")
    out["serviceType"] = ros.get_service_type("/reset")
    out["messageDetails"] = dict(ros.get_message_details("nav_msgs/msg/Odometry"))["typedefs"]
    servers: list[Any] = []
    ros.get_action_servers(servers.append)
    out["actionServers"] = wait_for(lambda: servers, timeout_s, "get_action_servers")[0][
        "action_servers"
    ]
    t = ros.get_time()
    out["time"] = {"time": {"secs": t.secs, "nsecs": t.nsecs}}
    out["subscribers"] = call("/rosapi/subscribers", "rosapi/Subscribers", {"topic": "/cmd_vel"})
    out["providers"] = call(
        "/rosapi/service_providers", "rosapi/ServiceProviders", {"service": "std_srvs/srv/Empty"}
    )
    out["serviceNode"] = call("/rosapi/service_node", "rosapi/ServiceNode", {"service": "/reset"})
    out["hasParam"] = call(
        "/rosapi/has_param", "rosapi/HasParam", {"name": "/virtual_robot:lidar.rays"}
    )
    out["version"] = call("/rosapi/get_ros_version", "rosapi/GetROSVersion", {})
    out["interfaces"] = len(call("/rosapi/interfaces", "rosapi/Interfaces", {})["interfaces"])
    out["rawTypes"] = call("/rosapi/topics_and_raw_types", "rosapi/TopicsAndRawTypes", {})
    out["publishers"] = call("/rosapi/publishers", "rosapi/Publishers", {"topic": "/odom"})[
        "publishers"
    ]
    speed = roslibpy.Param(ros, "/virtual_robot:robot.max_angular_velocity")
    speed.set(1.25, timeout=timeout_s)
    out["paramSet"] = {"ok": True, "value": None}
    out["paramGet"] = {"ok": True, "value": speed.get(timeout=timeout_s)}
    out["paramDelete"] = {"ok": True, "value": ros.delete_param(speed.name)}
    out["paramUnknown"] = {"ok": True, "value": ros.get_param("/virtual_robot:nope")}
    out["getParameters"] = call(
        "/virtual_robot/get_parameters",
        "rcl_interfaces/srv/GetParameters",
        {"names": ["robot.mass", "lidar.rays"]},
    )
    out["setParameters"] = call(
        "/virtual_robot/set_parameters",
        "rcl_interfaces/srv/SetParameters",
        {
            "parameters": [
                {"name": "lidar.range_max", "value": {"type": 3, "double_value": 3.0}},
                {"name": "lidar.range_min", "value": {"type": 3, "double_value": -1.0}},
            ]
        },
    )
    out["listParameters"] = call(
        "/virtual_robot/list_parameters",
        "rcl_interfaces/srv/ListParameters",
        {"prefixes": ["robot"], "depth": 0},
    )
    out["describeParameters"] = call(
        "/virtual_robot/describe_parameters",
        "rcl_interfaces/srv/DescribeParameters",
        {"names": ["lidar.range_max"]},
    )
    return out


def services_actions(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Roslibpy serves and calls services on one connection; ActionClient against /fibonacci.

    Same result keys as tests/js/scenarios/services_actions.mjs. The /fibonacci action server
    is run by the test (roslibpy has no action server side).
    """
    timeout_s = args.get("timeout_ms", 5000) / 1000

    def add(request: Any, response: Any) -> bool:
        response["sum"] = request["a"] + request["b"]
        return True

    def quiet(request: Any, response: Any) -> None:
        response["success"] = True
        response["message"] = "no result key"

    served = [
        roslibpy.Service(ros, "/add_two_ints", "example_interfaces/srv/AddTwoInts"),
        roslibpy.Service(ros, "/quiet", "std_srvs/srv/Trigger"),
        roslibpy.Service(ros, "/refuse", "std_srvs/srv/Trigger"),
    ]
    served[0].advertise(add)
    served[1].advertise(quiet)
    served[2].advertise(lambda request, response: False)
    ros.send_on_ready(
        roslibpy.Message(
            {"op": "advertise_service", "service": "/slow", "type": "std_srvs/Trigger"}
        )
    )
    wait_for(lambda: "/slow" in ros.get_services(), timeout_s, "services advertised")

    def outcome(name: str, type_name: str, request: Any) -> JSON:
        try:
            return {
                "ok": True,
                "value": call_service(roslibpy, ros, name, type_name, request, timeout_s),
            }
        except ServiceFailure as exc:
            return {"ok": False, "error": exc.values}

    out: dict[str, Any] = {"services": {}}
    s = out["services"]
    s["object"] = outcome("/add_two_ints", "example_interfaces/srv/AddTwoInts", {"a": 2, "b": 3})
    s["quiet"] = outcome("/quiet", "std_srvs/srv/Trigger", {})
    s["refuse"] = outcome("/refuse", "std_srvs/srv/Trigger", {})
    started = now_ms()
    s["slow"] = outcome("/slow", "std_srvs/srv/Trigger", {})
    s["slowMs"] = now_ms() - started
    for service in served:
        service.unadvertise()

    a: dict[str, Any] = {}
    out["actions"] = a
    wait_for(
        lambda: (
            "/fibonacci"
            in call_service(
                roslibpy, ros, "/rosapi/action_servers", "rosapi/GetActionServers", {}, timeout_s
            )["action_servers"]
        ),
        timeout_s,
        "/fibonacci advertised",
    )
    client = roslibpy.ActionClient(ros, "/fibonacci", "example_interfaces/action/Fibonacci")

    def send(goal: dict[str, Any]) -> tuple[str, dict[str, Any], threading.Event]:
        state: dict[str, Any] = {"feedback": []}
        done = threading.Event()

        def resultback(result: Any) -> None:
            state.update(ok=True, status=int(result["status"].value), values=result["values"])
            done.set()

        def errback(err: Any) -> None:
            state.update(ok=False, status=int(err["status"].value), values=err["values"])
            done.set()

        goal_id = client.send_goal(
            goal, resultback, lambda fb: state["feedback"].append(dict(fb)), errback
        )
        return goal_id, state, done

    def finished(item: tuple[str, dict[str, Any], threading.Event]) -> dict[str, Any]:
        if not item[2].wait(timeout_s):
            raise TimeoutError(f"goal {item[0]} did not finish")
        return item[1]

    a["succeeded"] = finished(send({"order": 6}))
    a["failed"] = finished(send({"order": -1}))
    long = send({"order": 100})
    wait_for(lambda: long[1]["feedback"], timeout_s, "feedback of the long goal")
    client.cancel_goal(long[0])
    a["canceled"] = finished(long)
    missing = roslibpy.ActionClient(ros, "/no_such_action", "example_interfaces/action/Fibonacci")
    state: dict[str, Any] = {}
    got = threading.Event()
    missing.send_goal(
        {"order": 1},
        lambda r: (state.update(ok=True), got.set()),
        None,
        lambda e: (state.update(ok=False, values=e["values"]), got.set()),
    )
    if not got.wait(timeout_s):
        raise TimeoutError("goal to a missing action got no result")
    a["missing"] = state
    # latching: advertise with latch, publish once, then subscribe
    pub = roslibpy.Topic(ros, "/latched_note", "std_msgs/msg/String", latch=True)
    pub.publish(roslibpy.Message({"data": "kept for late subscribers"}))
    wait_for(lambda: "/latched_note" in ros.get_topics(), timeout_s, "the latched topic to exist")
    out["latched"] = first_message(roslibpy, ros, "/latched_note", "std_msgs/msg/String", timeout_s)
    return out


def tf_clients(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """roslibpy.tf.TFClient (service mode); same result keys as scenarios/tf_clients.mjs."""
    from roslibpy.tf import TFClient

    timeout_s = args.get("timeout_ms", 5000) / 1000
    tf = TFClient(
        ros, fixed_frame="odom", angular_threshold=0.01, translation_threshold=0.001, rate=20
    )
    latest: dict[str, Any] = {}
    counts = {"base_link": 0, "laser": 0}

    def keep(name: str) -> Callable[[Any], None]:
        def callback(transform: Any) -> None:
            latest[name] = {
                "translation": dict(transform["translation"]),
                "rotation": dict(transform["rotation"]),
            }
            counts[name] += 1

        return callback

    tf.subscribe("base_link", keep("base_link"))
    tf.subscribe("/laser", keep("laser"))
    wait_for(lambda: "base_link" in latest and "laser" in latest, timeout_s, "first transforms")
    first = dict(latest)
    cmd = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
    deadline = time.monotonic() + timeout_s
    while latest["base_link"]["rotation"]["z"] <= 0.1:
        if time.monotonic() > deadline:
            raise TimeoutError("base_link did not turn")
        cmd.publish(roslibpy.Message({"angular": {"z": 1.0}}))
        time.sleep(0.05)
    cmd.publish(roslibpy.Message({}))
    turned = dict(latest)
    tf.dispose()
    return {"first": first, "turned": turned, "counts": counts}


def tutorials(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """The tutorial nodes as roslibpy's docs use them (same keys as scenarios/tutorials.mjs).

    The talker on /chatter, /add_two_ints, and /fibonacci through the ROS 1 actionlib client of
    roslibpy's docs (ros-action-client.py: actionlib_tutorials/FibonacciAction) and the ROS 2
    ActionClient, typed example_interfaces and action_tutorials_interfaces (the three goals at
    once); TF of the world file's turtle1 frame via roslibpy's TFClient; a tutorial node's
    use_sim_time with roslibpy.Param and get_params; whether /listener is a node, a topic.
    """
    from roslibpy.ros1 import actionlib
    from roslibpy.tf import TFClient

    timeout_s = args.get("timeout_ms", 5000) / 1000
    order = int(args.get("order", 3))
    talker, _times = collect(roslibpy, ros, "/chatter", "std_msgs/String", 1, timeout_s + 1.5)
    add = roslibpy.Service(ros, "/add_two_ints", "example_interfaces/srv/AddTwoInts")
    total = add.call(roslibpy.ServiceRequest({"a": 1, "b": 2}), timeout=timeout_s)

    client = actionlib.ActionClient(ros, "/fibonacci", "actionlib_tutorials/FibonacciAction")
    goal = actionlib.Goal(client, roslibpy.Message({"order": order}))
    feedback: list[Any] = []
    goal.on("feedback", lambda f: feedback.append(f["sequence"]))
    goal.send()

    ros2: dict[str, dict[str, Any]] = {}
    done = threading.Event()
    for action_type in (
        "example_interfaces/action/Fibonacci",
        "action_tutorials_interfaces/action/Fibonacci",
    ):
        got: dict[str, Any] = {"feedback": []}
        ros2[action_type.split("/")[0]] = got

        def on_result(r: Any, got: dict[str, Any] = got) -> None:
            got.update(status=int(r["status"].value), values=r["values"])
            if all("status" in g for g in ros2.values()):
                done.set()

        action = roslibpy.ActionClient(ros, "/fibonacci", action_type)
        action.send_goal(
            roslibpy.Goal({"order": order}),
            on_result,
            lambda f, got=got: got["feedback"].append(dict(f)),
            on_result,
        )

    name = "/add_two_ints_server:use_sim_time"
    param = roslibpy.Param(ros, name)
    sim_time = [param.get(timeout=timeout_s)]
    for value in (True, False):
        param.set(value, timeout=timeout_s)
        sim_time.append(param.get(timeout=timeout_s))
    params = ros.get_params()

    tf = TFClient(ros, fixed_frame="world")
    turtle: list[Any] = []
    tf.subscribe("turtle1", lambda t: turtle.append(dict(t["translation"])))
    wait_for(lambda: turtle, timeout_s, "turtle1 from roslibpy's TFClient")
    tf.dispose()
    listener = {"node": "/listener" in ros.get_nodes(), "topic": "/listener" in ros.get_topics()}

    result = goal.wait(timeout_s + order)
    status = goal.status["status"]
    client.dispose()
    if not done.wait(timeout_s + order):
        raise TimeoutError("ROS 2 fibonacci results")
    return {
        "chatter": {"talker": [m["data"] for m in talker]},
        "sum": dict(total),
        "actionlib": {"result": result["sequence"], "feedback": feedback, "status": status},
        "ros2": ros2,
        "tf": turtle[0],
        "simTime": {"values": sim_time, "listed": name in params},
        "listener": listener,
    }


def action_goals(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """roslibpy.ActionClient: one goal to its result, one long goal cancelled after feedback."""
    timeout_s = args.get("timeout_ms", 5000) / 1000
    name, type_name = args["action"], args["type"]
    wait_for(
        lambda: (
            name
            in call_service(
                roslibpy, ros, "/rosapi/action_servers", "rosapi/GetActionServers", {}, timeout_s
            )["action_servers"]
        ),
        timeout_s,
        f"{name} among the action servers",
    )
    client = roslibpy.ActionClient(ros, name, type_name)

    def send(goal: dict[str, Any]) -> tuple[str, dict[str, Any], threading.Event]:
        state: dict[str, Any] = {"feedback": []}
        done = threading.Event()

        def resultback(result: Any) -> None:
            state.update(ok=True, status=int(result["status"].value), values=result["values"])
            done.set()

        def errback(err: Any) -> None:
            state.update(ok=False, status=int(err["status"].value), values=err["values"])
            done.set()

        goal_id = client.send_goal(
            goal, resultback, lambda fb: state["feedback"].append(dict(fb)), errback
        )
        return goal_id, state, done

    def finished(item: tuple[str, dict[str, Any], threading.Event]) -> dict[str, Any]:
        if not item[2].wait(timeout_s):
            raise TimeoutError(f"goal {item[0]} did not finish")
        return item[1]

    out: JSON = {"succeeded": finished(send(args["goal"]))}
    long = send(args["long_goal"])
    wait_for(lambda: long[1]["feedback"], timeout_s, "feedback of the long goal")
    client.cancel_goal(long[0])
    out["canceled"] = finished(long)
    return out


def echo(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """The first ``count`` messages of ``topic`` (type ``type``), and rosapi's topics."""
    timeout_s = args.get("timeout_ms", 5000) / 1000
    messages, _ = collect(
        roslibpy, ros, args["topic"], args["type"], args.get("count", 1), timeout_s
    )
    full = call_service(roslibpy, ros, "/rosapi/topics", "rosapi/Topics", {}, timeout_s)
    return {"messages": messages, "topics": dict(zip(full["topics"], full["types"], strict=True))}


SCENARIOS: dict[str, Callable[[Any, Any, dict[str, Any]], JSON]] = {
    "echo": echo,
    "action_goals": action_goals,
    "tutorials": tutorials,
    "tf_clients": tf_clients,
    "services_actions": services_actions,
    "rosapi_all": rosapi_all,
    "topics": topics,
    "odom_rate": odom_rate,
    "drive": drive,
    "scan": scan,
    "tf": tf,
    "chatter": chatter,
    "reset": reset,
    "unknown_service": unknown_service,
    "param": param,
    "bad_publish": bad_publish,
    "throttle": throttle,
}

# Scenarios of other areas, kept in their own modules (imported last: they use the helpers).
from roslibpy_fleet import FLEET_SCENARIOS  # noqa: E402


SCENARIOS.update(FLEET_SCENARIOS)
