"""roslibpy scenarios for many robots: namespaced topics, spawn, teleport, kill, contacts."""

from __future__ import annotations

import threading
from typing import Any

from roslibpy_scenarios import JSON, ServiceFailure, call_service, collect, first_message, pose_of


def fleet(roslibpy: Any, ros: Any, args: dict[str, Any]) -> JSON:
    """Drive a world of named robots through its run-time services with roslibpy.

    World: r1 at (-1, 0) facing +x, r2 at (1, 0). Reports what a student's script would see.
    """
    out: dict[str, Any] = {}
    listed = call_service(roslibpy, ros, "/rosapi/topics", "rosapi_msgs/srv/Topics")
    out["topics"] = listed["topics"]
    odom = first_message(roslibpy, ros, "/r1/odom", "nav_msgs/msg/Odometry", 5)
    out["r1_frames"] = [odom["header"]["frame_id"], odom["child_frame_id"]]
    static = first_message(roslibpy, ros, "/tf_static", "tf2_msgs/msg/TFMessage", 5)
    out["tf_static"] = [
        [t["header"]["frame_id"], t["child_frame_id"]] for t in static["transforms"]
    ]
    scan = first_message(roslibpy, ros, "/r1/scan", "sensor_msgs/msg/LaserScan", 5)
    out["r1_scan_front"] = scan["ranges"][0]
    out["r1_scan_frame"] = scan["header"]["frame_id"]

    spawn_req = {"x": 2.0, "y": 2.0, "theta": 0.0, "name": "r3"}
    out["spawn"] = call_service(roslibpy, ros, "/spawn", "turtlesim/srv/Spawn", spawn_req)
    out["r3_start"] = pose_of(first_message(roslibpy, ros, "/r3/odom", "nav_msgs/msg/Odometry", 5))
    try:
        call_service(roslibpy, ros, "/spawn", "turtlesim/srv/Spawn", {"x": 1.05, "name": "r4"})
        out["spawn_on_r2"] = "accepted"
    except ServiceFailure as err:
        out["spawn_on_r2"] = err.values
    call_service(
        roslibpy,
        ros,
        "/r3/teleport_absolute",
        "turtlesim/srv/TeleportAbsolute",
        {"x": -2.0, "y": -2.0, "theta": 1.0},
    )
    out["r3_teleported"] = pose_of(
        first_message(roslibpy, ros, "/r3/odom", "nav_msgs/msg/Odometry", 5)
    )

    # Drive r1 into r2 until /r1/contact reports it.
    logs: list[str] = []
    contacts: list[JSON] = []
    got = threading.Event()
    rosout = roslibpy.Topic(ros, "/rosout", "rcl_interfaces/msg/Log")
    rosout.subscribe(lambda m: logs.append(m["msg"]))
    contact = roslibpy.Topic(ros, "/r1/contact", "simbridge_msgs/msg/Contact")
    contact.subscribe(lambda m: (contacts.append(m), got.set()))
    cmd = roslibpy.Topic(ros, "/r1/cmd_vel", "geometry_msgs/msg/Twist")
    cmd.publish(roslibpy.Message({"linear": {"x": 0.5}, "angular": {"z": 0.0}}))
    if not got.wait(args.get("contact_timeout_s", 10)):
        raise TimeoutError("no message on /r1/contact")
    cmd.publish(roslibpy.Message({"linear": {"x": 0.0}, "angular": {"z": 0.0}}))
    out["contact"] = contacts[0]
    messages, _ = collect(roslibpy, ros, "/r1/odom", "nav_msgs/msg/Odometry", 3, 5)
    out["r1_after_contact"] = pose_of(messages[-1])
    scan = first_message(roslibpy, ros, "/r1/scan", "sensor_msgs/msg/LaserScan", 5)
    out["r1_scan_front_at_contact"] = scan["ranges"][0]
    out["hit_logs"] = [m for m in logs if "hit" in m]

    out["kill"] = call_service(roslibpy, ros, "/kill", "turtlesim/srv/Kill", {"name": "r3"})
    listed = call_service(roslibpy, ros, "/rosapi/topics", "rosapi_msgs/srv/Topics")
    out["topics_after_kill"] = listed["topics"]
    call_service(roslibpy, ros, "/reset", "std_srvs/srv/Empty")
    out["r1_after_reset"] = pose_of(
        first_message(roslibpy, ros, "/r1/odom", "nav_msgs/msg/Odometry", 5)
    )
    return out


FLEET_SCENARIOS = {"fleet": fleet}
