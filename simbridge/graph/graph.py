"""The robot's ROS graph: what every front end's peers see of simbridge, whatever simulates.

:class:`Graph` holds the topic, service, action and parameter tables, the in-process nodes and
the connected peers of every front end, and the access rules those peers are admitted by
(:attr:`Graph.access`). The in-process API (:meth:`Graph.advertise`, :meth:`Graph.subscribe`,
:meth:`Graph.publish`, :meth:`Graph.add_service`, :meth:`Graph.log`) is what the robot's nodes
and the front ends use. A front end translates its own wire to these calls and back: rosbridge
(:mod:`simbridge.rosbridge.front`), ROS 2 over Zenoh (:mod:`simbridge.ros2.zenoh`), Foxglove.

The graph is sans-I/O: it is handed a monotonic ``now``; ``tick(now)`` expires what waits on
time.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from simbridge.graph.access import AccessRules
from simbridge.graph.actions import ActionTable
from simbridge.graph.params import ParameterStore
from simbridge.graph.services import Handler, ServiceTable
from simbridge.graph.topics import BRIDGE_NODE, InternalCallback, Peer, Topic, TopicTable
from simbridge.msgs import Converter, TypeRegistry


if TYPE_CHECKING:
    from simbridge.msgs.cdr import CdrWriter


__all__ = ["ROSOUT", "Graph", "PeerWatcher"]

logger = logging.getLogger(__name__)

ROSOUT = "/rosout"
_LOG_LEVELS = {"debug": 10, "info": 20, "warn": 30, "error": 40, "fatal": 50}


class PeerWatcher:
    """A part that hears of the peers of every front end; it overrides what it needs.

    The application's builder hands each such part to :meth:`Graph.watch`, in one place (no
    part adds itself to the graph from its constructor); a test that makes one part alone
    does the same.
    """

    def peer_connected(self, peer: Peer) -> None:
        """``peer`` connected; called before its first request."""

    def peer_lost(self, peer: Peer) -> None:
        """``peer`` went without closing its connection; called before :meth:`peer_left`."""

    def peer_left(self, peer: Peer) -> None:
        """``peer`` left (closed or lost), after the graph released what it held."""


class Graph:
    """Topics, services, actions, parameters and peers of one simbridge process."""

    def __init__(
        self,
        registry: TypeRegistry | None = None,
        *,
        service_timeout: float = 5.0,
        max_parameter_names: int = 1_000,
        wall_clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        """Make an empty graph.

        Args:
            registry: the interface definitions (default: the built-in ones).
            service_timeout: seconds a call waits for a peer's provider when it gives none
                (the server's ``service_timeout``).
            max_parameter_names: names in one request to the parameter services (the server's
                ``max_parameter_names``).
            wall_clock_ns: the wall clock for header stamps (nanoseconds since the epoch).
        """
        #: Names in one request to the parameter services at most.
        self.max_parameter_names = max_parameter_names
        #: Interface definitions.
        self.registry = registry or TypeRegistry()
        #: Wall clock for header stamps (nanoseconds since the epoch).
        self.wall_clock_ns = wall_clock_ns
        #: Validation of client payloads.
        self.converter = Converter(self.registry, self.stamp)
        #: Topics.
        self.topics = TopicTable(self.registry, self.converter)
        self.topics.cdr_factory = self._cdr  # cbor-raw
        self._cdr_writer: CdrWriter | None = None
        #: Services.
        self.services = ServiceTable(default_timeout=service_timeout)
        #: Parameters of the in-process nodes.
        self.params = ParameterStore()
        #: Connected clients.
        self.peers: set[Peer] = set()
        #: Nodes simulated in process: name -> description (for rosapi).
        self.nodes: dict[str, str] = {BRIDGE_NODE: "the rosbridge server"}
        #: Called with each peer that leaves, after the graph cleaned up (:meth:`watch`).
        self.on_disconnect: list[Callable[[Peer], None]] = []
        #: Called before :attr:`on_disconnect` with each peer lost without closing its
        #: connection (killed, crashed, unreachable; see :meth:`remove_peer`).
        self.on_lost: list[Callable[[Peer], None]] = []
        #: Called with each peer that connects, before its first op (:meth:`watch`).
        self.on_connect: list[Callable[[Peer], None]] = []
        #: Actions (client-served and in-process) and the goals in flight.
        self.actions = ActionTable(self)
        #: The access rules of every front end's peers (the guard turns them on).
        self.access = AccessRules()
        self.on_disconnect.append(self.actions.drop_peer)
        self._peer_ids = itertools.count(1)
        self.topics.advertise(ROSOUT, "rcl_interfaces/msg/Log", "/simbridge")
        self.nodes["/simbridge"] = "simbridge itself (/rosout)"

    # -- clients ------------------------------------------------------------------------------

    def watch(self, *parts: PeerWatcher) -> None:
        """Tell ``parts`` of every peer that connects, is lost or leaves, in this order.

        Only what a part overrides of :class:`PeerWatcher` is called. The application's
        builder is what calls this (:func:`simbridge.robot.assembly.build_robot_graph`, the
        guard in :mod:`simbridge.app.build`).
        """
        base = PeerWatcher
        for part in parts:
            kind = type(part)
            if kind.peer_connected is not base.peer_connected:
                self.on_connect.append(part.peer_connected)
            if kind.peer_lost is not base.peer_lost:
                self.on_lost.append(part.peer_lost)
            if kind.peer_left is not base.peer_left:
                self.on_disconnect.append(part.peer_left)

    def next_peer_id(self) -> int:
        """Return a number no other peer of any front end has (``Access.peer_id``)."""
        return next(self._peer_ids)

    def add_peer(self, peer: Peer) -> None:
        """Register a connected peer of a front end (the guard gives it its access)."""
        self.peers.add(peer)
        for callback in self.on_connect:
            callback(peer)

    def remove_peer(self, peer: Peer, *, lost: bool = False) -> None:
        """Forget a peer: its pending calls, then what the nodes do when a peer leaves.

        Its front end released what it held first. Every callback runs, whatever an earlier
        one raised. ``lost``: the peer went without closing its connection itself (a killed
        browser or script, a crash, a peer the keepalive or the server dropped);
        :attr:`on_lost` runs too.
        """
        self.peers.discard(peer)
        callbacks: list[Callable[[Peer], None]] = [self.services.drop_peer]
        callbacks += [*(self.on_lost if lost else []), *self.on_disconnect]
        # each part runs whatever failed before it: stop-on-disconnect must never be skipped
        for callback in callbacks:
            try:
                callback(peer)
            except Exception:
                logger.exception("%s: cleanup after disconnect failed in %r", peer.label, callback)

    def tick(self, now: float) -> None:
        """Expire what waits on time (service calls, goals to client-served actions)."""
        if self.services.pending:
            self.services.expire(now)
        if self.actions.deadlines:
            self.actions.expire(now)

    # -- in-process API (the simulated nodes) ---------------------------------------------

    def stamp(self) -> tuple[int, int]:
        """Return the current wall-clock time as (sec, nanosec): header stamps."""
        return divmod(self.wall_clock_ns(), 1_000_000_000)

    def advertise(self, name: str, type_name: str, node: str, *, latch: bool = False) -> Topic:
        """Declare an in-process publisher of ``name``."""
        self.nodes.setdefault(node, "")
        return self.topics.advertise(name, type_name, node, latch=latch)

    def subscribe(self, name: str, type_name: str, node: str, callback: InternalCallback) -> Topic:
        """Declare an in-process subscriber of ``name``."""
        self.nodes.setdefault(node, "")
        return self.topics.subscribe_internal(name, type_name, node, callback)

    def add_service(self, name: str, type_name: str, node: str, handler: Handler) -> None:
        """Declare an in-process service."""
        self.nodes.setdefault(node, "")
        self.services.add(name, type_name, node, handler)

    def _cdr(self, type_name: str, msg: Any) -> Callable[[], bytes]:
        """Return a function computing the CDR bytes of ``msg`` when first needed (then kept).

        Every consumer of one message (``cbor-raw`` subscribers) shares the one serialization.
        The writer (:mod:`simbridge.msgs.cdr`, its codec compiled per type) is made by the first
        message a consumer asks for: a run without one does not import it (issue 16: 0.3 MB).
        """
        kept: list[bytes] = []

        def cdr() -> bytes:
            if not kept:
                writer = self._cdr_writer
                if writer is None:
                    from simbridge.msgs.cdr import CdrWriter

                    writer = self._cdr_writer = CdrWriter(self.registry)
                kept.append(writer.serialize(type_name, msg))
            return kept[0]

        return cdr

    def publish(self, topic: Topic, msg: Any, now: float) -> None:
        """Publish a canonical message from in process (no validation: the caller is trusted)."""
        self.topics.deliver(topic, self.topics.outgoing(topic, msg, self.stamp()), now, None)

    def log(self, level: str, text: str, *, name: str = "simbridge", echo: bool = True) -> None:
        """Log a notable event to ``/rosout`` (rcl_interfaces/Log) and to the Python log.

        ``echo=False`` logs it at debug level in Python (a per-message log such as the tutorial
        listener's must not flood the server log). The message is an ordinary delivery of the
        topic: rosbridge clients, in-process subscribers and what stands for the other front
        ends' subscribers (a Foxglove channel's, a ROS 2 node's over Zenoh) all receive it, and
        the delivery taps see it. It is built only while one of them listens.
        """
        number = _LOG_LEVELS.get(level, 20)
        logger.log(number if echo else logging.DEBUG, "%s", text)
        topic = self.topics.topics.get(ROSOUT)
        if topic is None or not topic.wanted():
            return
        sec, nanosec = self.stamp()
        msg = {
            "stamp": {"sec": sec, "nanosec": nanosec},
            "level": number,
            "name": name,
            "msg": text,
            "file": "",
            "function": "",
            "line": 0,
        }
        # the time of the delivery under way, if any (a log from inside a callback): the
        # in-process subscribers that time commands read it
        now = self.topics.now
        self.topics.deliver(topic, self.topics.outgoing(topic, msg, (sec, nanosec)), now, None)
