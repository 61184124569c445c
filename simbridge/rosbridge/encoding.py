"""Wire encodings of rosbridge messages: JSON in, and JSON (plus extensions) out.

Outgoing JSON is produced by orjson, which writes NaN and infinities as ``null`` (never the bare
``NaN`` tokens that ``JSON.parse`` rejects, rosbridge issue #916), numpy arrays natively, and
``bytes`` as base64 text (rosbridge's ``uint8[]`` convention). JSON goes out in text frames;
binary encodings (CBOR) in binary frames (protocol reference section 1.1).

A message published on a topic is wrapped in an :class:`Outgoing`, which encodes it at most once
per encoding and topic spelling, however many clients receive it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any, NamedTuple

import orjson

from simbridge.errors import ProtocolError
from simbridge.msgs.message import Outgoing, encode_json


__all__ = [
    "Encoder",
    "Frame",
    "Outgoing",
    "decode_frame",
    "encode_json",
    "encode_none",
    "json_body",
    "json_frame",
    "status_frame",
]

#: JSON values one frame may carry (concatenated ops); more is refused, not parsed.
MAX_OPS_PER_FRAME = 100


class Frame(NamedTuple):
    """One WebSocket message to send: its bytes and whether it is a text frame."""

    data: bytes
    text: bool


def json_frame(obj: Any) -> Frame:
    """Return a text frame holding the JSON of ``obj``."""
    return Frame(encode_json(obj), True)


def status_frame(level: str, text: str, op_id: object = None) -> Frame:
    """Return a rosbridge ``status`` message (protocol section 3.2 of ROSBRIDGE_PROTOCOL.md)."""
    body: dict[str, Any] = {"op": "status", "level": level, "msg": text}
    if op_id is not None:
        body["id"] = op_id
    return json_frame(body)


def _decode_lenient(text: str) -> list[Any]:
    """Decode one or more concatenated JSON values, tolerating NaN/Infinity tokens.

    roslibpy serializes with Python's ``json.dumps``, which writes a float NaN as ``NaN``; and
    rosbridge accepts several objects in one frame. Both cases land here, off the fast path.
    """
    decoder = json.JSONDecoder()
    out: list[Any] = []
    pos = 0
    end = len(text)
    while True:
        while pos < end and text[pos] in " \t\r\n":
            pos += 1
        if pos >= end:
            return out
        if len(out) >= MAX_OPS_PER_FRAME:
            msg = f"more than {MAX_OPS_PER_FRAME} JSON values in one frame"
            raise ValueError(msg)
        value, pos = decoder.raw_decode(text, pos)
        out.append(value)


def decode_frame(data: str | bytes, kind: str | None = None) -> list[Any]:
    """Return the JSON values of one incoming WebSocket message.

    Binary frames are read as UTF-8 JSON, as ROS 2 rosbridge does. ``kind`` names the frame in
    errors (default: ``text`` or ``binary`` by the type of ``data``).

    Raises:
        ProtocolError: the frame is not valid UTF-8 JSON.
    """
    try:
        return [orjson.loads(data)]
    except orjson.JSONDecodeError:
        pass
    try:
        text = data if isinstance(data, str) else bytes(data).decode("utf-8")
        values = _decode_lenient(text)
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        kind = kind or ("text" if isinstance(data, str) else "binary")
        reason = str(err).split(":")[0] if isinstance(err, ValueError) else type(err).__name__
        msg = f"could not decode the {kind} frame as JSON ({reason}); send one JSON object"
        raise ProtocolError(msg) from None
    if not values:
        msg = "received an empty frame; send one JSON object per message"
        raise ProtocolError(msg)
    _check_unicode(values)
    return values


_SURROGATE = re.compile("[\ud800-\udfff]")


def _check_unicode(values: list[Any]) -> None:
    r"""Refuse strings (keys too) holding a lone UTF-16 surrogate such as ``"\ud800"``.

    Python's JSON decoder accepts the escape; no encoder can write it out again (UTF-8 has no
    surrogates), so a stored one would fail every later delivery. orjson refuses them itself:
    only the lenient path needs this walk.

    Raises:
        ProtocolError: a string holds a lone surrogate.
    """
    stack: list[Any] = list(values)
    while stack:
        value = stack.pop()
        if isinstance(value, str):
            found = _SURROGATE.search(value)
        elif isinstance(value, dict):
            stack.extend(value.values())
            found = next((m for k in value if (m := _SURROGATE.search(k))), None)
        elif isinstance(value, list):
            stack.extend(value)
            continue
        else:
            continue
        if found is not None:
            code = f"\\u{ord(found.group()):04x}"
            msg = (
                f"a string holds the lone UTF-16 surrogate {code}, which is not valid Unicode "
                "(pair it, or send the text as UTF-8)"
            )
            raise ProtocolError(msg)


#: Builds the frame of a published message for one compression: ``(outgoing, topic) -> Frame``.
Encoder = Callable[[Outgoing, str], Frame]


def json_body(out: Outgoing) -> bytes:
    """Return the JSON of the message itself, computed once per message."""
    body: bytes | None = out.cache.get("json")
    if body is None:
        body = out.cache["json"] = encode_json(out.msg)
    return body


def encode_none(out: Outgoing, topic: str) -> Frame:
    """Return the JSON ``publish`` frame of ``out`` for the topic spelling ``topic``."""
    head = b'{"op":"publish","topic":' + orjson.dumps(topic) + b',"msg":'
    return Frame(head + json_body(out) + b"}", True)
