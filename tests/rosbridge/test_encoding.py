from __future__ import annotations

import json
import math

import numpy as np
import pytest

from simbridge.errors import ProtocolError
from simbridge.rosbridge import Outgoing, decode_frame, encode_json, status_frame
from simbridge.rosbridge.frames import publish_frame


def test_non_finite_floats_are_sent_as_null_even_inside_arrays() -> None:
    """NaN and infinities never appear as bare tokens (rosbridge #916)."""
    data = encode_json(
        {"a": math.nan, "b": [math.inf, 1.0], "c": np.array([np.nan, -np.inf, 2.0], np.float32)}
    )
    assert json.loads(data) == {"a": None, "b": [None, 1.0], "c": [None, None, 2.0]}
    assert b"NaN" not in data and b"Infinity" not in data


def test_bytes_are_sent_as_base64() -> None:
    """uint8[] (bytes) goes out as standard base64 text."""
    assert json.loads(encode_json({"data": b"\x01\x02\x03"})) == {"data": "AQID"}


def test_float32_arrays_keep_their_shortest_float32_text() -> None:
    """float32 values serialise as their float32 repr (compact scans)."""
    assert encode_json(np.array([0.1], np.float32)) == b"[0.1]"


def test_publish_frame_is_encoded_once_per_encoding_and_topic_spelling() -> None:
    """Repeated requests for the same frame return the cached bytes object."""
    out = Outgoing("/odom", "nav_msgs/msg/Odometry", {"x": 1.0})
    first = publish_frame(out, "none", "/odom")
    assert publish_frame(out, "none", "/odom") is first
    assert json.loads(first.data) == {"op": "publish", "topic": "/odom", "msg": {"x": 1.0}}
    assert first.text
    other = publish_frame(out, "none", "odom")
    assert json.loads(other.data)["topic"] == "odom"


def test_unavailable_compression_is_a_protocol_error() -> None:
    """An encoder that does not exist is refused, not crashed on."""
    with pytest.raises(ProtocolError, match="not available"):
        publish_frame(Outgoing("/x", None, {}), "lz77", "/x")


def test_decode_accepts_text_and_utf8_binary_frames() -> None:
    """Binary frames are read as UTF-8 JSON, as ROS 2 rosbridge does."""
    assert decode_frame('{"op":"x"}') == [{"op": "x"}]
    assert decode_frame(b'{"op":"x"}') == [{"op": "x"}]


def test_decode_reads_several_objects_and_python_nan_tokens() -> None:
    """Concatenated objects and NaN tokens (roslibpy's json.dumps) are tolerated."""
    assert decode_frame('{"a":1} {"b":2}') == [{"a": 1}, {"b": 2}]
    value = decode_frame('{"x": NaN}')[0]["x"]
    assert math.isnan(value)


@pytest.mark.parametrize("data", ["", "{", "nope", b"\xff\xfe\x00", "[" * 100_000])
def test_undecodable_frames_raise_a_clear_error(data: str | bytes) -> None:
    """Garbage, truncated JSON, invalid UTF-8 and absurd nesting raise ProtocolError."""
    with pytest.raises(ProtocolError):
        decode_frame(data)


def test_status_frame_shape() -> None:
    """status: op, level, msg and the id when given."""
    assert json.loads(status_frame("error", "bad", "a1").data) == {
        "op": "status",
        "level": "error",
        "msg": "bad",
        "id": "a1",
    }


def test_integers_beyond_64_bits_are_written_as_doubles_not_an_error() -> None:
    """A pass-through payload may hold 2**70 or 10**400 (found by bench/hostile.py)."""
    out = json.loads(encode_json({"a": [2**70, -(2**64) - 1, 10**400, 5], "b": {"c": 2**63}}))
    assert out == {"a": [float(2**70), float(-(2**64) - 1), None, 5], "b": {"c": 2**63}}
