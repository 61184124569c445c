from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.app.config import Params, load_world
from simbridge.graph import Graph
from simbridge.graph.rosapi import install_rosapi
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.tutorials import install_tutorials
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    g = Graph()
    install_rosapi(g)
    RobotBridge(g, World(load_world(None), Params()))
    return g


def call(graph: Graph, service: str, args: Any = None) -> dict[str, Any]:
    peer = RecordingPeer(graph)
    body: dict[str, Any] = {"op": "call_service", "service": service, "id": 1}
    if args is not None:
        body["args"] = args
    rosbridge_of(graph).receive(peer, json.dumps(body), 0.0)
    (reply,) = peer.take()
    return reply


def test_topics_lists_names_and_types_in_parallel_arrays(graph: Graph) -> None:
    """rosapi/topics: /rosout always listed; relative name accepted."""
    reply = call(graph, "rosapi/topics", {})
    listed = dict(zip(reply["values"]["topics"], reply["values"]["types"], strict=True))
    assert listed["/rosout"] == "rcl_interfaces/msg/Log"
    assert listed["/odom"] == "nav_msgs/msg/Odometry"
    assert reply["service"] == "rosapi/topics"


@pytest.mark.parametrize("args", [{"topic": "/scan"}, ["/scan"], {"topic": "scan"}])
def test_topic_type_accepts_object_or_list_args(graph: Graph, args: Any) -> None:
    """Object args, list args zipped onto the fields, relative topic names."""
    assert call(graph, "/rosapi/topic_type", args)["values"] == {
        "type": "sensor_msgs/msg/LaserScan"
    }


def test_topic_type_of_unknown_topic_is_empty(graph: Graph) -> None:
    """Unknown topic: type ''."""
    assert call(graph, "/rosapi/topic_type", {"topic": "/nope"})["values"] == {"type": ""}


def test_unknown_request_field_fails_with_the_expected_fields(graph: Graph) -> None:
    """A misspelled request field is refused with a reason."""
    reply = call(graph, "/rosapi/topic_type", {"topik": "/scan"})
    assert reply["result"] is False and "expected topic" in reply["values"]


def test_get_param_returns_json_text_and_unknown_names_the_default(graph: Graph) -> None:
    """get_param value is JSON text; unknown parameters give '""' and successful false."""
    ok = call(graph, "/rosapi/get_param", {"name": "/virtual_robot:robot.mass"})["values"]
    assert (json.loads(ok["value"]), ok["successful"]) == (1.5, True)
    bad = call(graph, "/rosapi/get_param", {"name": "/virtual_robot:nope"})["values"]
    assert bad["value"] == '""' and bad["successful"] is False
    malformed = call(graph, "/rosapi/get_param", {"name": "mass"})["values"]
    assert "must be '<node>:<parameter>'" in malformed["reason"]


def test_set_param_changes_the_robot_or_says_why_not(graph: Graph) -> None:
    """set_param with JSON text; an invalid value is refused and nothing changes."""
    ok = call(graph, "/rosapi/set_param", {"name": "/virtual_robot:robot.mass", "value": "2.5"})
    assert ok["values"] == {"successful": True, "reason": ""}
    bad = call(graph, "/rosapi/set_param", {"name": "/virtual_robot:robot.mass", "value": "-1"})
    assert bad["values"]["successful"] is False and "greater than 0" in bad["values"]["reason"]
    now = call(graph, "/rosapi/get_param", {"name": "/virtual_robot:robot.mass"})
    assert json.loads(now["values"]["value"]) == 2.5


def test_param_names_has_param_and_delete_param(graph: Graph) -> None:
    """get_param_names lists node:param names; has_param; delete is refused politely."""
    names = call(graph, "/rosapi/get_param_names")["values"]["names"]
    assert "/virtual_robot:robot.max_linear_velocity" in names
    assert call(graph, "/rosapi/has_param", {"name": "/virtual_robot:lidar.rays"})["values"] == {
        "exists": True
    }
    assert call(graph, "/rosapi/has_param", {"name": "/x:y"})["values"] == {"exists": False}
    deleted = call(graph, "/rosapi/delete_param", {"name": "/virtual_robot:lidar.rays"})
    assert deleted["values"]["successful"] is False


def test_services_lists_reset_and_rosapi(graph: Graph) -> None:
    """rosapi/services includes the simulator's /reset."""
    services = call(graph, "/rosapi/services")["values"]["services"]
    assert "/reset" in services and "/rosapi/topics" in services


def test_topics_and_raw_types_give_full_text_with_msg_sections(graph: Graph) -> None:
    """typedefs_full_text: the .msg text then each dependency as an 80 '=' MSG: section."""
    values = call(graph, "/rosapi/topics_and_raw_types", {})["values"]
    text = dict(zip(values["topics"], values["typedefs_full_text"], strict=True))
    assert text["/cmd_vel"].startswith(
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular"
    )
    assert "=" * 80 + "\nMSG: geometry_msgs/Vector3\nfloat64 x" in text["/cmd_vel"]
    assert "MSG: builtin_interfaces/Time" in text["/rosout"]


def test_every_known_topic_type_has_its_text_and_an_unknown_one_an_empty_definition(
    graph: Graph,
) -> None:
    """Lichtblick needs a definition text per listed topic.

    Known types (the tutorial and actionlib ones included) get the full definition; a client's
    unknown type is listed with rosapi's comment-only text, which parses to an empty definition.
    """
    install_tutorials(graph)
    client = RecordingPeer(graph)
    rosbridge_of(graph).receive(
        client, json.dumps({"op": "advertise", "topic": "/x", "type": "my_pkg/X"}), 0.0
    )
    values = call(graph, "/rosapi/topics_and_raw_types", {})["values"]
    rows = list(zip(values["topics"], values["types"], values["typedefs_full_text"], strict=True))
    assert {"/chatter", "/fibonacci/goal", "/x"} <= {name for name, _t, _x in rows}
    for name, type_name, text in rows:
        body = [ln for ln in text.split("\n") if ln.strip() and not ln.startswith("#")]
        if name == "/x":
            assert type_name == "my_pkg/msg/X"
            assert body == [] and text.startswith("# failed to get full definition text")
        else:
            assert graph.registry.known(type_name) and body, name


def test_graph_introspection_services(graph: Graph) -> None:
    """publishers, subscribers, service_type/node/providers, node_details, action_type."""
    assert call(graph, "/rosapi/publishers", {"topic": "/odom"})["values"] == {
        "publishers": ["/virtual_robot"]
    }
    assert call(graph, "rosapi/subscribers", ["/cmd_vel"])["values"] == {
        "subscribers": ["/virtual_robot"]
    }
    assert call(graph, "/rosapi/service_type", {"service": "reset"})["values"] == {
        "type": "std_srvs/srv/Empty"
    }
    assert call(graph, "/rosapi/service_node", {"service": "/nope"})["values"] == {"node": ""}
    providers = call(graph, "/rosapi/service_providers", {"service": "rosapi_msgs/Topics"})
    assert providers["values"] == {"providers": ["/rosapi"]}
    bad = call(graph, "/rosapi/node_details", {"node": "/ghost"})
    assert bad["result"] is False and "does not exist" in bad["values"]
    assert call(graph, "/rosapi/action_type", {"action": "/nope"})["values"] == {"type": ""}


def test_details_services_and_versions(graph: Graph) -> None:
    """message/service/action details as TypeDefs; unknown type fails with a reason."""
    req = call(graph, "/rosapi/service_request_details", {"type": "std_srvs/SetBool"})
    assert req["values"]["typedefs"][0]["fieldnames"] == ["data"]
    fb = call(graph, "/rosapi/action_feedback_details", {"type": "example_interfaces/Fibonacci"})
    assert fb["values"]["typedefs"][0]["fieldtypes"] == ["int32"]
    unknown = call(graph, "/rosapi/message_details", {"type": "nope/Nope"})
    assert unknown["result"] is False and "unknown message type" in unknown["values"]
    assert call(graph, "/rosapi/get_ros_version")["values"] == {"version": 2, "distro": "jazzy"}
    stamp = call(graph, "/rosapi/get_time")["values"]["time"]
    assert stamp["sec"] == stamp["secs"] and stamp["nanosec"] == stamp["nsecs"]


def test_in_process_services_refuse_more_list_args_than_fields() -> None:
    """A direct call of an in-process handler follows the same rule as a client's call."""
    from simbridge.errors import ServiceError
    from simbridge.graph.rosapi import request_fields

    assert request_fields(["/odom"], ("topic",), "/rosapi/topic_type") == {"topic": "/odom"}
    with pytest.raises(ServiceError, match=r"/rosapi/topic_type: request has 1 fields \(topic\)"):
        request_fields(["/odom", "extra"], ("topic",), "/rosapi/topic_type")
