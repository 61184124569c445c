"""A message published on the graph, with what each front end encodes of it, made once.

Every subscriber of every front end receives the same :class:`Outgoing` for one publish. A
front end asks it for the encoding its wire needs and keeps that in :attr:`Outgoing.cache`
under its own key (rosbridge's JSON body and frames, the CBOR body, Foxglove's JSON), so that
a message is serialized at most once per encoding, whatever the number of subscribers; the CDR
bytes (ROS 2 over Zenoh and DDS, ``cbor-raw``, Foxglove's ROS 2 channels) are made by the
function the graph gives (:attr:`Outgoing.cdr`) on first use.
"""

from __future__ import annotations

import base64
from collections.abc import Callable
from typing import Any

import numpy as np
import orjson


__all__ = ["Outgoing", "encode_json"]

_OPTS = orjson.OPT_SERIALIZE_NUMPY


class Outgoing:
    """A message published on a topic, encoded lazily and at most once per encoding.

    Attributes:
        topic: the resolved topic name it was published on.
        msgtype: its canonical type, or ``None`` when the type is not known (passed through).
        msg: the canonical message (see :mod:`simbridge.msgs.convert`).
        stamp: (sec, nanosec) when it was published.
        cdr: a function returning its CDR bytes (made once), or ``None`` if the type is unknown.
        cache: the encodings front ends made of it, by a key of their own.
    """

    __slots__ = ("cache", "cdr", "msg", "msgtype", "stamp", "topic")

    def __init__(
        self,
        topic: str,
        msgtype: str | None,
        msg: Any,
        stamp: tuple[int, int] = (0, 0),
        cdr: Callable[[], bytes] | None = None,
    ) -> None:
        self.topic = topic
        self.msgtype = msgtype
        self.msg = msg
        self.stamp = stamp
        self.cdr = cdr
        self.cache: dict[Any, Any] = {}


def _default(value: Any) -> Any:
    if isinstance(value, bytes | bytearray | memoryview):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, np.ndarray):
        return value.tolist()  # non-contiguous or exotic dtype: orjson asks us
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(type(value).__name__)


def encode_json(obj: Any) -> bytes:
    """Return the UTF-8 JSON of a canonical message or envelope (NaN and inf as null).

    An integer beyond 64 bits (a client may send one in a pass-through payload) is written as
    the nearest double, as JavaScript would read it (``null`` past the double range).
    """
    try:
        return orjson.dumps(obj, default=_default, option=_OPTS)
    except orjson.JSONEncodeError as err:
        if "Integer exceeds 64-bit range" not in str(err):
            raise
        return orjson.dumps(_as_doubles(obj), default=_default, option=_OPTS)


def _as_doubles(obj: Any) -> Any:
    """Return ``obj`` with every integer beyond 64 bits replaced by a double (or None)."""
    if isinstance(obj, int) and not isinstance(obj, bool):
        if -(2**63) <= obj < 2**64:
            return obj
        try:
            return float(obj)
        except OverflowError:
            return None
    if isinstance(obj, dict):
        return {k: _as_doubles(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_as_doubles(v) for v in obj]
    return obj
