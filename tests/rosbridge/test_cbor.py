from __future__ import annotations

import cbor2
import numpy as np
import pytest

from simbridge.errors import ProtocolError
from simbridge.rosbridge import Outgoing, encode_cbor
from simbridge.rosbridge.frames import publish_frame


def test_values_decode_with_cbor2_and_arrays_are_rfc8746_typed_arrays() -> None:
    """Scalars, text, bytes and every numeric dtype (little-endian tagged byte strings)."""
    value = {
        "i": [0, 23, 24, 255, 256, 65536, 2**32, 2**64 - 1, -1, -25, -(2**40), -(2**64)],
        # beyond 64 bits (a JSON client may send them): bignums, tags 2 and 3
        "big": [2**64, 10**40, -(2**64) - 1, -(10**40)],
        "f": 1.5,
        "s": "héllo" * 10,
        "b": [True, False, None],
        "raw": b"\x00\x01",
        "nested": {"deep": [{"x": 1}]},
    }
    assert cbor2.loads(encode_cbor(value)) == value
    tags = {
        "B": 64,
        "H": 69,
        "I": 70,
        "Q": 71,
        "b": 72,
        "h": 77,
        "i": 78,
        "q": 79,
        "f": 85,
        "d": 86,
    }
    for char, tag in tags.items():
        array = np.arange(3, dtype=char)
        decoded = cbor2.loads(encode_cbor(array))
        assert decoded.tag == tag
        assert np.array_equal(
            np.frombuffer(decoded.value, dtype=np.dtype(char).newbyteorder("<")), array
        )
    assert cbor2.loads(encode_cbor(np.array([True, False]))) == [True, False]


def test_cbor_frames_are_binary_and_cbor_raw_needs_a_definition() -> None:
    """cbor: binary publish map; cbor-raw without CDR (unknown type): a clear error."""
    out = Outgoing("/x", None, {"data": np.zeros(36)}, (5, 6))
    frame = publish_frame(out, "cbor", "x")
    assert frame.text is False
    message = cbor2.loads(frame.data)
    assert (message["op"], message["topic"], message["msg"]["data"].tag) == ("publish", "x", 86)
    with pytest.raises(ProtocolError, match="cbor-raw needs the message definition"):
        publish_frame(out, "cbor-raw", "/x")
    raw = Outgoing(
        "/x", "std_msgs/msg/String", {"data": "hi"}, (5, 6), lambda: b"\x00\x01\x00\x00cdr"
    )
    body = cbor2.loads(publish_frame(raw, "cbor-raw", "/x").data)["msg"]
    assert body == {"secs": 5, "nsecs": 6, "bytes": b"\x00\x01\x00\x00cdr"}


def test_encoding_is_exact_floats_doubles_bignums_tagged_big_endian_arrays_little() -> None:
    """The wire bytes clients decode: 0xfb doubles, tags 2/3 bignums, swapped >i4 arrays."""
    assert encode_cbor(1.5) == bytes.fromhex("fb3ff8000000000000")
    assert encode_cbor(2**64) == bytes.fromhex("c249010000000000000000")
    assert encode_cbor(-(2**64) - 1) == bytes.fromhex("c349010000000000000000")
    big_endian = np.array([1, 2], dtype=">i4")
    assert encode_cbor(big_endian) == bytes.fromhex("d84e48") + np.array([1, 2], "<i4").tobytes()
    assert encode_cbor(np.float32(0.5)) == bytes.fromhex("fb3fe0000000000000")
    assert encode_cbor(np.zeros((2, 2))) == cbor2.dumps([[0.0, 0.0], [0.0, 0.0]])


def test_a_value_cbor_cannot_carry_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="cannot encode a object as CBOR"):
        encode_cbor({"x": object()})
