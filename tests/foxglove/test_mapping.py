"""The pure parts of the Foxglove front end: parameter names, status frames."""

from __future__ import annotations

import numpy as np

from simbridge.foxglove import param_name, split_param, status_of
from simbridge.foxglove.mapping import plain
from simbridge.rosbridge.encoding import json_frame, status_frame


def test_parameters_are_named_node_dot_parameter_as_foxglove_bridge_names_them() -> None:
    name = param_name("/virtual_robot", "robot.max_linear_velocity")
    assert name == "/virtual_robot.robot.max_linear_velocity"
    assert split_param(name, ["/virtual_robot"]) == ("/virtual_robot", "robot.max_linear_velocity")


def test_split_param_takes_the_longest_node_and_refuses_unknown_names() -> None:
    assert split_param("/a/b.x", ["/a", "/a/b"]) == ("/a/b", "x")
    assert split_param("/a.b.x", ["/a", "/a/b"]) == ("/a", "b.x")
    assert split_param("/virtual_robot.", ["/virtual_robot"]) is None
    assert split_param("robot.mass", ["/virtual_robot"]) is None


def test_status_of_reads_a_rosbridge_status_and_nothing_else() -> None:
    assert status_of(status_frame("error", "publish /x: refused").data) == (
        "error",
        "publish /x: refused",
    )
    assert status_of(json_frame({"op": "service_response", "id": 1}).data) is None
    assert status_of(b"\x00not json") is None


def test_plain_turns_canonical_messages_into_json_values() -> None:
    msg = {"ranges": np.array([1.0, 2.5], dtype=np.float32), "data": b"\x01\x02"}
    assert plain(msg) == {"ranges": [1.0, 2.5], "data": "AQI="}
