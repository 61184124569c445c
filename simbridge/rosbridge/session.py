"""Per-client protocol state: access, subscriptions, ownership, fragments and budgets.

A :class:`Session` is sans-I/O and owns everything simbridge keeps for one client. It turns
incoming frames into typed ops (:meth:`Session.parse`: names resolved, strings checked, nothing
but ``auth`` before the client is admitted), and keeps what the client owns (subscriptions,
advertisements, services, actions, pending calls, latched bytes) within its budgets
(:class:`~simbridge.rosbridge.budget.Limits`, and the :class:`~simbridge.rosbridge.budget.Pool`
shared by every client). The graph asks it before taking anything on the client's behalf; a
budget that is spent raises :class:`~simbridge.rosbridge.ops.Refusal` naming the limit, and
:meth:`Session.close` gives everything back when the client leaves.

Subscription rules (protocol reference section 2.4): a client receives each message of a topic
once, however many subscribe ids it holds on it; the ids' options merge as
``throttle_rate = min``, ``queue_length = min``, ``fragment_size = min of those given`` and
compression by precedence ``cbor-raw > cbor > png > none``. A throttled subscription drops
messages that arrive less than ``throttle_rate`` ms after the last one sent (less a small
jitter allowance).

Ops in, effects out (the sans-I/O shape of python-websockets and h11): the graph hands the
session a client op once :class:`~simbridge.rosbridge.admission.Admission` has allowed it, with what
the graph decided for it (a canonical type); the session updates only its own state, within
its budgets, and returns **effects**, typed data saying what the graph must do for this client
(:class:`Reply`, :class:`Subscribed`, :class:`Unsubscribed`, :class:`Advertised`,
:class:`Unadvertised`, :class:`Provided`, :class:`Withdrawn`, :class:`Unlatched`). The graph
carries them out on its tables (:meth:`Graph.apply <simbridge.graph.graph.Graph.apply>`). A
spent budget raises :class:`~simbridge.rosbridge.ops.Refusal` before anything changed.

The session changes in no other way than through these methods: :meth:`Session.parse` (frames
in), the op methods (:meth:`~Session.subscribe`, :meth:`~Session.unsubscribe`,
:meth:`~Session.advertise`, :meth:`~Session.unadvertise`, :meth:`~Session.publish`,
:meth:`~Session.latch`, :meth:`~Session.provide`, :meth:`~Session.withdraw`,
:meth:`~Session.call`, :meth:`~Session.start_goal`, :meth:`~Session.set_level`,
:meth:`~Session.refused`, :meth:`~Session.close`), and what the graph reports about the client:
its access (:meth:`~Session.connect`, :meth:`~Session.admit`, decided by the guard), a latched
message dropped (:meth:`~Session.unlatch`), a call answered (:meth:`~Session.end_call`), a goal
ended (:meth:`~Session.end_goal`), a name taken over by another provider
(:meth:`~Session.disown`). Everything else is read-only outside
:mod:`simbridge.rosbridge` (the access is exposed as properties).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, TypeAlias

from simbridge.errors import ProtocolError
from simbridge.rosbridge.budget import Limits, Pool, TokenBucket
from simbridge.rosbridge.encoding import Frame, decode_frame, status_frame
from simbridge.rosbridge.fragments import Defragmenter
from simbridge.rosbridge.ops import (
    Advertise,
    CallService,
    ClientId,
    Fragment,
    Op,
    OpId,
    Refusal,
    SetLevel,
    Subscribe,
    Unadvertise,
    Unsubscribe,
    parse_op,
    resolve_name,
)


if TYPE_CHECKING:
    from simbridge.graph.access import Access


__all__ = [
    "NOT_AUTHENTICATED",
    "STATUS_LEVELS",
    "Advertised",
    "Effect",
    "Provided",
    "Reply",
    "Session",
    "Subscribed",
    "Subscription",
    "Unadvertised",
    "Unlatched",
    "Unsubscribed",
    "Withdrawn",
    "resolve_name",
]

#: ``status`` levels, most verbose first (ROSBRIDGE_PROTOCOL.md section 3.2).
STATUS_LEVELS: tuple[str, ...] = ("info", "warning", "error", "none")
_COMPRESSION_RANK = {"none": 0, "png": 1, "cbor": 2, "cbor-raw": 3}
#: What a client that still owes a token is told for anything but ``auth``.
NOT_AUTHENTICATED = (
    "not authenticated: this server requires a token; connect with "
    "ws://HOST:PORT/?token=YOUR_TOKEN or send an auth op first"
)
#: What a JSON object and array count for in ``frame_values``, beside one per value: an object
#: becomes a message field by field in Python (~3 us), an array is a container the collector
#: tracks; a number costs ~0.1 us.
OBJECT_COST = 32
ARRAY_COST = 4
#: Distinct refusal causes remembered for the status budget before the memory starts over.
_MAX_CAUSES = 256


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

    def first_warning(self) -> bool:
        """Return whether no encoding error was told for this subscription yet (and count it)."""
        if self.warned:
            return False
        self.warned = True
        return True

    def _merge(self) -> None:
        ops = list(self.ids.values())
        self.throttle_rate = min(o.throttle_rate for o in ops)
        self.queue_length = min(o.queue_length for o in ops)
        sizes = [o.fragment_size for o in ops if o.fragment_size is not None]
        self.fragment_size = min(sizes) if sizes else None
        self.compression = max((o.compression for o in ops), key=_COMPRESSION_RANK.__getitem__)


# -- effects: what a session asks the graph to do for its client ----------------------------

#: What a client may provide besides topics.
Kind = Literal["service", "action"]


@dataclass(frozen=True, slots=True)
class Reply:
    """Send ``frame`` to this client (a ``status``, an answer)."""

    frame: Frame


@dataclass(frozen=True, slots=True)
class Subscribed:
    """The client receives topic ``sub.resolved`` as ``sub.topic`` (options merged in ``sub``).

    ``type`` (canonical) fixes the topic's type when nothing did yet; ``new``: the subscription
    is new, the topic's latched message (if any) is sent to it.
    """

    sub: Subscription
    new: bool
    type: str | None = None


@dataclass(frozen=True, slots=True)
class Unsubscribed:
    """A subscribe id was removed: ``gone`` when the client no longer receives the topic."""

    sub: Subscription
    gone: bool


@dataclass(frozen=True, slots=True)
class Advertised:
    """The client publishes topic ``name`` (canonical ``type``) under advertise id ``op_id``."""

    name: str
    type: str
    op_id: OpId | None
    latch: bool = False


@dataclass(frozen=True, slots=True)
class Unadvertised:
    """The client no longer publishes ``name`` under ``op_id`` (``None``: under any id)."""

    name: str
    op_id: OpId | None


@dataclass(frozen=True, slots=True)
class Provided:
    """The client provides service or action ``name`` (canonical ``type``).

    ``written`` and ``written_type`` are the name and type as the client spelled them (calls and
    goals are forwarded to it so).
    """

    kind: Kind
    name: str
    type: str
    written: str = ""
    written_type: str = ""


@dataclass(frozen=True, slots=True)
class Withdrawn:
    """The client no longer provides service or action ``name``."""

    kind: Kind
    name: str


@dataclass(frozen=True, slots=True)
class Unlatched:
    """The latched message the client left on topic ``name`` goes (the client left)."""

    name: str


Effect: TypeAlias = (
    Reply | Subscribed | Unsubscribed | Advertised | Unadvertised | Provided | Withdrawn | Unlatched
)
#: No effect (shared: the hot path allocates nothing).
NOTHING: tuple[Effect, ...] = ()


class Session:
    """Everything simbridge knows about one connected client."""

    def __init__(
        self,
        client_id: ClientId,
        *,
        limits: Limits | None = None,
        pool: Pool | None = None,
        max_message_size: int | None = None,
        fragment_timeout: float | None = None,
        token: str | None = None,
    ) -> None:
        limits = limits or Limits()
        if max_message_size is not None:
            limits = dataclasses.replace(limits, fragment_bytes=max_message_size)
        if fragment_timeout is not None:
            limits = dataclasses.replace(limits, fragment_timeout=fragment_timeout)
        #: Process-unique id of this client.
        self.client_id = client_id
        #: What this client may hold and do.
        self.limits = limits
        #: What every client together may hold (shared by the sessions of one graph).
        self.pool = pool or Pool()
        #: Who the client is for the graph's rules (set on connect from the token, or by a
        #: successful ``auth`` op; read through the properties below).
        self.access = _access(token, client_id)
        #: ``publish`` rate limit.
        self.publishes = TokenBucket(limits.publish_rate, limits.publish_burst)
        # -- what the client holds --
        #: Subscriptions by topic as written by the client.
        self.subscriptions: dict[str, Subscription] = {}
        #: Subscribe ids over every subscription.
        self.subscribe_ids = 0
        #: Advertised topics: absolute name -> {advertise id -> type}.
        self.advertisements: dict[str, dict[OpId | None, str]] = {}
        #: Advertise ids over every topic.
        self.advertise_ids = 0
        #: Services this client provides: absolute name -> type.
        self.services: dict[str, str] = {}
        #: Actions this client serves: absolute name -> type.
        self.actions: dict[str, str] = {}
        #: Calls of this client waiting for a client provider.
        self.pending_calls = 0
        #: Goals of this client in flight.
        self.pending_goals = 0
        #: Bytes of the latched message this client published last, by topic.
        self.latched: dict[str, int] = {}
        self.latched_bytes = 0
        self._fragment_size: int | None = None
        #: Lowest ``status`` level sent to this client (``set_level``).
        self.status_level = "error"
        #: Reassembly of incoming ``fragment`` ops.
        self.defrag = Defragmenter(
            max_bytes=limits.fragment_bytes,
            timeout=limits.fragment_timeout,
            max_sets=limits.fragment_sets,
            pool=self.pool,
        )
        #: Refusals not told (past the status budget), since the session began.
        self.refusals_untold = 0
        self._told: dict[str, float] = {}
        self._statuses = TokenBucket(limits.statuses_per_second, limits.statuses_per_second)
        self.closed = False

    # -- access: decided by the graph's guard, read by its admission ------------------------

    @property
    def authenticated(self) -> bool:
        """The client is admitted: its ops are carried out (else only ``auth`` is read)."""
        return self.access.authenticated

    @property
    def scope(self) -> str:
        """``"*"`` (any topic) or a robot name (its namespace only)."""
        return self.access.scope

    @property
    def admin(self) -> bool:
        """The client may call administrative services."""
        return self.access.admin

    @property
    def guarded(self) -> bool:
        """A guard gave this client its access (a graph without one trusts everyone)."""
        return self.access.guarded

    @property
    def token(self) -> str | None:
        """The token the client connected with (``?token=``), if any: the guard reads it."""
        return self.access.token

    def connect(self, scope: str, admin: bool, *, authenticated: bool = True) -> None:
        """Take the access a guard gives on connect; ``authenticated=False``: a token is owed."""
        access = self.access
        access.guarded = True
        access.scope, access.admin = scope, admin
        access.authenticated = authenticated

    def admit(self, scope: str, admin: bool) -> None:
        """Admit the client with an access (a token on connect, or a good ``auth`` op)."""
        access = self.access
        access.authenticated = True
        access.scope = scope
        access.admin = admin

    def take_publish(self, now: float) -> bool:
        """Charge one ``publish`` to the client's rate (``publish_rate``); whether it fits.

        Admission decides by it (:meth:`Admission.admit
        <simbridge.rosbridge.admission.Admission.admit>`); the token bucket is the client's.
        """
        return self.publishes.take(now)

    def advertises(self, name: str) -> bool:
        """Return whether the client publishes topic ``name`` (advertised, or by publishing)."""
        return name in self.advertisements

    def provides(self, kind: Kind, name: str) -> bool:
        """Return whether the client provides service or action ``name``."""
        return name in (self.services if kind == "service" else self.actions)

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

    # -- frames in ------------------------------------------------------------------------

    def parse(
        self, data: str | bytes, now: float, kind: str | None = None
    ) -> list[Op | ProtocolError]:
        """Decode one incoming frame into ops; errors come back in place, never raised.

        Complete ``fragment`` sequences are reassembled and parsed here; an incomplete one
        yields nothing yet. Before the client is admitted only a small frame holding ``auth``
        is read: anything else is refused unparsed, fragments are not reassembled.
        """
        if not self.access.authenticated:
            return self._parse_unadmitted(data)
        if not self.access.admin:
            refused = self._too_costly(data)
            if refused is not None:
                return [refused]
        try:
            values = decode_frame(data, kind)
        except ProtocolError as err:
            return [_bare(err)]
        out: list[Op | ProtocolError] = []
        for value in values:
            try:
                op = parse_op(value)
                refused = self._long_id(op)
                if refused is not None:
                    out.append(refused)
                    continue
                if isinstance(op, Fragment):
                    text = self.defrag.add(op, now)
                    if text is not None:
                        out.extend(self.parse(text, now, "reassembled"))
                    continue
                out.append(op)
            except ProtocolError as err:
                out.append(_bare(err))
        return out

    def _too_costly(self, data: str | bytes) -> Refusal | None:
        """Refuse a frame too long (``frame_bytes``) or of too many values, before parsing it.

        A frame is handled in one go (parsed, converted into messages, encoded again for its
        subscribers) and its cost grows with its length and its values: a 9 MB string
        published to one subscriber 58 ms, 700,000 floats 57 ms to parse, a ``nav_msgs/Path``
        of 1,000 poses 18 ms to convert (each object is converted field by field in Python,
        ~3 us, where a number costs ~0.1 us), on a shared x86 core; a Pi 4B core is about five
        times slower. ``frame_values`` bounds the values counted by their commas, each object
        counting :data:`OBJECT_COST` and each array :data:`ARRAY_COST` (three scans, a tenth
        of the cheapest parse; frames too short to reach the budget are not scanned). Commas
        and brackets inside strings count too, erring on the side of the loop.
        """
        limit = self.limits.frame_bytes
        if len(data) > limit:
            unit = "bytes" if isinstance(data, bytes) else "characters"
            msg = (
                f"a frame of {len(data)} {unit} was refused unparsed: longer than {limit} (the "
                "server's max_frame_bytes for clients without the admin token; handling it "
                "would hold the simulation loop); send less in one message"
            )
            return Refusal(msg, cause="max_frame_bytes")
        limit = self.limits.frame_values
        if len(data) * (OBJECT_COST // 2 + 1) <= limit:  # '{}' is the densest: 2 characters
            return None
        if isinstance(data, bytes):
            count = (
                data.count(b",") + OBJECT_COST * data.count(b"{") + ARRAY_COST * data.count(b"[")
            )
        else:
            count = data.count(",") + OBJECT_COST * data.count("{") + ARRAY_COST * data.count("[")
        count += 1
        if count <= limit:
            return None
        msg = (
            f"a frame of about {count} JSON values (an object counts {OBJECT_COST}, an array "
            f"{ARRAY_COST}) was refused unparsed: more than {limit} (the server's "
            "max_frame_values; handling it would hold the simulation loop); send less in one "
            "message"
        )
        return Refusal(msg, cause="max_frame_values")

    def _long_id(self, op: Op) -> Refusal | None:
        """Refuse an op whose ``id`` is longer than ``id_length`` (ids are kept and echoed).

        A subscribe, advertise, call or goal keeps its id as long as it lasts: 1,000
        subscribes with distinct 1 MB ids held 1 GB. The id is not echoed in the refusal (a
        call's failed answer has none): a client that needs its answer uses short ids.
        """
        op_id = getattr(op, "id", None)
        if op_id is None:
            return None
        limit = self.limits.id_length
        if isinstance(op_id, str):
            size = len(op_id) if op_id.isascii() else len(op_id.encode("utf-8", "replace"))
        elif op_id.bit_length() <= 64:
            return None  # up to 20 digits
        else:
            size = len(str(op_id))
        if size <= limit:
            return None
        name = re.sub(r"(?<!^)(?=[A-Z])", "_", type(op).__name__).lower()  # CallService
        unit = "characters" if isinstance(op_id, str) else "digits"
        msg = (
            f"{name}: refused, its id is {size} {unit} long: more than {limit} (the server's "
            "max_id_length; ids are kept while the op lasts); use a shorter id"
        )
        target = getattr(op, "service", None) or getattr(op, "action", None) or ""
        return Refusal(msg, op=name, target=target, cause="max_id_length")

    def _parse_unadmitted(self, data: str | bytes) -> list[Op | ProtocolError]:
        limit = self.limits.unauthenticated_frame_bytes
        if len(data) > limit:
            text = f"{NOT_AUTHENTICATED} (until then frames are limited to {limit} bytes)"
            return [Refusal(text, cause="unauthenticated_frame_bytes")]
        try:
            values = decode_frame(data)
        except ProtocolError as err:
            return [_bare(err)]
        out: list[Op | ProtocolError] = []
        for value in values:
            kind = value.get("op") if isinstance(value, dict) else None
            if kind == "auth":
                try:
                    out.append(parse_op(value))
                except ProtocolError as err:
                    out.append(_bare(err))
                continue
            target = value.get("service") if kind == "call_service" else None
            op_id = value.get("id") if isinstance(value.get("id"), str | int) else None
            if isinstance(target, str):  # a caller waits for its answer: give it one
                out.append(
                    Refusal(
                        NOT_AUTHENTICATED,
                        op="call_service",
                        target=target,
                        op_id=op_id,
                        cause="unauthenticated",
                    )
                )
            else:
                out.append(Refusal(NOT_AUTHENTICATED, cause="unauthenticated"))
        return out

    # -- status ---------------------------------------------------------------------------

    def wants_status(self, level: str) -> bool:
        """Return whether a ``status`` of ``level`` should be sent (per ``set_level``)."""
        if level not in STATUS_LEVELS or self.status_level == "none":
            return False
        return STATUS_LEVELS.index(level) >= STATUS_LEVELS.index(self.status_level)

    def set_level(self, op: SetLevel) -> tuple[Effect, ...]:
        """Apply a ``set_level`` op (no effect on the graph).

        Raises:
            ProtocolError: an unknown level.
        """
        level = op.level
        if level not in STATUS_LEVELS:
            msg = f"set_level: level '{level}' is not one of {', '.join(STATUS_LEVELS)}"
            raise ProtocolError(msg)
        self.status_level = level
        return NOTHING

    def status(self, level: str, text: str, op_id: OpId | None = None) -> tuple[Reply, ...]:
        """Return the ``status`` of ``level`` to send, if the client's ``set_level`` wants it."""
        if not self.wants_status(level):
            return ()
        return (Reply(status_frame(level, text, op_id)),)

    def refused(
        self, text: str, cause: str, now: float, op_id: OpId | None = None
    ) -> tuple[Reply, ...]:
        """Return the ``status`` error telling the client of a refusal, within its budgets.

        Nothing when its ``set_level`` silences errors or the refusal is not told (past the
        status budget, :meth:`may_tell`: it is counted).
        """
        if not self.wants_status("error") or not self.may_tell(cause, now):
            return ()
        return (Reply(status_frame("error", text, op_id)),)

    def may_tell(self, cause: str, now: float) -> bool:
        """Return whether a refusal of ``cause`` may be told now (and count it if not).

        At most one ``status`` per cause per second and ``statuses_per_second`` in all: a
        client that sends 300,000 refused ops costs the server 300,000 counts, not 300,000
        messages.
        """
        last = self._told.get(cause)
        if last is not None and now - last < 1.0:
            self.refusals_untold += 1
            return False
        if not self._statuses.take(now):
            self.refusals_untold += 1
            return False
        if len(self._told) >= _MAX_CAUSES:
            self._told.clear()
        self._told[cause] = now
        return True

    # -- subscriptions --------------------------------------------------------------------

    def subscribe(self, op: Subscribe, type_name: str | None = None) -> tuple[Effect, ...]:
        """Add a subscribe id (``type_name``: its canonical type, if the op gives one).

        Effect: :class:`Subscribed`, with the merged subscription. A ``fragment_size`` becomes
        the client's outgoing fragment size.

        Raises:
            Refusal: a subscription, subscribe-id or global budget is spent.
        """
        if op.fragment_size is not None:
            self.fragment_size = op.fragment_size
        sub = self.subscriptions.get(op.topic)
        limits = self.limits
        if sub is None and len(self.subscriptions) >= limits.subscriptions:
            msg = (
                f"subscribe {op.topic}: refused, this client already has {limits.subscriptions} "
                "subscriptions (the server's max_subscriptions); unsubscribe from some first"
            )
            raise Refusal(msg, op="subscribe", op_id=op.id, cause="max_subscriptions")
        fresh_id = sub is None or op.id not in sub.ids
        if fresh_id:
            if sub is not None and len(sub.ids) >= limits.ids_per_subscription:
                msg = (
                    f"subscribe {op.topic}: refused, this client already holds "
                    f"{limits.ids_per_subscription} subscribe ids on it (the server's "
                    "max_ids_per_subscription); reuse an id or unsubscribe one"
                )
                raise Refusal(msg, op="subscribe", op_id=op.id, cause="max_ids_per_subscription")
            self._take(
                "subscribe_ids",
                self.subscribe_ids,
                limits.subscribe_ids,
                f"subscribe {op.topic}",
                "subscribe ids",
                op.id,
            )
            self.subscribe_ids += 1
        new = sub is None
        if sub is None:
            sub = self.subscriptions[op.topic] = Subscription(op.topic, op.name)
        sub.add(op)
        return (Subscribed(sub, new, type_name),)

    def unsubscribe(self, op: Unsubscribe) -> tuple[Effect, ...]:
        """Remove one subscribe id (``None``: all) of a topic spelling.

        Effect: :class:`Unsubscribed` (``gone`` when the topic is no longer received), or none
        when the client does not subscribe to that spelling.
        """
        return self._unsubscribe(op.topic, op.id)

    def _unsubscribe(self, written: str, op_id: OpId | None) -> tuple[Effect, ...]:
        sub = self.subscriptions.get(written)
        if sub is None:
            return NOTHING
        before = len(sub.ids)
        empty = sub.remove(op_id)
        released = before - len(sub.ids)
        self.subscribe_ids -= released
        self.pool.give("subscribe_ids", released)
        if empty:
            del self.subscriptions[written]
        return (Unsubscribed(sub, empty),)

    # -- advertisements, services, actions ------------------------------------------------

    def owned(self) -> int:
        """Return how many names (topics, services, actions) this client advertises."""
        return len(self.advertisements) + len(self.services) + len(self.actions)

    def may_own(self, what: str, name: str, new: bool) -> None:
        """Check that the client may advertise one more name (when ``new``).

        Raises:
            Refusal: the advertisement budget is spent.
        """
        limit = self.limits.advertisements
        if new and self.owned() >= limit:
            msg = (
                f"{what} {name}: refused, this client already advertises {limit} topics, "
                "services and actions (the server's max_advertisements); unadvertise some first"
            )
            raise Refusal(msg, op=what, cause="max_advertisements")

    def advertise(self, op: Advertise, type_name: str) -> tuple[Effect, ...]:
        """Record an ``advertise`` of canonical type ``type_name``.

        Effect: :class:`Advertised` (again for an id already held: the op may add ``latch``).

        Raises:
            Refusal: the advertisement or advertise-id budget is spent.
        """
        self._advertise(op.name, op.id, type_name)
        return (Advertised(op.name, type_name, op.id, op.latch),)

    def publish(self, name: str, type_name: str) -> tuple[Effect, ...]:
        """Record a ``publish`` on ``name`` (canonical ``type_name``), as the graph admitted it.

        A client that publishes is a publisher of the topic (rosbridge advertises it
        implicitly, advertise id ``None``). Effect: :class:`Advertised` the first time, else
        none (the hot path: a dict lookup).

        Raises:
            Refusal: the advertisement or advertise-id budget is spent.
        """
        ads = self.advertisements.get(name)
        if ads is not None and None in ads:
            return NOTHING
        self._advertise(name, None, type_name)
        return (Advertised(name, type_name, None),)

    def _advertise(self, name: str, op_id: OpId | None, type_name: str) -> bool:
        """Record an advertise id of topic ``name``; return whether the id is new."""
        ads = self.advertisements.get(name)
        self.may_own("advertise", name, ads is None)
        if ads is not None and op_id in ads:
            return False
        self._take(
            "advertise_ids",
            self.advertise_ids,
            self.limits.advertise_ids,
            f"advertise {name}",
            "advertise ids",
            op_id,
        )
        self.advertise_ids += 1
        if ads is None:
            ads = self.advertisements[name] = {}
        ads[op_id] = type_name
        return True

    def unadvertise(self, op: Unadvertise) -> tuple[Effect, ...]:
        """Remove one advertise id of ``op.name`` (``None`` or an id not held: all of them).

        Effect: :class:`Unadvertised` with the id removed (``None``: all), or none when the
        client does not advertise the topic.
        """
        ads = self.advertisements.get(op.name)
        if ads is None:
            return NOTHING
        one = op.id if op.id is not None and op.id in ads else None
        self._unadvertise(op.name, one)
        return (Unadvertised(op.name, one),)

    def _unadvertise(self, name: str, op_id: OpId | None) -> bool:
        """Remove one advertise id of ``name`` (``None`` or unknown: all of them).

        Returns whether the client no longer advertises ``name`` at all.
        """
        ads = self.advertisements.get(name)
        if ads is None:
            return True
        if op_id is not None and op_id in ads:
            del ads[op_id]
            released = 1
        else:
            released = len(ads)
            ads.clear()
        self.advertise_ids -= released
        self.pool.give("advertise_ids", released)
        if ads:
            return False
        del self.advertisements[name]
        return True

    def provide(
        self, kind: Kind, name: str, type_name: str, written: str = "", written_type: str = ""
    ) -> tuple[Effect, ...]:
        """Record an ``advertise_service`` or ``advertise_action`` (canonical ``type_name``).

        Effect: :class:`Provided`. (Whether the name may be taken, and the count of names, is
        admission's: a service the server provides stays the server's.)
        """
        (self.services if kind == "service" else self.actions)[name] = type_name
        return (Provided(kind, name, type_name, written or name, written_type or type_name),)

    def withdraw(self, kind: Kind, name: str) -> tuple[Effect, ...]:
        """Record an ``unadvertise_service`` or ``unadvertise_action``.

        Effect: :class:`Withdrawn`.

        Raises:
            ProtocolError: the client does not provide ``name``.
        """
        owned = self.services if kind == "service" else self.actions
        if owned.pop(name, None) is None:
            msg = f"unadvertise_{kind}: {kind} {name} is not advertised by this client"
            raise ProtocolError(msg)
        return (Withdrawn(kind, name),)

    def disown(self, kind: Kind, name: str) -> None:
        """The graph gave ``name`` to another provider: the client no longer provides it."""
        (self.services if kind == "service" else self.actions).pop(name, None)

    # -- calls and latched messages -------------------------------------------------------

    def call_timeout(self, requested: float | None, default: float) -> float:
        """Return how long a call may wait for a client provider, in seconds.

        No ``timeout`` means ``default``; ``0`` (rosbridge: "wait forever") and anything
        longer than the ``call_timeout`` budget mean the budget: no call waits without end.
        """
        longest = self.limits.call_timeout
        if requested is None:
            return min(default, longest)
        if requested <= 0:
            return longest
        return min(requested, longest)

    def call_service(
        self, op: CallService, now: float, *, waits: bool, default: float
    ) -> float | None:
        """Record a ``call_service``; return its deadline when it ``waits`` for a client provider.

        A waiting call is counted against the pending-call budgets, for ``op.timeout`` (see
        :meth:`call_timeout`; ``default`` when it gives none); the graph reports its end
        (answered, timed out, dropped) with :meth:`end_call`. A ``fragment_size`` becomes the
        client's outgoing fragment size (its answer may be long).

        Raises:
            Refusal: the pending-call budget is spent (answered as a failed call).
        """
        if op.fragment_size is not None:
            self.fragment_size = op.fragment_size
        if not waits:
            return None
        self._start_call(op.service, op.id)
        return now + self.call_timeout(op.timeout, default)

    def _start_call(self, service: str, op_id: OpId | None) -> None:
        limit = self.limits.pending_calls
        if self.pending_calls >= limit:
            msg = (
                f"call_service {service}: refused, this client already waits for {limit} "
                "answers (the server's max_pending_calls); wait for them first"
            )
            raise Refusal(
                msg, op="call_service", target=service, op_id=op_id, cause="max_pending_calls"
            )
        if not self.pool.take("pending_calls"):
            msg = (
                f"call_service {service}: refused, the server waits for its limit of "
                f"{self.pool.limit('pending_calls')} answers for all clients "
                "(global_pending_calls); try again later"
            )
            raise Refusal(
                msg, op="call_service", target=service, op_id=op_id, cause="global_pending_calls"
            )
        self.pending_calls += 1

    def end_call(self) -> None:
        """A call of this client was answered, timed out or dropped."""
        if self.pending_calls > 0:
            self.pending_calls -= 1
            self.pool.give("pending_calls")

    def start_goal(self, action: str, op_id: OpId | None) -> None:
        """Count a goal of this client in flight against the pending-goal budgets.

        The graph reports its end (finished, timed out, dropped) with :meth:`end_goal`.

        Raises:
            Refusal: the budget is spent (answered as a failed ``action_result``).
        """
        limit = self.limits.pending_goals
        if self.pending_goals >= limit:
            msg = (
                f"send_action_goal {action}: refused, this client already has {limit} goals in "
                "flight (the server's max_pending_goals); wait for their results or cancel some"
            )
            raise Refusal(
                msg, op="send_action_goal", target=action, op_id=op_id, cause="max_pending_goals"
            )
        if not self.pool.take("pending_goals"):
            msg = (
                f"send_action_goal {action}: refused, the server has its limit of "
                f"{self.pool.limit('pending_goals')} goals in flight for all clients "
                "(global_pending_goals); try again later"
            )
            raise Refusal(
                msg,
                op="send_action_goal",
                target=action,
                op_id=op_id,
                cause="global_pending_goals",
            )
        self.pending_goals += 1

    def end_goal(self) -> None:
        """A goal of this client finished, timed out or was dropped."""
        if self.pending_goals > 0:
            self.pending_goals -= 1
            self.pool.give("pending_goals")

    def latch(self, name: str, size: int) -> None:
        """Charge the latched message (``size`` bytes) this client leaves on topic ``name``.

        It replaces the client's previous one on that topic.

        Raises:
            Refusal: the latched-bytes budget of the client or of the server is spent.
        """
        old = self.latched.get(name, 0)
        limit = self.limits.latched_bytes
        if self.latched_bytes - old + size > limit:
            msg = (
                f"publish {name}: refused, this client's latched messages would take more than "
                f"{limit} bytes (the server's max_latched_bytes); publish it without latch"
            )
            raise Refusal(msg, op="publish", cause="max_latched_bytes")
        if size > old and not self.pool.take("latched_bytes", size - old):
            msg = (
                f"publish {name}: refused, the server keeps its limit of "
                f"{self.pool.limit('latched_bytes')} bytes of latched messages for all clients "
                "(global_latched_bytes); publish it without latch"
            )
            raise Refusal(msg, op="publish", cause="global_latched_bytes")
        if size < old:
            self.pool.give("latched_bytes", old - size)
        self.latched[name] = size
        self.latched_bytes += size - old

    def unlatch(self, name: str) -> None:
        """The server no longer keeps this client's latched message of topic ``name``."""
        old = self.latched.pop(name, 0)
        self.latched_bytes -= old
        self.pool.give("latched_bytes", old)

    # -- leaving --------------------------------------------------------------------------

    def close(self) -> list[Effect]:
        """Give back everything the client held to the shared pool (it left).

        Effects: what the graph withdraws for it (:class:`Unsubscribed`, :class:`Unadvertised`,
        :class:`Unlatched`, :class:`Withdrawn`). Calls still waiting are ended here; the graph
        forgets them on its side.
        """
        if self.closed:
            return []
        self.closed = True
        self.defrag.clear()
        effects: list[Effect] = []
        for written in list(self.subscriptions):
            effects.extend(self._unsubscribe(written, None))
        for name in list(self.advertisements):
            self._unadvertise(name, None)
            effects.append(Unadvertised(name, None))
        for name in list(self.latched):
            self.unlatch(name)
            effects.append(Unlatched(name))
        effects.extend(Withdrawn("service", name) for name in self.services)
        effects.extend(Withdrawn("action", name) for name in self.actions)
        self.services.clear()
        self.actions.clear()
        while self.pending_calls:
            self.end_call()
        while self.pending_goals:
            self.end_goal()
        return effects

    def _take(
        self, what: str, used: int, limit: int, doing: str, things: str, op_id: OpId | None
    ) -> None:
        if used >= limit:
            msg = (
                f"{doing}: refused, this client already holds {limit} {things} "
                f"(the server's max_{what}); release some first"
            )
            raise Refusal(msg, op=doing.split()[0], op_id=op_id, cause=f"max_{what}")
        if not self.pool.take(what):
            msg = (
                f"{doing}: refused, the server holds its limit of {self.pool.limit(what)} "
                f"{things} for all clients (global_{what}); try again later"
            )
            raise Refusal(msg, op=doing.split()[0], op_id=op_id, cause=f"global_{what}")


def _bare(err: ProtocolError) -> ProtocolError:
    """Return ``err`` without its traceback, to be kept in a list of results.

    The traceback holds the frame of :meth:`Session.parse`, whose locals hold the list and the
    frame's text: a cycle that kept every refused frame (megabytes each) alive until the next
    full garbage collection (issue 17 row 7: 5 clients' refused fragments took 400 MB).
    """
    return err.with_traceback(None)


def _access(token: str | None, client_id: int) -> Access:
    # imported here: the graph's package imports this module (its tables still hold sessions)
    from simbridge.graph.access import Access

    return Access(token=token, peer_id=client_id)
