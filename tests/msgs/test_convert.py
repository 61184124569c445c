from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.errors import ConversionError
from simbridge.msgs import Converter, TypeRegistry


NOW = (1_700_000_000, 123)


@pytest.fixture(scope="module")
def conv() -> Converter:
    return Converter(TypeRegistry(), lambda: NOW)


def test_missing_fields_get_defaults(conv: Converter) -> None:
    """A partial Twist is filled with zeros, as rosbridge does."""
    msg = conv.from_json("geometry_msgs/Twist", {"linear": {"x": 0.3}})
    assert msg == {
        "linear": {"x": 0.3, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }


def test_integer_is_accepted_for_a_float_field(conv: Converter) -> None:
    """JSON 1 for a float64 becomes 1.0."""
    msg = conv.from_json("geometry_msgs/msg/Vector3", {"x": 1})
    assert msg["x"] == 1.0
    assert isinstance(msg["x"], float)


def test_unknown_field_is_rejected_with_its_path(conv: Converter) -> None:
    """A key that is not a field names the full path."""
    with pytest.raises(ConversionError, match=r"does not have a field linear\.q"):
        conv.from_json("geometry_msgs/msg/Twist", {"linear": {"q": 1}})


@pytest.mark.parametrize(
    ("type_name", "payload", "where"),
    [
        ("geometry_msgs/msg/Twist", {"linear": {"x": "fast"}}, "linear.x"),
        ("geometry_msgs/msg/Twist", {"linear": {"x": True}}, "linear.x"),
        ("geometry_msgs/msg/Twist", {"linear": 3}, "linear"),
        ("std_msgs/msg/Int32", {"data": 1.5}, "data"),
        ("std_msgs/msg/Int32", {"data": 2**31}, "data"),
        ("std_msgs/msg/UInt8", {"data": -1}, "data"),
        ("std_msgs/msg/Bool", {"data": 1}, "data"),
        ("std_msgs/msg/String", {"data": 5}, "data"),
        ("std_msgs/msg/Float32MultiArray", {"data": [1, "x"]}, r"data\[1\]"),
        ("std_msgs/msg/Int8MultiArray", {"data": [1, 300]}, r"data\[1\]"),
        ("std_msgs/msg/Float32MultiArray", {"data": 4}, "data"),
    ],
)
def test_wrong_types_are_rejected_naming_the_field(
    conv: Converter, type_name: str, payload: dict[str, object], where: str
) -> None:
    """Wrong JSON types and out-of-range integers are refused with the field's path."""
    with pytest.raises(ConversionError, match=where):
        conv.from_json(type_name, payload)


def test_non_object_message_is_rejected(conv: Converter) -> None:
    """The payload itself must be an object."""
    with pytest.raises(ConversionError, match="Expected a JSON object"):
        conv.from_json("std_msgs/msg/String", ["x"])


def test_uint8_array_accepts_base64_or_a_list(conv: Converter) -> None:
    """uint8[] in: base64 text or a list of 0-255; canonical form is bytes."""
    a = conv.from_json("std_msgs/msg/UInt8MultiArray", {"data": "AQID"})
    b = conv.from_json("std_msgs/msg/UInt8MultiArray", {"data": [1, 2, 3]})
    assert a["data"] == b["data"] == b"\x01\x02\x03"
    with pytest.raises(ConversionError, match="base64"):
        conv.from_json("std_msgs/msg/UInt8MultiArray", {"data": "not base64!"})


def test_numeric_arrays_become_numpy_of_the_field_dtype(conv: Converter) -> None:
    """float32[] becomes a float32 array; null inside reads as NaN."""
    msg = conv.from_json("sensor_msgs/msg/LaserScan", {"ranges": [1, 2.5, None]})
    assert msg["ranges"].dtype == np.float32
    assert msg["ranges"][:2].tolist() == [1.0, 2.5]
    assert math.isnan(msg["ranges"][2])


def test_fixed_size_array_needs_exact_length(conv: Converter) -> None:
    """float64[36] covariance with 3 numbers is refused; default is 36 zeros."""
    with pytest.raises(ConversionError, match="exactly 36"):
        conv.from_json("geometry_msgs/msg/PoseWithCovariance", {"covariance": [0, 0, 0]})
    default = conv.from_json("geometry_msgs/msg/PoseWithCovariance", {})
    assert default["covariance"].shape == (36,)


def test_time_accepts_both_spellings_and_now(conv: Converter) -> None:
    """Time: sec/secs, nanosec/nsecs, or the string 'now'."""
    a = conv.from_json("std_msgs/msg/Header", {"stamp": {"secs": 5, "nsecs": 7}})
    assert a["stamp"] == {"sec": 5, "nanosec": 7}
    b = conv.from_json("std_msgs/msg/Header", {"stamp": "now"})
    assert b["stamp"] == {"sec": NOW[0], "nanosec": NOW[1]}
    with pytest.raises(ConversionError, match=r"stamp\.nanosec"):
        conv.from_json("std_msgs/msg/Header", {"stamp": {"nanosec": -1}})


def test_ros1_header_seq_is_checked_then_dropped(conv: Converter) -> None:
    """ROS 1's header.seq (roslibpy's Header) is accepted and left out; a bad one is refused."""
    msg = conv.from_json(
        "geometry_msgs/msg/PointStamped",
        {"header": {"seq": 3, "stamp": {"secs": 1, "nsecs": 2}, "frame_id": "base"}},
    )
    assert msg["header"] == {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "base"}
    with pytest.raises(ConversionError, match=r"header\.seq"):
        conv.from_json("geometry_msgs/msg/PointStamped", {"header": {"seq": -1}})
    with pytest.raises(ConversionError, match="does not have a field seq"):
        conv.from_json("std_msgs/msg/String", {"seq": 1})


def test_time_with_both_ros1_and_ros2_names_is_refused(conv: Converter) -> None:
    """{sec, secs} is ambiguous: refused naming both; actionlib GoalID stamps take secs/nsecs."""
    with pytest.raises(ConversionError, match=r"both 'sec' .* and 'secs'"):
        conv.from_json("std_msgs/msg/Header", {"stamp": {"sec": 1, "secs": 1}})
    goal_id = conv.from_json("actionlib_msgs/msg/GoalID", {"stamp": {"secs": 0, "nsecs": 5}})
    assert goal_id == {"stamp": {"sec": 0, "nanosec": 5}, "id": ""}


def test_header_object_without_stamp_is_stamped_now(conv: Converter) -> None:
    """A header object given without stamp gets the current time; an absent header stays 0."""
    stamped = conv.from_json("geometry_msgs/msg/PoseStamped", {"header": {"frame_id": "map"}})
    assert stamped["header"] == {"stamp": {"sec": NOW[0], "nanosec": NOW[1]}, "frame_id": "map"}
    bare = conv.from_json("geometry_msgs/msg/PoseStamped", {})
    assert bare["header"]["stamp"] == {"sec": 0, "nanosec": 0}


def test_nested_message_arrays_are_lists_of_dicts(conv: Converter) -> None:
    """TFMessage.transforms: each element converted with defaults."""
    msg = conv.from_json("tf2_msgs/msg/TFMessage", {"transforms": [{"child_frame_id": "a"}]})
    assert msg["transforms"][0]["child_frame_id"] == "a"
    assert msg["transforms"][0]["transform"]["rotation"]["w"] == 0.0


def test_null_float_reads_as_nan(conv: Converter) -> None:
    """JSON null in a float field is NaN (JSON.stringify writes NaN as null)."""
    msg = conv.from_json("geometry_msgs/msg/Vector3", {"x": None})
    assert math.isnan(msg["x"])


def test_default_message_has_every_field(conv: Converter) -> None:
    """default() builds the all-zero message with a zero stamp."""
    msg = conv.default("nav_msgs/msg/Odometry")
    assert msg["header"]["stamp"] == {"sec": 0, "nanosec": 0}
    assert msg["pose"]["pose"]["orientation"]["w"] == 0.0


def test_integer_too_large_for_a_double_is_a_conversion_error(conv: Converter) -> None:
    """A JSON integer past the float range is refused, not an OverflowError (found by fuzzing)."""
    with pytest.raises(ConversionError, match="out of range for float64"):
        conv.from_json("geometry_msgs/msg/Twist", {"linear": {"x": 10**400}})
    with pytest.raises(ConversionError, match=r"covariance\[1\] = .* out of range"):
        conv.from_json(
            "geometry_msgs/msg/PoseWithCovariance", {"covariance": [0] + [10**400] + [0] * 34}
        )


def test_float32_out_of_range_is_refused_scalars_and_arrays(conv: Converter) -> None:
    """A finite number beyond float32 is refused at publish; inf and NaN (null) stay allowed."""
    with pytest.raises(ConversionError, match="out of range for float32"):
        conv.from_json("std_msgs/msg/Float32", {"data": 1e308})
    assert conv.from_json("std_msgs/msg/Float32", {"data": 3.0e38})["data"] == 3.0e38
    assert math.isinf(conv.from_json("std_msgs/msg/Float32", {"data": math.inf})["data"])
    with pytest.raises(ConversionError, match=r"data\[1\] = 1e\+300 is out of range for float32"):
        conv.from_json("std_msgs/msg/Float32MultiArray", {"data": [1.0, 1e300]})
    out = conv.from_json("std_msgs/msg/Float32MultiArray", {"data": [1, None, 2.5]})
    assert out["data"].dtype == np.float32 and math.isnan(out["data"][1])


def test_nul_in_a_ros_string_is_refused(conv: Converter) -> None:
    with pytest.raises(ConversionError, match="must not contain a NUL"):
        conv.from_json("std_msgs/msg/String", {"data": "a\x00b"})
