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
envelope once per topic spelling. Encoding is cbor2's (C extension), with a hook for numpy:
measured faster than the hand-written encoder it replaced (``python -m bench cbor``).
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from simbridge.errors import ProtocolError
from simbridge.rosbridge.encoding import Frame, Outgoing


if TYPE_CHECKING:
    import cbor2

# cbor2 is imported on first use (a client subscribing with cbor or cbor-raw): its C extension
# and module cost an idle server about 0.7 MB resident (issue 16); afterwards the import
# statement is a dict lookup

__all__ = ["TYPED_ARRAY_TAGS", "encode_cbor", "encode_cbor_frame", "encode_cbor_raw_frame"]

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

_LITTLE = "<"


def _numpy(encoder: cbor2.CBOREncoder, value: Any) -> None:
    """cbor2's hook for what it does not know: numpy arrays and scalars."""
    if isinstance(value, np.ndarray):
        tag = TYPED_ARRAY_TAGS.get(value.dtype.char)
        if tag is None or value.ndim != 1:  # bools, strings, 2-D: a plain CBOR array
            encoder.encode(value.tolist())
            return
        if value.dtype.byteorder not in (_LITTLE, "|") and not (
            value.dtype.byteorder == "=" and sys.byteorder == "little"
        ):
            value = value.astype(value.dtype.newbyteorder(_LITTLE))
        import cbor2

        encoder.encode(cbor2.CBORTag(tag, value.tobytes()))
    elif isinstance(value, np.generic):
        encoder.encode(value.item())
    else:
        msg = f"cannot encode a {type(value).__name__} as CBOR"
        raise TypeError(msg)


def encode_cbor(value: Any) -> bytes:
    """Return the CBOR encoding of a canonical message or envelope.

    Floats are 8-byte doubles, integers beyond 64 bits bignums (tags 2 and 3, RFC 8949
    section 3.4.3), numeric numpy arrays RFC 8746 typed arrays.
    """
    import cbor2

    try:
        return cbor2.dumps(value, default=_numpy)
    except cbor2.CBOREncodeError as err:
        if isinstance(err.__cause__, TypeError):
            raise err.__cause__ from None
        raise


#: The CBOR text strings "op", "publish", "topic" and "msg" (major type 3: 0x60 + length, then
#: the UTF-8 bytes; RFC 8949 section 3.1), written out so that importing needs no encoder.
_ENVELOPE = b"\x62op" + b"\x67publish" + b"\x65topic"
_MSG_KEY = b"\x63msg"


def _publish(topic: str, body: bytes) -> Frame:
    return Frame(b"\xa3" + _ENVELOPE + encode_cbor(topic) + _MSG_KEY + body, False)


def encode_cbor_frame(out: Outgoing, topic: str) -> Frame:
    """Return the ``cbor`` publish frame of ``out`` (the CBOR body made once per message)."""
    body = out.cache.get("cbor")
    if body is None:
        body = out.cache["cbor"] = encode_cbor(out.msg)
    return _publish(topic, body)


def encode_cbor_raw_frame(out: Outgoing, topic: str) -> Frame:
    """Return the ``cbor-raw`` publish frame of ``out`` (its CDR, made once, in CBOR)."""
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
