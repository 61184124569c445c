"""The rosbridge v2 protocol, sans-I/O: typed ops, per-client sessions, encodings, fragments.

Nothing here imports asyncio or websockets: bytes and decoded objects go in, frames come out.
A client's :class:`Session` takes its ops and returns effects (:class:`Reply`,
:class:`Subscribed`, :class:`Unsubscribed`, :class:`Advertised`, :class:`Unadvertised`,
:class:`Provided`, :class:`Withdrawn`, :class:`Unlatched`) for the graph to carry out.
"""

from __future__ import annotations

from simbridge.rosbridge.budget import GLOBAL_LIMITS, Limits, Pool, TokenBucket
from simbridge.rosbridge.cbor import encode_cbor
from simbridge.rosbridge.encoding import (
    Frame,
    Outgoing,
    decode_frame,
    encode_json,
    json_frame,
    status_frame,
)
from simbridge.rosbridge.fragments import Defragmenter, split_frame
from simbridge.rosbridge.ops import (
    ClientId,
    Op,
    OpId,
    Refusal,
    parse_op,
    resolve_name,
)
from simbridge.rosbridge.queue import SendQueue
from simbridge.rosbridge.session import (
    NOT_AUTHENTICATED,
    STATUS_LEVELS,
    Advertised,
    Effect,
    Provided,
    Reply,
    Session,
    Subscribed,
    Subscription,
    Unadvertised,
    Unlatched,
    Unsubscribed,
    Withdrawn,
)


__all__ = [
    "GLOBAL_LIMITS",
    "NOT_AUTHENTICATED",
    "STATUS_LEVELS",
    "Advertised",
    "ClientId",
    "Defragmenter",
    "Effect",
    "Frame",
    "Limits",
    "Op",
    "OpId",
    "Outgoing",
    "Pool",
    "Provided",
    "Refusal",
    "Reply",
    "SendQueue",
    "Session",
    "Subscribed",
    "Subscription",
    "TokenBucket",
    "Unadvertised",
    "Unlatched",
    "Unsubscribed",
    "Withdrawn",
    "decode_frame",
    "encode_cbor",
    "encode_json",
    "json_frame",
    "parse_op",
    "resolve_name",
    "split_frame",
    "status_frame",
]
