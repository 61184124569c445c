from __future__ import annotations

import pytest

from simbridge.errors import ProtocolError
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.ops import parse_op


def test_subscribe_with_every_field() -> None:
    """Every subscribe field is read with its type."""
    op = parse_op(
        {
            "op": "subscribe",
            "topic": "/odom",
            "type": "nav_msgs/Odometry",
            "id": "subscribe:/odom:1",
            "throttle_rate": 100,
            "queue_length": 2,
            "fragment_size": 1000,
            "compression": "cbor",
        }
    )
    assert op == o.Subscribe(
        "/odom", "nav_msgs/Odometry", "subscribe:/odom:1", 100, 2, 1000, "cbor"
    )


def test_defaults_fill_optional_fields() -> None:
    """Omitted optional fields take rosbridge's defaults."""
    assert parse_op({"op": "subscribe", "topic": "/x"}) == o.Subscribe("/x")
    assert parse_op({"op": "advertise", "topic": "/x", "type": "std_msgs/String"}) == o.Advertise(
        "/x", "std_msgs/String", None, False, 100
    )
    assert parse_op({"op": "publish", "topic": "/x"}).msg == {}


@pytest.mark.parametrize(
    ("obj", "text"),
    [
        ({}, "without an op"),
        ({"op": 5}, "op field must be a string"),
        ({"op": "frobnicate"}, "unknown operation 'frobnicate'"),
        ({"op": "subscribe"}, "expected a topic field"),
        ({"op": "subscribe", "topic": 3}, "topic to be a string"),
        (
            {"op": "subscribe", "topic": "/x", "throttle_rate": 1.5},
            "throttle_rate to be an integer",
        ),
        ({"op": "subscribe", "topic": "/x", "queue_length": -1}, "out of range"),
        ({"op": "subscribe", "topic": "/x", "compression": "zip"}, "compression 'zip'"),
        ({"op": "advertise", "topic": "/x"}, "expected a type field"),
        ({"op": "publish", "topic": "/x", "latch": "yes"}, "latch to be a boolean"),
        ({"op": "call_service", "service": "/s", "args": 3}, "args to be an object or a list"),
        ({"op": "call_service", "service": "/s", "timeout": "soon"}, "timeout to be a number"),
        ({"op": "subscribe", "topic": "/x", "id": [1]}, "id to be a string or an integer"),
        ({"op": "fragment", "id": "f", "data": "x", "num": 3, "total": 2}, "num = 3"),
        ({"op": "service_response", "service": "/s", "result": "ok"}, "result to be a boolean"),
    ],
)
def test_malformed_ops_raise_with_a_rosbridge_style_reason(obj: object, text: str) -> None:
    """Missing, wrong-typed or absurd fields raise ProtocolError naming the field."""
    with pytest.raises(ProtocolError, match=text):
        parse_op(obj)


def test_non_object_message_is_refused() -> None:
    """A JSON array is not a rosbridge message."""
    with pytest.raises(ProtocolError, match="JSON object"):
        parse_op([1, 2])


def test_integral_float_is_accepted_for_integer_fields() -> None:
    """throttle_rate 100.0 (as some JS code sends) counts as 100."""
    assert parse_op({"op": "subscribe", "topic": "/x", "throttle_rate": 100.0}).throttle_rate == 100


def test_float_fragment_total_is_floored_like_roslibjs() -> None:
    """Rosbridge sends total as a float; it is floored."""
    op = parse_op({"op": "fragment", "id": 0, "data": "{", "num": 0, "total": 2.4})
    assert op == o.Fragment(0, "{", 0, 2)


def test_service_response_keeps_missing_result_and_values_apart() -> None:
    """Result absent -> None; whether values was sent is recorded."""
    op = parse_op({"op": "service_response", "service": "/s", "id": "a"})
    assert isinstance(op, o.ServiceResponse)
    assert (op.result, op.has_values) == (None, False)


def test_auth_op_reads_rosauth_fields() -> None:
    """Auth carries mac, client, dest, rand, t, level, end."""
    op = parse_op(
        {
            "op": "auth",
            "mac": "m",
            "client": "c",
            "dest": "d",
            "rand": "r",
            "t": 1,
            "level": "user",
            "end": 2,
        }
    )
    assert op == o.Auth("m", "c", "d", "r", 1, "user", 2)


def test_a_huge_integer_timeout_is_a_protocol_error_not_an_overflow() -> None:
    """call_service timeout 10**400 (found by bench/hostile.py: was an internal error)."""
    with pytest.raises(ProtocolError, match="finite number"):
        parse_op({"op": "call_service", "service": "/x", "timeout": 10**400})
