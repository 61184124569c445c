"""Topics of the ROS graph: publishers, subscribers, latched messages and delivery.

A topic's type is fixed by its first publisher or typed subscriber; a later advertise or
subscribe with another type is refused (rosbridge's TypeConflictException), comparing the
canonical ``pkg/msg/Type`` spelling. A subscription to a topic that does not exist yet waits for
it, with or without a type (rosbridge instead drops an untyped one, #1142).

Each front end is one subscriber of a topic its peers subscribe to (a :class:`Sink`: rosbridge's
:class:`~simbridge.rosbridge.subscribers.TopicSubscribers`), beside the in-process subscribers
(the robot's nodes). A message is wrapped once (:class:`~simbridge.msgs.message.Outgoing`) and
handed to each; what a front end encodes of it is made once per encoding, in the message.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

from simbridge.errors import ProtocolError, TypeNotFoundError
from simbridge.graph.access import Access
from simbridge.msgs import Converter, TypeRegistry, normalize_type
from simbridge.msgs.message import Outgoing


__all__ = [
    "BRIDGE_NODE",
    "DEFAULT_TOPIC_QOS",
    "LATCHED_TOPIC_QOS",
    "InternalCallback",
    "Peer",
    "Sink",
    "Topic",
    "TopicQos",
    "TopicTable",
]

logger = logging.getLogger(__name__)

#: The node that client-owned publishers, subscribers and services belong to (as in rosbridge).
BRIDGE_NODE = "/rosbridge_websocket"


class Peer(Protocol):
    """A peer of a front end (a rosbridge client, a ROS 2 node), as the graph sees it.

    Who it is, and a label for logs: what reaches it goes through its own front end.
    """

    #: A short label for logs ("client 3 127.0.0.1:50412").
    label: str

    @property
    def access(self) -> Access:
        """Who the peer is for the graph's rules (scope, admin rights, token)."""


#: An in-process subscriber: ``(message, sending peer or None) -> None``; may raise
#: :class:`ProtocolError` to refuse a message, which is reported to the sending client.
InternalCallback = Callable[[Any, "Peer | None"], None]


class Sink(Protocol):
    """A front end's subscribers of one topic: the graph hands it each message once."""

    def __len__(self) -> int:
        """Return how many subscriptions it holds (a sink without any is removed)."""

    def peers(self) -> Iterable[Peer]:
        """Return the peers subscribed through it."""

    def deliver(
        self,
        topic: Topic,
        out: Outgoing,
        now: float,
        source: Peer | None,
        only: Collection[Peer] | None = None,
    ) -> None:
        """Send ``out`` to its subscribers (``only``: to those of these peers alone)."""


@dataclass(frozen=True, slots=True)
class TopicQos:
    """How a topic's messages are offered: what the ROS 2 front ends declare on their wire.

    A publisher offers reliable delivery (a reliable writer serves reliable and best-effort
    readers alike); a latched topic keeps its last message for late joiners (transient local,
    keep last 1: rclcpp's ``transient_local()``, as ``/tf_static`` and ``/map``), any other
    keeps the last 10 (ROS 2's default profile, rmw ``qos_profiles.h``).
    """

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10


#: ROS 2's default profile: reliable, volatile, keep last 10.
DEFAULT_TOPIC_QOS = TopicQos()
#: A latched topic: reliable, transient local, keep last 1.
LATCHED_TOPIC_QOS = TopicQos(transient_local=True, depth=1)


@dataclass(eq=False, slots=True)
class Topic:
    """One topic of the graph."""

    name: str
    #: Canonical type, or ``None`` while only untyped subscribers wait for the topic.
    type: str | None = None
    #: The type is known to the registry (payloads are validated and defaults filled).
    known: bool = False
    #: Publishers: owner (a node name or a Peer) -> advertise ids.
    publishers: dict[object, set[Hashable]] = field(default_factory=dict)
    #: The front ends' subscribers, by front end (a sink without subscribers is removed).
    sinks: dict[object, Sink] = field(default_factory=dict)
    #: In-process subscribers: (node name, callback).
    internal: list[tuple[str, InternalCallback]] = field(default_factory=list)
    #: Keep the last message for late subscribers (``latch: true``, /tf_static).
    latch: bool = False
    #: The last message, when latched.
    latched: Outgoing | None = None
    #: The peer whose message is latched, if any, and what gives its cost back when it goes.
    latched_by: Peer | None = None
    latched_release: Callable[[], None] | None = None

    @property
    def qos(self) -> TopicQos:
        """How the topic is offered (latched: transient local, depth 1; else the default)."""
        return LATCHED_TOPIC_QOS if self.latch else DEFAULT_TOPIC_QOS

    def unused(self) -> bool:
        """Return whether nothing refers to the topic any more."""
        return not (self.publishers or self.sinks or self.internal)

    def wanted(self) -> bool:
        """Return whether anyone subscribes: a front end's peer or an in-process node."""
        return bool(self.sinks or self.internal)


class TopicTable:
    """Every topic, with the rules for advertising, subscribing and publishing."""

    def __init__(self, registry: TypeRegistry, converter: Converter) -> None:
        #: Interface definitions.
        self.registry = registry
        #: JSON payload validation.
        self.converter = converter
        #: Topics by absolute name.
        self.topics: dict[str, Topic] = {}
        #: Makes the CDR-bytes function of a message (set by the graph: made once, on first use).
        self.cdr_factory: Callable[[str, Any], Callable[[], bytes]] | None = None
        #: Bumped by every change of a topic's type, publishers or subscribers (front ends and
        #: in-process): what mirrors the table elsewhere (the Zenoh and DDS links) compares it
        #: instead of walking every topic.
        self.changes = 0
        #: Called with ``(topic, message, sending peer or None)`` before each delivery
        #: (the ROS 2 and Foxglove front ends forward messages to their subscribers).
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
        op_id: Hashable | None = None,
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

    def unadvertise(self, name: str, owner: object, op_id: Hashable | None = None) -> None:
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
        """Drop the latched message of ``topic`` (and give its cost back to its publisher)."""
        release = topic.latched_release
        topic.latched = topic.latched_by = topic.latched_release = None
        if release is not None:
            release()

    def take(self, name: str, type_name: str | None = None) -> Topic:
        """Return topic ``name``, made if it does not exist; ``type_name`` fixes its type.

        Raises:
            ProtocolError: the type string is malformed or conflicts with the topic's type.
        """
        topic = self.topics.get(name) or Topic(name)
        if type_name:
            self._typed(topic, type_name)
        self.topics[name] = topic
        return topic

    def add_sink(self, topic: Topic, key: object, sink: Sink) -> None:
        """Make ``sink`` the subscribers of front end ``key`` on ``topic`` (kept or replaced)."""
        topic.sinks[key] = sink
        self.topics[topic.name] = topic
        self.changes += 1

    def remove_sink(self, topic: Topic, key: object) -> None:
        """Remove front end ``key``'s subscribers from ``topic`` (it has none left)."""
        if topic.sinks.pop(key, None) is not None:
            self.changes += 1
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

    def deliver(
        self,
        topic: Topic,
        out: Outgoing,
        now: float,
        source: Peer | None,
        *,
        release: Callable[[], None] | None = None,
    ) -> None:
        """Hand ``out`` to every subscriber of ``topic``: taps, front ends, in-process nodes.

        ``release``: what gives the publisher's cost of a latched message back when it goes
        (another message replaces it, or its publisher leaves).

        Raises:
            ProtocolError: an in-process subscriber refused the message (after every front end
                got it); the caller reports it to ``source``.
        """
        self.now = now
        for tap in self.taps:
            tap(topic, out, source)
        if topic.latch:
            old = topic.latched_release
            if old is not None and topic.latched_by is not source:
                old()
            topic.latched, topic.latched_by, topic.latched_release = out, source, release
        for sink in topic.sinks.values():
            sink.deliver(topic, out, now, source)
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

    def deliver_to(self, topic: Topic, out: Outgoing, now: float, peers: Collection[Peer]) -> None:
        """Hand ``out`` to the subscriptions of ``peers`` on ``topic`` only (nothing latched)."""
        for sink in topic.sinks.values():
            sink.deliver(topic, out, now, None, peers)

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
