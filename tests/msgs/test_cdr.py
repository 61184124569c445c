from __future__ import annotations

import numpy as np
import pytest

from simbridge.msgs import Converter, TypeRegistry
from simbridge.msgs.cdr import CdrReader, CdrWriter
from simbridge.rosbridge.encoding import encode_json


def test_cdr_round_trips_through_rosbags_with_the_encapsulation_header() -> None:
    """LaserScan and Odometry canonical dicts -> CDR (00 01 00 00 ...) -> same values."""
    registry = TypeRegistry()
    convert = Converter(registry, lambda: (7, 8))
    writer = CdrWriter(registry)
    scan = convert.from_json(
        "sensor_msgs/LaserScan", {"header": {"frame_id": "laser"}, "ranges": [1.0, 2.5]}
    )
    data = writer.serialize("sensor_msgs/msg/LaserScan", scan)
    assert data[:4] == b"\x00\x01\x00\x00"
    back = registry.store.deserialize_cdr(data, "sensor_msgs/msg/LaserScan")
    assert back.header.frame_id == "laser" and back.header.stamp.sec == 7
    assert np.array_equal(back.ranges, np.array([1.0, 2.5], dtype=np.float32))
    odom = convert.default("nav_msgs/Odometry")
    back = registry.store.deserialize_cdr(
        writer.serialize("nav_msgs/Odometry", odom), "nav_msgs/msg/Odometry"
    )
    assert back.pose.covariance.shape == (36,)


def test_cdr_of_bytes_bools_strings_and_empty_messages() -> None:
    """uint8[] from bytes, bool[] and string[] sequences, and a field-less request."""
    registry = TypeRegistry()
    convert = Converter(registry, lambda: (0, 0))
    writer = CdrWriter(registry)
    value = convert.from_json(
        "rcl_interfaces/msg/ParameterValue",
        {
            "type": 5,
            "byte_array_value": [1, 2],
            "bool_array_value": [True],
            "string_array_value": ["a"],
        },
    )
    data = writer.serialize("rcl_interfaces/msg/ParameterValue", value)
    back = registry.store.deserialize_cdr(data, "rcl_interfaces/msg/ParameterValue")
    assert list(back.byte_array_value) == [1, 2] and list(back.bool_array_value) == [True]
    assert back.string_array_value == ["a"]
    assert len(writer.serialize("std_srvs/srv/Empty_Request", {})) == 5


def test_a_message_is_serialized_once_whoever_asks_for_its_cdr() -> None:
    """cbor-raw subscribers and ROS 2 over Zenoh share one serialization per message."""
    writer = CdrWriter(TypeRegistry())
    cdr = writer.factory("std_msgs/msg/String", {"data": "hi"})
    first = cdr()
    assert cdr() is first  # the same bytes object: computed once, then kept
    assert first[4:] == b"\x03\x00\x00\x00hi\x00"


@pytest.mark.parametrize(
    ("typename", "payload"),
    [
        (
            "nav_msgs/msg/Odometry",
            {"child_frame_id": "base_link", "pose": {"covariance": [0.5] * 36}},
        ),
        ("sensor_msgs/msg/LaserScan", {"ranges": [1.0, float("inf"), 2.5], "intensities": [3.0]}),
        (
            "tf2_msgs/msg/TFMessage",
            {"transforms": [{"child_frame_id": "a"}, {"child_frame_id": "b"}]},
        ),
        ("sensor_msgs/msg/Image", {"encoding": "mono8", "data": [0, 7, 255], "is_bigendian": 1}),
        (
            "diagnostic_msgs/msg/DiagnosticStatus",
            {"name": "x", "values": [{"key": "k", "value": "v"}]},
        ),
        ("std_msgs/msg/Empty", {}),
        ("sensor_msgs/msg/JointState", {"name": ["j1", "j2"], "position": [0.1, 0.2]}),
    ],
)
def test_reading_cdr_gives_what_the_json_converter_gives(typename: str, payload: dict) -> None:
    registry = TypeRegistry()
    convert = Converter(registry, lambda: (7, 8))
    msg = convert.from_json(typename, payload)
    data = CdrWriter(registry).serialize(typename, msg)
    read = CdrReader(registry).read(typename, data)
    assert encode_json(read) == encode_json(msg)


def test_reading_bytes_that_are_not_cdr_of_the_type_raises() -> None:
    reader = CdrReader(TypeRegistry())
    with pytest.raises(Exception, match="Twist"):
        reader.read("geometry_msgs/msg/Twist", b"\x00\x01\x00\x00\x01")
    assert reader.read("std_srvs/srv/Empty_Request", b"\x00\x01\x00\x00") == {}


def test_message_builds_the_rosbags_object_with_typed_arrays() -> None:
    """The object bags write: float32 ranges as a numpy array, values kept."""
    registry = TypeRegistry()
    msg = Converter(registry, lambda: (1, 2)).from_json("sensor_msgs/LaserScan", {"ranges": [1, 2]})
    obj = CdrWriter(registry).message("sensor_msgs/msg/LaserScan", msg)
    assert obj.ranges.dtype == np.float32
    assert obj.ranges.tolist() == [1.0, 2.0]
