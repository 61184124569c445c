from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.app.config import Params, load_world
from simbridge.graph import Graph
from simbridge.graph.paramservices import install_parameter_services
from simbridge.graph.rosapi import install_rosapi
from simbridge.robot.bridge import RobotBridge
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    g = Graph()
    install_rosapi(g)
    install_parameter_services(g)
    RobotBridge(g, World(load_world(None), Params()))
    return g


def call(graph: Graph, service: str, args: Any) -> dict[str, Any]:
    peer = RecordingPeer(graph)
    body = {"op": "call_service", "service": service, "id": 1, "args": args}
    rosbridge_of(graph).receive(peer, json.dumps(body), 0.0)
    (reply,) = peer.take()
    assert reply["result"] is True, reply
    return dict(reply["values"])


def test_get_parameters_and_types(graph: Graph) -> None:
    """Values in the field of their type; an unknown name is NOT_SET (type 0)."""
    values = call(graph, "/virtual_robot/get_parameters", {"names": ["lidar.mount", "x"]})
    mount, unknown = values["values"]
    assert (mount["type"], mount["double_array_value"]) == (8, [0.0, 0.0, 0.0])
    assert unknown["type"] == 0
    types = call(graph, "/virtual_robot/get_parameter_types", {"names": ["lidar.rays", "x"]})
    assert types == {"types": "AgA="}  # uint8[] as base64: [2, 0]


def test_set_parameters_one_by_one_and_atomically(graph: Graph) -> None:
    """set_parameters: each on its own; set_parameters_atomically: all or nothing."""
    ok = {"name": "robot.mass", "value": {"type": 3, "double_value": 3.0}}
    bad = {"name": "lidar.rays", "value": {"type": 4, "string_value": "many"}}
    results = call(graph, "/virtual_robot/set_parameters", {"parameters": [ok, bad]})["results"]
    assert [r["successful"] for r in results] == [True, False]
    assert graph.params.get("/virtual_robot", "robot.mass") == 3.0
    ok["value"] = {"type": 3, "double_value": 4.0}
    atomic = call(graph, "/virtual_robot/set_parameters_atomically", {"parameters": [ok, bad]})
    assert atomic["result"]["successful"] is False
    assert graph.params.get("/virtual_robot", "robot.mass") == 3.0


def test_list_and_describe_parameters(graph: Graph) -> None:
    """list_parameters by prefix and depth; describe gives type and description."""
    listed = call(graph, "/virtual_robot/list_parameters", {"prefixes": ["lidar"], "depth": 1})
    assert "lidar.rays" in listed["result"]["names"] and listed["result"]["prefixes"] == ["lidar"]
    every = call(graph, "/virtual_robot/list_parameters", {})
    assert "robot.mass" in every["result"]["names"]
    (d,) = call(graph, "/virtual_robot/describe_parameters", {"names": ["lidar.rays"]})[
        "descriptors"
    ]
    assert d["type"] == 2 and d["description"]
    assert d["integer_range"] == [{"from_value": 1, "to_value": 8192, "step": 0}]
    assert d["additional_constraints"] == ">= 1 and <= 8192"


def test_describe_parameters_gives_the_declared_bounds(graph: Graph) -> None:
    """Constraints from the parameters' declarations; a ROS range only where it is inclusive."""
    names = ["robot.mass", "lidar.noise_stddev", "lidar.mount", "safety.stop_on_disconnect"]
    mass, noise, mount, flag = call(graph, "/virtual_robot/describe_parameters", {"names": names})[
        "descriptors"
    ]
    assert (mass["additional_constraints"], mass["floating_point_range"]) == ("> 0 and <= 1000", [])
    assert mass["description"] == Params.describe()["robot.mass"]
    assert noise["floating_point_range"] == [{"from_value": 0.0, "to_value": 1.0, "step": 0.0}]
    assert mount["additional_constraints"] == flag["additional_constraints"] == ""


def test_a_request_of_too_many_names_is_refused_before_its_answer_is_built(
    graph: Graph,
) -> None:
    """Past max_parameter_names, each service refuses by name; at the limit it answers."""
    limit = graph.max_parameter_names
    for service, args in (
        ("describe_parameters", {"names": ["x"] * (limit + 1)}),
        ("get_parameters", {"names": ["x"] * (limit + 1)}),
        ("get_parameter_types", {"names": ["x"] * (limit + 1)}),
        ("list_parameters", {"prefixes": ["x"] * (limit + 1)}),
    ):
        peer = RecordingPeer(graph)
        body = {"op": "call_service", "service": f"/virtual_robot/{service}", "args": args}
        rosbridge_of(graph).receive(peer, json.dumps(body), 0.0)
        (reply,) = peer.take()
        assert reply["result"] is False, service
        assert f"{limit + 1} " in reply["values"] and "max_parameter_names" in reply["values"]
    values = call(graph, "/virtual_robot/describe_parameters", {"names": ["x"] * limit})
    assert len(values["descriptors"]) == limit
