"""Per-client protocol state: subscriptions and their delivery rules, ownership, fragments.

A :class:`Session` is sans-I/O. It turns incoming frames into typed ops
(:meth:`Session.parse`) and keeps what the client owns (subscriptions, advertisements,
services, actions) so that the graph can route messages to it and clean up when it leaves.

Subscription rules (protocol reference section 2.4): a client receives each message of a topic
once, however many subscribe ids it holds on it; the ids' options merge as
``throttle_rate = min``, ``queue_length = min``, ``fragment_size = min of those given`` and
compression by precedence ``cbor-raw > cbor > png > none``. A throttled subscription drops
messages that arrive less than ``throttle_rate`` ms after the last one sent (less a small
jitter allowance).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

from simbridge.errors import ProtocolError
from simbridge.protocol.encoding import decode_frame
from simbridge.protocol.fragments import Defragmenter
from simbridge.protocol.ops import ClientId, Fragment, Op, OpId, Subscribe, parse_op


__all__ = ["STATUS_LEVELS", "Session", "Subscription", "resolve_name"]

#: ``status`` levels, most verbose first (ROSBRIDGE_PROTOCOL.md section 3.2).
STATUS_LEVELS: tuple[str, ...] = ("info", "warning", "error", "none")
_COMPRESSION_RANK = {"none": 0, "png": 1, "cbor": 2, "cbor-raw": 3}
_NAME = re.compile(r"^/?[A-Za-z_~][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*/?$")


def resolve_name(name: str, what: str = "topic") -> str:
    """Return the absolute ROS name of ``name`` relative to the root namespace.

    ``rosapi/topics`` becomes ``/rosapi/topics`` (roslibjs 2.1 sends relative names); a
    trailing slash is dropped.

    Raises:
        ProtocolError: not a valid ROS name.
    """
    if len(name) > 256 or not _NAME.match(name) or name in ("/", "~"):
        shown = name if len(name) <= 60 else name[:57] + "..."
        msg = (
            f"{what} name '{shown}' is not a valid ROS name "
            "(letters, digits and underscores, separated by '/')"
        )
        raise ProtocolError(msg)
    name = name.rstrip("/")
    return name if name.startswith("/") else "/" + name


@dataclass(slots=True, eq=False)
class Subscription:
    """One client's subscription to one topic spelling, with every subscribe id merged."""

    #: The topic exactly as the client wrote it (echoed in every ``publish``).
    topic: str
    #: The absolute topic name.
    resolved: str
    #: Options of each subscribe id.
    ids: dict[OpId | None, Subscribe] = field(default_factory=dict)
    throttle_rate: int = 0
    queue_length: int = 0
    fragment_size: int | None = None
    compression: str = "none"
    #: When the last message was sent (monotonic seconds), for throttling.
    last_sent: float = -math.inf
    #: An encoding error was already reported to the client.
    warned: bool = False

    def add(self, op: Subscribe) -> None:
        """Add (or replace) one subscribe id and re-merge the options."""
        self.ids[op.id] = op
        self._merge()

    def remove(self, op_id: OpId | None) -> bool:
        """Remove one id (``None``: all); return whether the subscription is now empty."""
        if op_id is None:
            self.ids.clear()
        else:
            self.ids.pop(op_id, None)
        if self.ids:
            self._merge()
        return not self.ids

    def admit(self, now: float) -> bool:
        """Return whether a message arriving at ``now`` passes the throttle (and count it).

        A message is dropped when it comes less than ``throttle_rate`` ms after the last one
        sent, less a jitter allowance of 10% (at most 10 ms): a 20 Hz topic throttled to 200 ms
        then arrives at 5 Hz, not at 4 Hz whenever a tick is a fraction of a millisecond early.
        """
        if self.throttle_rate:
            window = self.throttle_rate - min(0.1 * self.throttle_rate, 10.0)
            if (now - self.last_sent) * 1000.0 < window:
                return False
        self.last_sent = now
        return True

    def _merge(self) -> None:
        ops = list(self.ids.values())
        self.throttle_rate = min(o.throttle_rate for o in ops)
        self.queue_length = min(o.queue_length for o in ops)
        sizes = [o.fragment_size for o in ops if o.fragment_size is not None]
        self.fragment_size = min(sizes) if sizes else None
        self.compression = max((o.compression for o in ops), key=_COMPRESSION_RANK.__getitem__)


class Session:
    """Everything simbridge knows about one connected client."""

    def __init__(
        self,
        client_id: ClientId,
        *,
        max_message_size: int = 10_000_000,
        fragment_timeout: float = 60.0,
    ) -> None:
        #: Process-unique id of this client.
        self.client_id = client_id
        #: Subscriptions by topic as written by the client.
        self.subscriptions: dict[str, Subscription] = {}
        #: Advertised topics: absolute name -> {advertise id -> type}.
        self.advertisements: dict[str, dict[OpId | None, str]] = {}
        #: Services this client provides: absolute name -> type.
        self.services: dict[str, str] = {}
        #: Actions this client serves: absolute name -> type.
        self.actions: dict[str, str] = {}
        self._fragment_size: int | None = None
        #: Lowest ``status`` level sent to this client (``set_level``).
        self.status_level = "error"
        #: Reassembly of incoming ``fragment`` ops.
        self.defrag = Defragmenter(max_bytes=max_message_size, timeout=fragment_timeout)
        #: Free-form per-client data of extensions (auth state, rate limits...).
        self.extra: dict[str, Any] = {}

    #: Bumped whenever any session's :attr:`fragment_size` changes (delivery plans of topics
    #: depend on it; see :class:`~simbridge.graph.topics.TopicTable`).
    epoch = 0

    @property
    def fragment_size(self) -> int | None:
        """Client-wide outgoing fragment size (any op carrying ``fragment_size`` sets it)."""
        return self._fragment_size

    @fragment_size.setter
    def fragment_size(self, size: int | None) -> None:
        if size != self._fragment_size:
            self._fragment_size = size
            Session.epoch += 1

    def parse(self, data: str | bytes, now: float) -> list[Op | ProtocolError]:
        """Decode one incoming frame into ops; errors come back in place, never raised.

        Complete ``fragment`` sequences are reassembled and parsed here; an incomplete one
        yields nothing yet.
        """
        try:
            values = decode_frame(data)
        except ProtocolError as err:
            return [err]
        out: list[Op | ProtocolError] = []
        for value in values:
            try:
                op = parse_op(value)
                if isinstance(op, Fragment):
                    text = self.defrag.add(op, now)
                    if text is not None:
                        out.extend(self.parse(text, now))
                    continue
                out.append(op)
            except ProtocolError as err:
                out.append(err)
        return out

    def wants_status(self, level: str) -> bool:
        """Return whether a ``status`` of ``level`` should be sent (per ``set_level``)."""
        if level not in STATUS_LEVELS or self.status_level == "none":
            return False
        return STATUS_LEVELS.index(level) >= STATUS_LEVELS.index(self.status_level)

    def set_level(self, level: str) -> None:
        """Apply a ``set_level`` op.

        Raises:
            ProtocolError: an unknown level.
        """
        if level not in STATUS_LEVELS:
            msg = f"set_level: level '{level}' is not one of {', '.join(STATUS_LEVELS)}"
            raise ProtocolError(msg)
        self.status_level = level
