"""What every ROS 2 link (Zenoh, DDS) keeps on the event loop's side of the graph.

A link's transport library runs callbacks on threads of its own; everything else happens on the
event loop, in the same shape for every transport:

* :class:`Inbox`: the samples those threads hand to the event loop, bounded in samples
  (:data:`INBOX_LIMIT`) and bytes, handed to the graph :data:`DRAIN_BATCH` samples and
  :data:`DRAIN_BYTES` bytes per event-loop callback at most, what is dropped counted;
* :class:`Logbook`: one rate-limited warning per problem (also on ``/rosout``: a rosbridge
  client sees why a topic stays silent), and notes said once;
* :class:`Refusals`: the ROS 2 peers' role (``--ros2-role``) per name, cached;
* :class:`Imports`: the remote publishers, in the graph as owners of their topics;
* :class:`StandIns`: the remote subscriptions, in the graph as in-process subscribers that do
  nothing (the simulation publishes what only ROS 2 listens to, rosapi lists them);
* :func:`local_owner`, :func:`outward_topics`, :func:`outward_services`: which local node an
  owner in the graph stands for, and the graph's topics and services a link mirrors outward
  (a node of another process, a :class:`ForeignNode`, is never mirrored back).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from typing import TYPE_CHECKING, Any, TypeVar

from simbridge.errors import SimbridgeError
from simbridge.graph import BRIDGE_NODE, Graph, Topic
from simbridge.graph.access import Access


if TYPE_CHECKING:
    from simbridge.graph.services import Service


__all__ = [
    "DRAIN_BATCH",
    "DRAIN_BYTES",
    "INBOX_LIMIT",
    "LOG_EVERY",
    "SHARED_TOPICS",
    "ForeignNode",
    "Imports",
    "Inbox",
    "Logbook",
    "Refusals",
    "Ros2Peer",
    "StandIns",
    "Take",
    "graph_signature",
    "local_owner",
    "local_publisher",
    "outward_services",
    "outward_topics",
]

#: Seconds between two log lines about the same problem.
LOG_EVERY = 30.0
#: Topics that many processes publish at once (every other name has one owner).
SHARED_TOPICS = frozenset({"/tf", "/tf_static", "/rosout", "/parameter_events"})
#: Samples waiting for the event loop at most; their bytes are bounded too (the link's
#: ``*_inbox_bytes`` setting).
INBOX_LIMIT = 20_000
#: Samples handed to the graph per event-loop callback at most, and their bytes at most (a
#: sample bigger than that goes alone): 500 samples of 4 MB in one callback had stalled the
#: loop 1.5-1.8 s (issue 29).
DRAIN_BATCH = 500
DRAIN_BYTES = 1_000_000
#: Names whose refusal is kept at most (then the cache starts again: names come from the
#: graph's topics and the remote endpoints, both bounded, so a clear is rare).
REFUSALS_KEPT = 100_000

#: A transport's node of another process.
NodeT = TypeVar("NodeT", bound="ForeignNode")
#: Who takes a sample on the event loop: ``take(name, payload)``.
Take = Callable[[str, bytes], None]


class ForeignNode(str):
    """A node of another process, as the owner of a topic's publisher or subscription here.

    It reads as the node's name (rosapi lists it so) but is never equal to a local node of the
    same name, nor to a node of that name in a third process or on another transport.
    """

    #: Which process it is in: a Zenoh session id, a DDS participant's GUID.
    origin: str

    def __new__(cls, name: str, origin: str) -> ForeignNode:
        """Make the owner for node ``name`` of the process ``origin``."""
        node = super().__new__(cls, name)
        node.origin = origin
        return node

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and str.__eq__(self, other) and self.origin == other.origin

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    def __hash__(self) -> int:
        return hash((type(self).__name__, str(self), self.origin))


class Ros2Peer:
    """A peer of the graph that stands for ROS 2 processes (a caller, a remote provider).

    What such a peer owns in the graph came from ROS 2: a link never mirrors it outward.
    """

    __slots__ = ()


def local_owner(owner: object) -> str | None:
    """Return the local node an owner in the graph stands for; None for another process's.

    An in-process node is its name; a rosbridge client (or any other front end's peer) is
    :data:`~simbridge.graph.BRIDGE_NODE`, as rosbridge_suite's node; a node of another process
    (:class:`ForeignNode`) and the ROS 2 links' own peers (:class:`Ros2Peer`) are not local.
    """
    if type(owner) is str:
        return owner
    if isinstance(owner, ForeignNode | Ros2Peer):
        return None
    return BRIDGE_NODE


def local_publisher(topic: Topic | None, *, clients: bool = True) -> str | None:
    """Return the first local node publishing ``topic``, if any.

    ``clients``: whether a rosbridge client counts (as :data:`~simbridge.graph.BRIDGE_NODE`).
    """
    if topic is None:
        return None
    for owner in topic.publishers:
        if type(owner) is str:
            return owner
        if clients and local_owner(owner) is not None:
            return BRIDGE_NODE
    return None


def outward_topics(
    graph: Graph, markers: Collection[int]
) -> Iterator[tuple[Topic, list[str], list[str]]]:
    """Yield each topic of a known type with its local publishers and subscribers.

    Publishers in the order they came, a rosbridge client as
    :data:`~simbridge.graph.BRIDGE_NODE`; subscribers: the in-process nodes (but the link's own
    stand-ins for remote subscriptions, whose callbacks' ids are in ``markers``), then
    :data:`~simbridge.graph.BRIDGE_NODE` if a rosbridge client subscribes.
    """
    for topic in graph.topics.topics.values():
        if topic.type is None or not topic.known:
            continue
        publishers = [n for n in map(local_owner, topic.publishers) if n is not None]
        subscribers = [
            node
            for node, callback in topic.internal
            if type(node) is str and id(callback) not in markers
        ]
        if topic.sinks:
            subscribers.append(BRIDGE_NODE)
        yield topic, publishers, subscribers


def graph_signature(graph: Graph) -> int:
    """A number that changes with what a link mirrors: topics, services, actions, nodes.

    Cheap (no walk over topics or clients): every client's subscribe and advertise, every
    in-process publisher and subscriber, every service goes through the graph's tables,
    which count their changes; services and actions removed outside them change a length.
    """
    return hash(
        (
            graph.topics.changes,
            len(graph.topics.topics),
            graph.services.changes,
            len(graph.services.services),
            len(graph.actions.actions),
            len(graph.nodes),
        )
    )


def outward_services(graph: Graph) -> Iterator[tuple[Service, str]]:
    """Yield each service of a known type provided here, with the node that provides it.

    An in-process handler's node, or :data:`~simbridge.graph.BRIDGE_NODE` for a service a
    rosbridge client advertises; not the services of ROS 2 processes (:class:`Ros2Peer`).
    """
    registry = graph.registry
    for service in graph.services.services.values():
        if isinstance(service.provider, Ros2Peer) or service.type not in registry.services:
            continue
        yield service, (service.node if service.handler is not None else BRIDGE_NODE)


class Logbook:
    """A link's warnings, each at most once per :data:`LOG_EVERY` seconds per key."""

    def __init__(
        self, graph: Graph, label: str, source: str, stats: Counter[str], logger: logging.Logger
    ) -> None:
        self.graph = graph
        #: ``DDS`` or ``Zenoh``: how the link's log lines begin.
        self.label = label
        #: The logger name of the warnings on ``/rosout`` (``simbridge.dds``...).
        self.source = source
        self.stats = stats
        self.logger = logger
        #: When each key was last said (monotonic seconds).
        self.logged: dict[str, float] = {}

    def warn(self, key: str, text: str) -> None:
        """Log a warning (and put it on ``/rosout``) unless ``key`` was said lately."""
        now = time.monotonic()
        if now - self.logged.get(key, -LOG_EVERY) >= LOG_EVERY:
            self.logged[key] = now
            self.graph.log("warn", text, name=self.source)

    def note(self, key: str, text: str) -> None:
        """Count a name clash; log it once (at INFO: classrooms have them by design)."""
        self.stats["name_clashes"] += 1
        if key not in self.logged:
            self.logged[key] = time.monotonic()
            self.logger.info("%s", text)


class Refusals:
    """Why the ROS 2 peers may not publish on (or provide) a name, kept per name.

    The admission's scope rule for the ROS 2 peers' role (:func:`simbridge.ros2.role.ros2_access`):
    samples of a refused name are dropped, remote publishers and services under it are not
    brought into the graph.
    """

    def __init__(self, graph: Graph, access: Access, logbook: Logbook) -> None:
        self.graph = graph
        #: Who the ROS 2 peers are for the graph's rules.
        self.access = access
        self.logbook = logbook
        #: name -> why not (None: allowed). Read directly on the way of every sample.
        self.cache: dict[str, str | None] = {}

    def refusal(self, name: str) -> str | None:
        """Return why ROS 2 peers may not publish on ``name``; None if they may."""
        try:
            return self.cache[name]
        except KeyError:
            pass
        if len(self.cache) >= REFUSALS_KEPT:
            self.cache.clear()
        text = self.graph.access.publish_refusal(self.access, name)
        self.cache[name] = text
        return text

    def refused(self, name: str, what: str, *, count: bool = True) -> bool:
        """Whether ROS 2 may not bring ``name`` in; log (rate-limited) and count a refusal."""
        text = self.refusal(name)
        if text is None:
            return False
        if count:
            self.logbook.stats["refused"] += 1
        self.logbook.warn(
            f"refused {name}",
            f"{self.logbook.label}: {what} {text} (ROS 2 peers' role; --ros2-role)",
        )
        return True


class Inbox:
    """Samples from a transport library's threads, waiting for the event loop.

    Bounded in samples (:data:`INBOX_LIMIT`) and bytes (``max_bytes``); one wake-up of the
    loop per burst; :meth:`drain` hands them over a bounded batch per callback, so that under a
    flood the loop's other work (clients, the tick) runs between two batches. What is dropped
    is counted in ``stats``; a sample over ``max_sample`` is reported too (rate-limited).
    """

    def __init__(
        self,
        logbook: Logbook,
        *,
        max_bytes: int,
        max_sample: int,
        dropped: str,
        oversized: str,
        setting: str,
    ) -> None:
        self.logbook = logbook
        self.stats = logbook.stats
        #: Bytes held at most, and one sample's at most.
        self.max_bytes = max_bytes
        self.max_sample = max_sample
        #: The counters of samples dropped for room and for size.
        self.dropped = dropped
        self.oversized_key = oversized
        #: The settings' prefix (``zenoh``, ``dds``) for the log lines.
        self.setting = setting
        #: (who takes it, topic, bytes), their bytes, whether the loop was woken; under
        #: :attr:`lock` (several of the library's threads hand samples over; a link may guard
        #: its other queues with it too).
        self.samples: deque[tuple[Take, str, bytes]] = deque()
        self.bytes = 0
        self.lock = threading.Lock()
        self._rung = False
        #: The event loop (None before the start and after the close: nothing is handed over).
        self.loop: asyncio.AbstractEventLoop | None = None
        #: The last oversized sample's topic and size, and whether its report is scheduled.
        self._oversized: tuple[str, int] | None = None
        self._oversized_rung = False

    def put(self, take: Take, name: str, data: bytes) -> None:
        """Queue one sample (any thread); past the bounds, the oldest go (counted)."""
        size = len(data)
        samples = self.samples
        with self.lock:
            while samples and (len(samples) >= INBOX_LIMIT or self.bytes + size > self.max_bytes):
                self.bytes -= len(samples.popleft()[2])
                self.stats[self.dropped] += 1
            samples.append((take, name, data))
            self.bytes += size
            ring = not self._rung
            self._rung = True
        if ring:
            self._ring()

    def put_many(self, take: Take, name: str, batch: Iterable[bytes]) -> None:
        """Queue samples taken at once (any thread); past the bounds, new ones go (counted)."""
        samples = self.samples
        with self.lock:
            for data in batch:
                size = len(data)
                if size > self.max_sample:
                    self.oversized(name, size)
                    continue
                if len(samples) >= INBOX_LIMIT or self.bytes + size > self.max_bytes:
                    self.stats[self.dropped] += 1
                    continue
                samples.append((take, name, data))
                self.bytes += size
            ring = bool(samples) and not self._rung
            if ring:
                self._rung = True
        if ring:
            self._ring()

    def _ring(self) -> None:
        loop = self.loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self.drain)

    def drain(self) -> None:
        """Hand the samples that arrived to their takers (the event loop).

        Only those already there, at most :data:`DRAIN_BATCH` of them and :data:`DRAIN_BYTES`
        bytes; the rest in the next callback.
        """
        samples = self.samples
        budget = DRAIN_BYTES
        for _ in range(DRAIN_BATCH):
            with self.lock:
                if not samples:
                    break
                take, name, payload = samples.popleft()
                self.bytes -= len(payload)
            take(name, payload)
            budget -= len(payload)
            if budget <= 0:
                break
        with self.lock:
            loop = self.loop
            again = bool(samples) and loop is not None
            self._rung = again
        if again:
            loop.call_soon(self.drain)  # type: ignore[union-attr]

    def oversized(self, name: str, size: int) -> None:
        """Count a sample over ``max_sample``; have the loop report it (any thread)."""
        self.stats[self.oversized_key] += 1
        self._oversized = (name, size)
        loop = self.loop
        if not self._oversized_rung and loop is not None:
            self._oversized_rung = True
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._report_oversized)

    def _report_oversized(self) -> None:
        self._oversized_rung = False
        if self._oversized is not None:
            name, size = self._oversized
            self.logbook.warn(
                "oversized",
                f"{self.logbook.label}: a sample of {size} "
                f"bytes on {name} dropped: over {self.setting}_max_sample_bytes "
                f"({self.max_sample}); {self.stats[self.oversized_key]} dropped so far",
            )


class StandIns:
    """Remote subscriptions, in the graph as in-process subscribers that do nothing.

    So that the simulation publishes what only ROS 2 listens to (the link's delivery tap sends
    it out) and rosapi lists them under their nodes; the outward walk leaves them out
    (:attr:`ids`).
    """

    def __init__(self, graph: Graph, logbook: Logbook) -> None:
        self.graph = graph
        self.logbook = logbook
        #: topic -> remote node -> its stand-in's callback.
        self.by_topic: dict[str, dict[ForeignNode, Callable[[Any, Any], None]]] = {}
        #: The stand-ins' callbacks' ids.
        self.ids: set[int] = set()

    def update(self, name: str, subs: Mapping[NodeT, str]) -> None:
        """Make the graph hold exactly these remote subscriptions of ``name`` (node -> type).

        One of a type the registry does not know is left out; one the graph refuses (another
        type on that name) is counted and said (``name_clashes``).
        """
        topics = self.graph.topics
        markers = self.by_topic.get(name, {})
        for owner in [o for o in markers if o not in subs]:
            callback = markers.pop(owner)
            self.ids.discard(id(callback))
            topics.unsubscribe_internal(name, callback)
        for owner, type_name in subs.items():
            if owner in markers or not self.graph.registry.known(type_name):
                continue

            def marker(msg: Any, source: Any) -> None:
                """A ROS 2 subscription: the message goes out through the delivery tap."""

            try:
                topics.subscribe_internal(name, type_name, owner, marker)
            except SimbridgeError as err:
                self.logbook.warn(
                    f"clash {name}", f"{self.logbook.label}: {name} of {owner} not bridged: {err}"
                )
                self.logbook.stats["name_clashes"] += 1
                continue
            markers = self.by_topic.setdefault(name, markers)
            markers[owner] = marker
            self.ids.add(id(marker))
        if not markers:
            self.by_topic.pop(name, None)


class Imports:
    """Remote publishers, in the graph as owners of their topics (rosapi lists them).

    Not those the ROS 2 peers' role may not publish (:class:`Refusals`); one of a type the
    registry does not know is listed without being bridged (``unknown_types``); one of a name
    a local node publishes already (but :data:`SHARED_TOPICS`) goes to ``clash``.
    """

    def __init__(
        self,
        graph: Graph,
        refusals: Refusals,
        clash: Callable[[str, ForeignNode, str], None],
        *,
        clients_clash: bool,
    ) -> None:
        self.graph = graph
        self.refusals = refusals
        self.logbook = refusals.logbook
        #: Says (and counts) that ``(name, node, local)``: ``local`` publishes ``name`` here.
        self.clash = clash
        #: Whether a rosbridge client publishing a name keeps remote publishers of it out.
        self.clients_clash = clients_clash
        #: topic -> remote node -> its type.
        self.by_topic: dict[str, dict[ForeignNode, str]] = {}

    def update(self, name: str, pubs: Mapping[NodeT, tuple[str, bool]]) -> None:
        """Make the graph hold exactly these remote publishers of ``name``.

        ``pubs``: remote node -> (type, latched).
        """
        topics = self.graph.topics
        logbook = self.logbook
        label = logbook.label
        if pubs and self.refusals.refused(name, f"{next(iter(pubs))}:", count=False):
            pubs = {}  # the ROS 2 peers' role may not publish it here
        imported = self.by_topic.get(name, {})
        for owner in [o for o in imported if o not in pubs]:
            del imported[owner]
            topics.unadvertise(name, owner, None)
        for owner, (type_name, latched) in pubs.items():
            if owner in imported:
                continue
            if not self.graph.registry.known(type_name):
                logbook.warn(
                    f"type {type_name}",
                    f"{label}: {name} from {owner} has type {type_name}, unknown here: listed, "
                    "its messages are not bridged",
                )
                logbook.stats["unknown_types"] += 1
                if "/" not in type_name:
                    continue  # not even a ROS type name: not listed
            local = local_publisher(topics.topics.get(name), clients=self.clients_clash)
            if local is not None and name not in SHARED_TOPICS:
                self.clash(name, owner, local)
                continue
            try:
                topics.advertise(name, type_name, owner, latch=latched)
            except SimbridgeError as err:
                logbook.warn(f"clash {name}", f"{label}: {name} from {owner} not bridged: {err}")
                logbook.stats["name_clashes"] += 1
                continue
            imported = self.by_topic.setdefault(name, imported)
            imported[owner] = type_name
        if not imported:
            self.by_topic.pop(name, None)
