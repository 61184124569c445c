"""CBOR (RFC 8949) for the ``cbor`` and ``cbor-raw`` compressions, for simbridge's own shapes.

``cbor`` (protocol reference section 3.7) encodes the whole ``publish`` message as a CBOR map:
strings as text, ``uint8``/``char`` arrays as byte strings and numeric arrays as RFC 8746 typed
arrays (a tag over the little-endian bytes: 64 uint8, 69 uint16, 70 uint32, 71 uint64, 72 int8,
77 int16, 78 int32, 79 int64, 85 float32, 86 float64), exactly as rosbridge does. Unlike
rosbridge 2.1 (#864, #965) fixed-size arrays (e.g. covariances) work too. Floats are always
8-byte doubles, as Python's ``cbor`` libraries write them.

``cbor-raw`` sends ``{"op": "publish", "topic", "msg": {"secs", "nsecs", "bytes"}}`` with the
message's ROS 2 CDR serialization (4-byte encapsulation header included) as a byte string;
Foxglove and Lichtblick decode it with the ``typedefs_full_text`` of ``topics_and_raw_types``.

Both go out in binary frames. The message body is encoded once per :class:`Outgoing`, the
envelope once per topic spelling. Nothing here needs a CBOR library at run time.
"""

from __future__ import annotations

import struct
import sys
from typing import Any

import numpy as np

from simbridge.errors import ProtocolError
from simbridge.protocol.encoding import Frame, Outgoing


__all__ = ["TYPED_ARRAY_TAGS", "encode_cbor", "register"]

#: RFC 8746 tags of little-endian typed arrays, by numpy dtype character.
TYPED_ARRAY_TAGS: dict[str, int] = {
    "B": 64,
    "H": 69,
    "I": 70,
    "L": 71,
    "Q": 71,
    "b": 72,
    "h": 77,
    "i": 78,
    "l": 79,
    "q": 79,
    "f": 85,
    "d": 86,
}

_BIG_ENDIAN = sys.byteorder == "big"
_DOUBLE = struct.Struct(">Bd")
_U8 = struct.Struct(">BB")
_U16 = struct.Struct(">BH")
_U32 = struct.Struct(">BI")
_U64 = struct.Struct(">BQ")


def _head(major: int, n: int) -> bytes:
    """Return the initial bytes of a data item of ``major`` type with argument ``n``."""
    mt = major << 5
    if n < 24:
        return bytes((mt | n,))
    if n < 0x100:
        return _U8.pack(mt | 24, n)
    if n < 0x10000:
        return _U16.pack(mt | 25, n)
    if n < 0x100000000:
        return _U32.pack(mt | 26, n)
    return _U64.pack(mt | 27, n)


def _array(value: np.ndarray[Any, Any], out: list[bytes]) -> None:
    char = value.dtype.char
    if char == "?":
        out.append(_head(4, len(value)))
        out.extend(b"\xf5" if x else b"\xf4" for x in value.tolist())
        return
    tag = TYPED_ARRAY_TAGS.get(char)
    if tag is None or value.ndim != 1:
        _encode(value.tolist(), out)
        return
    if value.dtype.byteorder == ">" or (_BIG_ENDIAN and value.dtype.byteorder == "="):
        value = value.astype(value.dtype.newbyteorder("<"))
    data = value.tobytes()
    out.append(_head(6, tag))
    out.append(_head(2, len(data)))
    out.append(data)


#: Encoded text strings seen as map keys (field names: a small, fixed set).
_KEYS: dict[str, bytes] = {}


def _text(value: str) -> bytes:
    data = value.encode("utf-8")
    n = len(data)
    if n < 24:
        return bytes((0x60 | n,)) + data
    return _head(3, n) + data


def _encode(value: Any, out: list[bytes]) -> None:
    t = type(value)
    append = out.append
    if t is dict:
        append(_head(5, len(value)))
        keys = _KEYS
        for key, item in value.items():
            encoded = keys.get(key)
            if encoded is None:
                encoded = _text(key)
                if len(keys) < 4096:
                    keys[key] = encoded
            append(encoded)
            it = type(item)
            if it is float:
                append(_DOUBLE.pack(0xFB, item))
            elif it is str:
                append(_text(item))
            elif it is int and 0 <= item < 24:
                append(_SMALL[item])
            else:
                _encode(item, out)
    elif t is float:
        append(_DOUBLE.pack(0xFB, value))
    elif t is str:
        append(_text(value))
    elif t is bool:
        append(b"\xf5" if value else b"\xf4")
    elif t is int:
        if 0 <= value < _BIG:
            append(_head(0, value))
        elif -_BIG <= value < 0:
            append(_head(1, -1 - value))
        else:  # beyond 64 bits (JSON allows it): a bignum, tag 2 or 3 (RFC 8949 3.4.3)
            n = value if value >= 0 else -1 - value
            append(_head(6, 2 if value >= 0 else 3))
            _encode(n.to_bytes((n.bit_length() + 7) // 8, "big"), out)
    elif t is list or t is tuple:
        append(_head(4, len(value)))
        for item in value:
            _encode(item, out)
    elif value is None:
        append(b"\xf6")
    elif t is bytes or t is bytearray or t is memoryview:
        data = bytes(value)
        append(_head(2, len(data)))
        append(data)
    elif t is np.ndarray:
        _array(value, out)
    elif isinstance(value, np.generic):
        _encode(value.item(), out)
    else:
        msg = f"cannot encode a {t.__name__} as CBOR"
        raise TypeError(msg)


_SMALL = [bytes((n,)) for n in range(24)]
#: Integers from ``-_BIG`` to ``_BIG - 1`` fit a CBOR head; others are bignums.
_BIG = 1 << 64


def encode_cbor(value: Any) -> bytes:
    """Return the CBOR encoding of a canonical message or envelope."""
    out: list[bytes] = []
    _encode(value, out)
    return b"".join(out)


_ENVELOPE = encode_cbor("op") + encode_cbor("publish") + encode_cbor("topic")
_MSG_KEY = encode_cbor("msg")


def _publish(topic: str, body: bytes) -> Frame:
    return Frame(b"\xa3" + _ENVELOPE + encode_cbor(topic) + _MSG_KEY + body, False)


def _encode_cbor(out: Outgoing, topic: str) -> Frame:
    body = out.cache.get("cbor")
    if body is None:
        body = out.cache["cbor"] = encode_cbor(out.msg)
    return _publish(topic, body)


def _encode_cbor_raw(out: Outgoing, topic: str) -> Frame:
    body = out.cache.get("cbor-raw")
    if body is None:
        if out.cdr is None:
            msg = (
                f"compression cbor-raw needs the message definition, and the type of "
                f"{out.topic} is not known to simbridge; subscribe with cbor or none"
            )
            raise ProtocolError(msg)
        secs, nsecs = out.stamp
        body = out.cache["cbor-raw"] = encode_cbor(
            {"secs": secs, "nsecs": nsecs, "bytes": out.cdr()}
        )
    return _publish(topic, body)


def register() -> None:
    """Make ``cbor`` and ``cbor-raw`` available to every :class:`Outgoing`."""
    Outgoing.encoders["cbor"] = _encode_cbor
    Outgoing.encoders["cbor-raw"] = _encode_cbor_raw
