"""A message published on the graph, with what each front end encodes of it, made once.

Every subscriber of every front end receives the same :class:`Outgoing` for one publish. A
front end asks it for the encoding its wire needs and keeps that in :attr:`Outgoing.cache`
under its own key (rosbridge's JSON body and frames, the CBOR body, Foxglove's JSON), so that
a message is serialized at most once per encoding, whatever the number of subscribers; the CDR
bytes (ROS 2 over Zenoh and DDS, ``cbor-raw``, Foxglove's ROS 2 channels) are made by the
function the graph gives (:attr:`Outgoing.cdr`) on first use.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


__all__ = ["Outgoing"]


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
