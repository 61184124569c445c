"""The compiled CDR codec writes and reads exactly what rosbags does, for every known type."""

from __future__ import annotations

import numpy as np
import pytest

from simbridge.errors import TypeNotFoundError
from simbridge.msgs import Converter, TypeRegistry
from simbridge.msgs.cdr import CdrReader, CdrWriter
from simbridge.msgs.cdrcodec import LAYOUTS_KEPT
from simbridge.rosbridge.encoding import encode_json


@pytest.fixture(scope="module")
def parts() -> tuple[TypeRegistry, Converter, CdrWriter, CdrReader]:
    registry = TypeRegistry()
    registry.action_wire("example_interfaces/action/Fibonacci")
    return registry, Converter(registry, lambda: (7, 8)), CdrWriter(registry), CdrReader(registry)


def test_every_known_type_encodes_and_decodes_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader],
) -> None:
    registry, convert, writer, reader = parts
    compared = 0
    for typename in registry.types():
        try:
            msg = convert.default(typename)
        except TypeNotFoundError:  # wstring: the converter has no such type either
            continue
        data = writer.serialize(typename, msg)
        assert data == writer.serialize_with_rosbags(typename, msg), typename
        assert encode_json(reader.read(typename, data)) == encode_json(
            reader.read_with_rosbags(typename, data)
        ), typename
        compared += 1
    assert compared > 250


def _encodes_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader], typename: str, payload: dict
) -> None:
    """The bytes are rosbags' for the same message, and they read back to the message."""
    _registry, convert, writer, reader = parts
    msg = convert.from_json(typename, payload)
    data = writer.serialize(typename, msg)
    assert data == writer.serialize_with_rosbags(typename, msg)
    assert encode_json(reader.read(typename, data)) == encode_json(msg)


@pytest.mark.parametrize(
    ("typename", "payload"),
    [
        ("nav_msgs/msg/Odometry", {"child_frame_id": "odd", "pose": {"covariance": [0.5] * 36}}),
        ("sensor_msgs/msg/LaserScan", {"ranges": [1.0, 2.5, 3.0], "intensities": [3.0]}),
        ("tf2_msgs/msg/TFMessage", {"transforms": [{"child_frame_id": "a"}, {}]}),
        ("std_msgs/msg/Float64MultiArray", {"layout": {"dim": [{"label": "x"}]}, "data": [1.5]}),
        ("sensor_msgs/msg/Image", {"encoding": "mono8", "data": [0, 7, 255], "step": 3}),
        ("sensor_msgs/msg/JointState", {"name": ["j1", "j22"], "velocity": [0.1, 0.2]}),
        (
            "rcl_interfaces/msg/ParameterValue",
            {"byte_array_value": [1], "bool_array_value": [True, False], "integer_value": -3},
        ),
        (
            "example_interfaces/action/Fibonacci_SendGoal_Request",
            {"goal_id": {"uuid": list(range(16))}, "goal": {"order": 9}},
        ),
        ("std_msgs/msg/String", {"data": "grüße"}),
    ],
)
def test_messages_with_values_encode_and_decode_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader], typename: str, payload: dict
) -> None:
    _encodes_as_rosbags_does(parts, typename, payload)


def test_a_fixed_array_of_the_wrong_length_is_refused(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader],
) -> None:
    _registry, convert, writer, _reader = parts
    odom = convert.default("nav_msgs/msg/Odometry")
    odom["pose"]["covariance"] = np.zeros(35)
    with pytest.raises(ValueError, match="covariance has 35 elements, expected 36"):
        writer.serialize("nav_msgs/msg/Odometry", odom)


def test_truncated_or_overlong_counts_are_errors_naming_the_type(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader],
) -> None:
    _registry, convert, writer, reader = parts
    data = writer.serialize("sensor_msgs/msg/LaserScan", convert.default("sensor_msgs/LaserScan"))
    with pytest.raises(ValueError, match="LaserScan"):
        reader.read("sensor_msgs/msg/LaserScan", data[:-3])
    huge = b"\x00\x01\x00\x00" + b"\xff\xff\xff\x7f"  # a string claiming 2 GB
    with pytest.raises(ValueError, match="String"):
        reader.read("std_msgs/msg/String", huge)


@pytest.mark.parametrize(
    "typename",
    [
        "nav_msgs/msg/Odometry",
        "sensor_msgs/msg/LaserScan",
        "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/JointState",
        "diagnostic_msgs/msg/KeyValue",
    ],
)
def test_strings_and_arrays_of_every_length_encode_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader], typename: str
) -> None:
    # every length mod 8 puts the fields after a string or an array at another alignment
    _registry, convert, writer, _reader = parts
    for n in range(10):
        text = "abcdefghij"[:n]
        payload = {
            "header": {"frame_id": text},
            "child_frame_id": text + "é",
            "ranges": [0.25 * k for k in range(n)],
            "intensities": [1.5] * (n % 3),
            "transforms": [{"child_frame_id": text[:k]} for k in range(n % 4)],
            "encoding": text,
            "data": list(range(n)),
            "name": [text] * (n % 3),
            "position": [k / 3 for k in range(n)],
            "key": text,
            "value": text[::-1],
        }
        spec = convert.default(typename)
        msg = convert.from_json(typename, {k: v for k, v in payload.items() if k in spec})
        data = writer.serialize(typename, msg)
        assert data == writer.serialize_with_rosbags(typename, msg), (typename, n)


def test_strings_of_more_lengths_than_the_layouts_kept_encode_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader],
) -> None:
    _registry, _convert, writer, _reader = parts
    for n in (*range(LAYOUTS_KEPT + 10), *range(20)):
        msg = {"key": "k" * (n % 7), "value": "v" * n}
        data = writer.serialize("diagnostic_msgs/msg/KeyValue", msg)
        assert data == writer.serialize_with_rosbags("diagnostic_msgs/msg/KeyValue", msg), n


@pytest.mark.parametrize(
    "ranges",
    [
        [1.0, 2.5, 3.0],
        (1.0, 2.5),
        np.array([1.0, 2.5, 3.0]),  # float64 for a float32[]
        np.array([1.0, 2.5, 3.0], dtype=">f4"),
        np.arange(6, dtype=np.float32)[::2],  # not contiguous
        np.arange(6, dtype=np.float32).reshape(2, 3),
        np.array([1, 2, 3]),
    ],
    ids=["list", "tuple", "float64", "big-endian", "strided", "2-d", "int"],
)
def test_arrays_of_any_form_encode_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader], ranges: object
) -> None:
    _registry, convert, writer, _reader = parts
    msg = convert.default("sensor_msgs/msg/LaserScan")
    msg["ranges"] = ranges
    msg["intensities"] = np.ones(2, dtype=np.float32)
    data = writer.serialize("sensor_msgs/msg/LaserScan", msg)
    expected = dict(msg, ranges=np.asarray(ranges, dtype=np.float32).ravel())
    assert data == writer.serialize_with_rosbags("sensor_msgs/msg/LaserScan", expected)


@pytest.mark.parametrize(
    ("typename", "payload"),
    [
        ("geometry_msgs/msg/PolygonStamped", {"polygon": {"points": [{"x": 1.5}, {"y": 2.0}] * 3}}),
        ("geometry_msgs/msg/PoseArray", {"poses": [{"position": {"x": 1.0}}, {}, {}]}),
        (
            "visualization_msgs/msg/MarkerArray",
            {
                "markers": [
                    {"ns": "a", "points": [{"x": 1.0}, {"z": 2.0}], "text": "hi"},
                    {"ns": "bcd", "colors": [{"r": 0.5}], "header": {"frame_id": "map"}},
                ]
            },
        ),
    ],
)
def test_sequences_of_messages_encode_as_rosbags_does(
    parts: tuple[TypeRegistry, Converter, CdrWriter, CdrReader], typename: str, payload: dict
) -> None:
    # elements that one pack writes are written in the sequence's loop; the others by a call
    _encodes_as_rosbags_does(parts, typename, payload)
