"""Topics of the ROS graph: publishers, subscribers, latched messages and delivery.

A topic's type is fixed by its first publisher or typed subscriber; a later advertise or
subscribe with another type is refused (rosbridge's TypeConflictException), comparing the
canonical ``pkg/msg/Type`` spelling. A subscription to a topic that does not exist yet waits for
it, with or without a type (rosbridge instead drops an untyped one, #1142).

A message is encoded at most once per encoding (see :class:`~simbridge.rosbridge.Outgoing`) and
each client receives it once per topic spelling it subscribed with.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

from simbridge.errors import ProtocolError, TypeNotFoundError
from simbridge.graph.access import Access
from simbridge.msgs import Converter, TypeRegistry, normalize_type
from simbridge.rosbridge import (
    Frame,
    OpId,
    Outgoing,
    Session,
    Subscription,
    split_frame,
)


__all__ = ["BRIDGE_NODE", "InternalCallback", "Peer", "Topic", "TopicTable"]

logger = logging.getLogger(__name__)

#: The node that client-owned publishers, subscribers and services belong to (as in rosbridge).
BRIDGE_NODE = "/rosbridge_websocket"


class Peer(Protocol):
    """A connected client, as the graph sees it."""

    #: The client's protocol state.
    session: Session
    #: A short label for logs ("client 3 127.0.0.1:50412").
    label: str

    @property
    def access(self) -> Access:
        """Who the peer is for the graph's rules (scope, admin rights, token)."""

    def send(self, frame: Frame, key: Hashable | None = None, limit: int = 0) -> None:
        """Queue one frame for the client (``key``/``limit``: drop-oldest per subscription)."""


#: An in-process subscriber: ``(message, sending peer or None) -> None``; may raise
#: :class:`ProtocolError` to refuse a message, which is reported to the sending client.
InternalCallback = Callable[[Any, "Peer | None"], None]


@dataclass(eq=False, slots=True)
class Topic:
    """One topic of the graph."""

    name: str
    #: Canonical type, or ``None`` while only untyped subscribers wait for the topic.
    type: str | None = None
    #: The type is known to the registry (payloads are validated and defaults filled).
    known: bool = False
    #: Publishers: owner (a node name or a Peer) -> advertise ids.
    publishers: dict[object, set[OpId | None]] = field(default_factory=dict)
    #: Client subscriptions by (peer, topic spelling).
    subscriptions: dict[tuple[Peer, str], Subscription] = field(default_factory=dict)
    #: In-process subscribers: (node name, callback).
    internal: list[tuple[str, InternalCallback]] = field(default_factory=list)
    #: Keep the last message for late subscribers (``latch: true``, /tf_static).
    latch: bool = False
    #: The last message, when latched.
    latched: Outgoing | None = None
    #: How a message reaches the client subscribers (rebuilt when subscriptions change).
    plan: _Plan | None = None
    #: The client whose message is latched (charged to its latched-bytes budget), if any.
    latched_by: Peer | None = None

    def unused(self) -> bool:
        """Return whether nothing refers to the topic any more."""
        return not (self.publishers or self.subscriptions or self.internal)


#: Subscribers that get one shared frame: ``(peer, subscription, queue bound)``.
SendEntries = list[tuple[Peer, Hashable, int]]


@dataclass(eq=False, slots=True)
class _Plan:
    """The subscribers of a topic sorted for delivery, valid for one ``version``.

    Most subscribers take the frame as it is: they are grouped by (compression, topic
    spelling), each group written with one ``send_many``. Throttled and fragmented ones are
    served one by one.
    """

    version: tuple[int, int]
    groups: list[tuple[str, str, SendEntries]]
    one_by_one: list[tuple[Peer, Subscription]]


class TopicTable:
    """Every topic, with the rules for advertising, subscribing and publishing."""

    def __init__(
        self, registry: TypeRegistry, converter: Converter, *, default_queue_length: int = 100
    ) -> None:
        #: Interface definitions.
        self.registry = registry
        #: JSON payload validation.
        self.converter = converter
        #: Per-subscription bound of pending frames when a client asked for queue_length 0.
        self.default_queue_length = default_queue_length
        #: Topics by absolute name.
        self.topics: dict[str, Topic] = {}
        #: Sends one frame to many subscribers at once, ``(frame, [(peer, key, limit)])`` (set by
        #: the server: one ``websockets.broadcast`` per frame instead of one call per client).
        self.send_many: Callable[[Frame, SendEntries], None] | None = None
        #: Makes the CDR-bytes function of a message for ``cbor-raw`` (set by extensions).
        self.cdr_factory: Callable[[str, Any], Callable[[], bytes]] | None = None
        #: Bumped by every subscription change: the delivery plans of topics are rebuilt.
        self.generation = 0
        #: Bumped by every change of a topic's type, publishers or subscribers (clients and
        #: in-process): what mirrors the table elsewhere (the Zenoh link) compares it instead
        #: of walking every topic.
        self.changes = 0
        #: Called with ``(topic, message, sending peer or None)`` before each delivery
        #: (extensions: the Zenoh link forwards messages to ROS 2 subscribers).
        self.taps: list[Callable[[Topic, Outgoing, Peer | None], None]] = []
        #: Called by :meth:`flush`: what a tap holds back to send together, sent now.
        self.flushers: list[Callable[[], None]] = []
        #: When the message being delivered arrived (monotonic seconds): the in-process
        #: subscribers that time commands read it (the ``/cmd_vel`` watchdog).
        self.now = 0.0

    # -- declaration ----------------------------------------------------------------------------

    def check_type(self, name: str, type_name: str) -> str:
        """Return the canonical spelling of ``type_name`` if topic ``name`` may have that type.

        Raises:
            ProtocolError: the type string is malformed, or the topic has another type
                (rosbridge's TypeConflictException).
        """
        topic = self.topics.get(name)
        return _canonical(type_name, None if topic is None else topic)

    def _typed(self, topic: Topic, type_name: str) -> None:
        """Fix or check the type of ``topic``."""
        canonical = _canonical(type_name, topic)
        if topic.type is None:
            self.changes += 1
            topic.type = canonical
            topic.known = self.registry.known(canonical)

    def advertise(
        self,
        name: str,
        type_name: str,
        owner: object,
        op_id: OpId | None = None,
        *,
        latch: bool = False,
    ) -> Topic:
        """Register ``owner`` (a node name or a Peer) as a publisher of ``name``.

        Raises:
            ProtocolError: the type string is malformed or conflicts with the topic's type.
        """
        topic = self.topics.get(name) or Topic(name)
        self._typed(topic, type_name)  # raises before anything is registered
        self.topics[name] = topic
        self.changes += 1
        topic.publishers.setdefault(owner, set()).add(op_id)
        topic.latch = topic.latch or latch
        return topic

    def unadvertise(self, name: str, owner: object, op_id: OpId | None = None) -> None:
        """Remove one advertise id of ``owner`` (``None``: all of them)."""
        topic = self.topics.get(name)
        if topic is None or owner not in topic.publishers:
            return
        self.changes += 1
        ids = topic.publishers[owner]
        if op_id is None:
            ids.clear()
        else:
            ids.discard(op_id)
        if not ids:
            del topic.publishers[owner]
            if not topic.publishers:
                self.unlatch(topic)
        self._forget_if_unused(topic)

    def latch(self, topic: Topic) -> None:
        """Keep the last message of ``topic`` for later subscribers from now on."""
        if not topic.latch:
            topic.latch = True
            self.changes += 1  # the Zenoh link subscribes to latched topics apart

    def unlatch(self, topic: Topic) -> None:
        """Drop the latched message of ``topic`` (and give its bytes back to its publisher)."""
        if topic.latched_by is not None:
            topic.latched_by.session.unlatch(topic.name)
            topic.latched_by = None
        topic.latched = None

    def subscribed(self, peer: Peer, sub: Subscription, type_name: str | None) -> Topic:
        """Deliver topic ``sub.resolved`` to ``peer`` as its session's subscription ``sub``.

        ``type_name`` (canonical, admitted) fixes the topic's type if nothing did yet.
        """
        topic = self.topics.get(sub.resolved) or Topic(sub.resolved)
        if type_name:
            self._typed(topic, type_name)
        self.topics[sub.resolved] = topic
        topic.subscriptions[(peer, sub.topic)] = sub
        self.generation += 1  # the options may have changed: plans are rebuilt
        self.changes += 1
        return topic

    def unsubscribed(self, peer: Peer, sub: Subscription, gone: bool) -> None:
        """A subscribe id of ``sub`` went; ``gone``: ``peer`` no longer receives the topic."""
        self.generation += 1
        self.changes += 1
        if not gone:
            return
        topic = self.topics.get(sub.resolved)
        if topic is not None:
            topic.subscriptions.pop((peer, sub.topic), None)
            topic.plan = None  # holds the peer: drop it now, not at the next publish
            self._forget_if_unused(topic)

    def subscribe_internal(
        self, name: str, type_name: str, node: str, callback: InternalCallback
    ) -> Topic:
        """Add an in-process subscriber (a simulated node) of ``name``."""
        topic = self.topics.get(name) or Topic(name)
        self._typed(topic, type_name)
        self.topics[name] = topic
        self.changes += 1
        topic.internal.append((node, callback))
        return topic

    def unsubscribe_internal(self, name: str, callback: InternalCallback) -> None:
        """Remove an in-process subscriber added by :meth:`subscribe_internal`."""
        topic = self.topics.get(name)
        if topic is None:
            return
        self.changes += 1
        # by equality: a bound method is a new object each time it is read
        topic.internal = [(n, cb) for n, cb in topic.internal if cb != callback]
        self._forget_if_unused(topic)

    def unlatched(self, peer: Peer, name: str) -> None:
        """Drop the latched message ``peer`` left on topic ``name``, if it is still there."""
        topic = self.topics.get(name)
        if topic is not None and topic.latched_by is peer:
            self.unlatch(topic)  # its message goes with it: the bytes were its budget

    def _forget_if_unused(self, topic: Topic) -> None:
        if topic.unused() and self.topics.get(topic.name) is topic:
            del self.topics[topic.name]

    # -- publishing -------------------------------------------------------------------------------

    def outgoing(self, topic: Topic, msg: Any, stamp: tuple[int, int]) -> Outgoing:
        """Wrap a canonical message of ``topic`` for delivery."""
        cdr = None
        if topic.known and topic.type is not None and self.cdr_factory is not None:
            cdr = self.cdr_factory(topic.type, msg)
        return Outgoing(topic.name, topic.type if topic.known else None, msg, stamp, cdr)

    def convert(self, topic: Topic, payload: Any) -> Any:
        """Validate a payload for ``topic`` (see :meth:`validate`; the topic must be typed)."""
        assert topic.type is not None
        return self.validate(topic.type, topic.known, payload)

    def validate(self, type_name: str, known: bool, payload: Any) -> Any:
        """Return a client payload of canonical type ``type_name`` as a canonical message.

        A ``known`` type is validated and completed with defaults; any other type passes
        through, if it is a JSON object.

        Raises:
            ConversionError: the payload does not fit the type.
            ProtocolError: the payload of an unknown type is not a JSON object.
        """
        if known:
            return self.converter.from_json(type_name, payload)
        if not isinstance(payload, dict):
            msg = f"publish: msg must be a JSON object, got {type(payload).__name__}"
            raise ProtocolError(msg)
        return payload

    def flush(self) -> None:
        """Send what the taps hold back (a publisher that has more to compute says so)."""
        for flush in self.flushers:
            flush()

    def deliver(self, topic: Topic, out: Outgoing, now: float, source: Peer | None) -> None:
        """Send ``out`` to every subscriber of ``topic`` and run the in-process callbacks.

        Raises:
            ProtocolError: an in-process subscriber refused the message (after every client
                subscriber got it); the caller reports it to ``source``.
        """
        self.now = now
        for tap in self.taps:
            tap(topic, out, source)
        if topic.latch:
            if topic.latched_by is not None and topic.latched_by is not source:
                topic.latched_by.session.unlatch(topic.name)
            topic.latched = out
            topic.latched_by = source
        if topic.subscriptions:
            default_limit = self.default_queue_length
            if self.send_many is not None:
                self._deliver_many(topic, out, now, default_limit, self.send_many)
            else:
                for (peer, _written), sub in topic.subscriptions.items():
                    if sub.throttle_rate and not sub.admit(now):
                        continue
                    self.send_to(peer, sub, out, default_limit)
        refusal: ProtocolError | None = None
        for _node, callback in topic.internal:
            try:
                callback(out.msg, source)
            except ProtocolError as err:
                refusal = err
        if refusal is not None:
            try:
                raise refusal
            finally:
                refusal = None  # no cycle through this frame: it holds the message

    def _deliver_many(
        self,
        topic: Topic,
        out: Outgoing,
        now: float,
        default_limit: int,
        send_many: Callable[[Frame, SendEntries], None],
    ) -> None:
        """Deliver ``out`` along the topic's plan: one ``send_many`` per shared frame.

        Frames are cached per (compression, topic spelling), so most subscribers share one;
        throttled and fragmented subscriptions and encoding errors take the one-by-one path.
        """
        plan = topic.plan
        if plan is None or plan.version != (self.generation, Session.epoch):
            plan = topic.plan = self._plan(topic, default_limit)
        for peer, sub in plan.one_by_one:
            if sub.throttle_rate and not sub.admit(now):
                continue
            self.send_to(peer, sub, out, default_limit)
        for compression, spelling, entries in plan.groups:
            try:
                frame = out.frame(compression, spelling)
            except ProtocolError:
                for peer, key, _limit in entries:
                    self.send_to(peer, cast(Subscription, key), out, default_limit)
                continue
            send_many(frame, entries)

    def _plan(self, topic: Topic, default_limit: int) -> _Plan:
        groups: dict[tuple[str, str], SendEntries] = {}
        one_by_one: list[tuple[Peer, Subscription]] = []
        for (peer, _written), sub in topic.subscriptions.items():
            fragmented = sub.fragment_size is not None or peer.session.fragment_size is not None
            if sub.throttle_rate or fragmented:
                one_by_one.append((peer, sub))
                continue
            entries = groups.setdefault((sub.compression, sub.topic), [])
            entries.append((peer, sub, sub.queue_length or default_limit))
        return _Plan(
            (self.generation, Session.epoch),
            [(c, t, entries) for (c, t), entries in groups.items()],
            one_by_one,
        )

    def send_to(self, peer: Peer, sub: Subscription, out: Outgoing, default_limit: int) -> None:
        """Encode ``out`` as ``sub`` wants it (cached) and queue it for ``peer``."""
        try:
            frame = out.frame(sub.compression, sub.topic)
        except ProtocolError as err:
            if sub.first_warning():  # once per subscription, not once per message
                for reply in peer.session.status("error", f"subscribe {sub.topic}: {err}"):
                    peer.send(reply.frame)
            return
        size = sub.fragment_size or peer.session.fragment_size
        limit = sub.queue_length or default_limit
        if size is not None and frame.text and len(frame.data) > size:
            frag_id = f"{sub.topic}:{out.stamp[0]}.{out.stamp[1]:09d}"
            for piece in split_frame(frame, size, frag_id):
                peer.send(piece, sub, 0)
            return
        peer.send(frame, sub, limit)

    def replay_latched(self, peer: Peer, topic: Topic, sub: Subscription) -> None:
        """Send the latched message of ``topic`` to a new subscription."""
        if topic.latched is not None:
            self.send_to(peer, sub, topic.latched, self.default_queue_length)

    def listed(self) -> list[Topic]:
        """Return the topics that exist in the graph (typed), sorted by name."""
        return sorted((t for t in self.topics.values() if t.type is not None), key=lambda t: t.name)


def _canonical(type_name: str, topic: Topic | None) -> str:
    """Return the canonical spelling of ``type_name``, which ``topic`` (if typed) must have.

    Raises:
        ProtocolError: the type string is malformed or conflicts with the topic's type.
    """
    if topic is not None and type_name == topic.type:
        return type_name  # canonical already: what admitted ops and in-process users give
    try:
        canonical = normalize_type(type_name)
    except TypeNotFoundError as err:
        raise ProtocolError(str(err)) from None
    if topic is not None and topic.type is not None and topic.type != canonical:
        msg = (
            f"Tried to register topic {topic.name} with type {canonical} "
            f"but it is already established with type {topic.type}"
        )
        raise ProtocolError(msg)
    return canonical
