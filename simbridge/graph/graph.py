"""The ROS-graph facade: what clients see of simbridge, whatever simulates behind it.

:class:`Graph` receives every client frame, turns it into ops (via the client's
:class:`~simbridge.protocol.Session`) and carries them out on its topic and service tables. A
bad op is answered with a ``status`` error to its sender only (when the sender's ``set_level``
allows it) and logged at debug level; it never touches other clients or the simulation.

The graph is sans-I/O: the server hands it frames and a monotonic ``now``; it hands frames
back to peers through :meth:`Peer.send`. ``tick(now)`` expires what waits on time.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable
from typing import Any

from simbridge.config import ServerSettings
from simbridge.errors import ProtocolError, SimbridgeError, TypeNotFoundError
from simbridge.graph.actions import ActionTable
from simbridge.graph.params import ParameterStore
from simbridge.graph.services import Handler, ServiceTable, service_response, typed_calls
from simbridge.graph.topics import BRIDGE_NODE, InternalCallback, Peer, Topic, TopicTable
from simbridge.msgs import Converter, TypeRegistry, normalize_type
from simbridge.msgs.cdr import CdrWriter
from simbridge.protocol import ClientId, Op, Session, ops as o, resolve_name, status_frame


__all__ = ["ROSOUT", "Graph"]

logger = logging.getLogger(__name__)

ROSOUT = "/rosout"
_LOG_LEVELS = {"debug": 10, "info": 20, "warn": 30, "error": 40, "fatal": 50}
OpHandler = Callable[[Peer, Any, float], None]


class Graph:
    """Topics, services and clients of one simbridge process."""

    def __init__(
        self,
        registry: TypeRegistry | None = None,
        settings: ServerSettings | None = None,
        *,
        wall_clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        #: Server settings (limits, timeouts).
        self.settings = settings or ServerSettings()
        #: Interface definitions.
        self.registry = registry or TypeRegistry()
        #: Wall clock for header stamps (nanoseconds since the epoch).
        self.wall_clock_ns = wall_clock_ns
        #: Validation of client payloads.
        self.converter = Converter(self.registry, self.stamp)
        #: Topics.
        self.topics = TopicTable(
            self.registry,
            self.converter,
            default_queue_length=self.settings.default_queue_length,
        )
        self.topics.cdr_factory = CdrWriter(self.registry).factory  # cbor-raw
        #: Services.
        self.services = ServiceTable(default_timeout=self.settings.service_timeout)
        self.services.prepare, self.services.finish = typed_calls(self.registry, self.converter)
        #: Parameters of the in-process nodes.
        self.params = ParameterStore()
        #: Connected clients.
        self.peers: set[Peer] = set()
        #: Nodes simulated in process: name -> description (for rosapi).
        self.nodes: dict[str, str] = {BRIDGE_NODE: "the rosbridge server"}
        #: Op handlers by op class; extensions may replace or add entries.
        self.handlers: dict[type, OpHandler] = {
            o.Advertise: self._advertise,
            o.Unadvertise: self._unadvertise,
            o.Publish: self._publish,
            o.Subscribe: self._subscribe,
            o.Unsubscribe: self._unsubscribe,
            o.CallService: self._call_service,
            o.AdvertiseService: self._advertise_service,
            o.UnadvertiseService: self._unadvertise_service,
            o.ServiceResponse: self._service_response,
            o.SetLevel: self._set_level,
        }
        #: Called with each peer that leaves, after the graph cleaned up (extensions).
        self.on_disconnect: list[Callable[[Peer], None]] = []
        #: Called with each peer that connects, before its first op (extensions).
        self.on_connect: list[Callable[[Peer], None]] = []
        #: Checks run before every op: ``(peer, op, now) -> carry it out?``. A gate that says
        #: no has answered the client itself; one that raises SimbridgeError is reported.
        self.gates: list[Callable[[Peer, Op, float], bool]] = []
        #: Services that need admin rights (see :mod:`simbridge.graph.guard`).
        self.admin_services: set[str] = set()
        #: Actions (client-served and in-process) and the goals in flight.
        self.actions = ActionTable(self)
        self.handlers.update(self.actions.handlers())
        self.on_disconnect.append(self.actions.drop_peer)
        self._ids = itertools.count(1)
        self.topics.advertise(ROSOUT, "rcl_interfaces/msg/Log", "/simbridge")
        self.nodes["/simbridge"] = "simbridge itself (/rosout)"

    # -- clients ------------------------------------------------------------------------------

    def new_session(self) -> Session:
        """Return a fresh session for a connecting client."""
        return Session(ClientId(next(self._ids)), max_message_size=self.settings.max_message_size)

    def add_peer(self, peer: Peer) -> None:
        """Register a connected client."""
        self.peers.add(peer)
        for callback in self.on_connect:
            callback(peer)

    def remove_peer(self, peer: Peer) -> None:
        """Forget a client and everything it owned (subscriptions, publishers, services)."""
        self.peers.discard(peer)
        # each part runs whatever failed before it: stop-on-disconnect must never be skipped
        for callback in (self.topics.drop_peer, self.services.drop_peer, *self.on_disconnect):
            try:
                callback(peer)
            except Exception:
                logger.exception("%s: cleanup after disconnect failed in %r", peer.label, callback)

    def receive(self, peer: Peer, data: str | bytes, now: float) -> None:
        """Handle one frame from ``peer``: every op in it, in order."""
        for item in peer.session.parse(data, now):
            if isinstance(item, ProtocolError):
                self.reject(peer, str(item), None)
            else:
                self.dispatch(peer, item, now)

    def dispatch(self, peer: Peer, op: Op, now: float) -> None:
        """Carry out one op; a :class:`SimbridgeError` becomes a ``status`` to the sender."""
        handler = self.handlers.get(type(op))
        try:
            for gate in self.gates:
                if not gate(peer, op, now):
                    return
            if handler is None:
                name = type(op).__name__
                msg = f"operation {name} is not supported by this server yet"
                raise ProtocolError(msg)
            handler(peer, op, now)
        except SimbridgeError as err:
            self.reject(peer, str(err), getattr(op, "id", None))

    def reject(self, peer: Peer, text: str, op_id: object) -> None:
        """Tell ``peer`` (only) that its op failed, as a ``status`` error."""
        logger.debug("%s: %s", peer.label, text)
        if peer.session.wants_status("error"):
            peer.send(status_frame("error", text, op_id))

    def tick(self, now: float) -> None:
        """Expire what waits on time (service calls)."""
        if self.services.pending:
            self.services.expire(now)

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

    def publish(self, topic: Topic, msg: Any, now: float) -> None:
        """Publish a canonical message from in process (no validation: the caller is trusted)."""
        self.topics.deliver(topic, self.topics.outgoing(topic, msg, self.stamp()), now, None)

    def log(self, level: str, text: str, *, name: str = "simbridge", echo: bool = True) -> None:
        """Log a notable event to ``/rosout`` (rcl_interfaces/Log) and to the Python log.

        ``echo=False`` logs it at debug level in Python (a per-message log such as the tutorial
        listener's must not flood the server log).
        """
        number = _LOG_LEVELS.get(level, 20)
        logger.log(number if echo else logging.DEBUG, "%s", text)
        topic = self.topics.topics.get(ROSOUT)
        if topic is None or not topic.subscriptions:
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
        self.topics.deliver(topic, self.topics.outgoing(topic, msg, (sec, nanosec)), 0.0, None)

    # -- op handlers ------------------------------------------------------------------------

    def _advertise(self, peer: Peer, op: o.Advertise, now: float) -> None:
        name = resolve_name(op.topic)
        topic = self.topics.advertise(name, op.type, peer, op.id, latch=op.latch)
        peer.session.advertisements.setdefault(name, {})[op.id] = topic.type or op.type

    def _unadvertise(self, peer: Peer, op: o.Unadvertise, now: float) -> None:
        name = resolve_name(op.topic)
        ads = peer.session.advertisements.get(name)
        if ads is None:
            return
        if op.id is None or op.id not in ads:
            ads.clear()
            self.topics.unadvertise(name, peer, None)
        else:
            del ads[op.id]
            self.topics.unadvertise(name, peer, op.id)
        if not ads:
            del peer.session.advertisements[name]

    def _publish(self, peer: Peer, op: o.Publish, now: float) -> None:
        name = resolve_name(op.topic)
        topic = self.topics.topics.get(name)
        if op.type is not None or topic is None or topic.type is None:
            if op.type is None:
                msg = (
                    f"publish: cannot infer the type of topic {name}: it is not advertised; "
                    "advertise it first or give a type"
                )
                raise ProtocolError(msg)
            topic = self.topics.advertise(name, op.type, peer, None)
            peer.session.advertisements.setdefault(name, {}).setdefault(None, op.type)
        elif name not in peer.session.advertisements:
            # rosbridge registers a publishing client as a publisher implicitly
            self.topics.advertise(name, topic.type, peer, None)
            peer.session.advertisements[name] = {None: topic.type}
        if op.latch:
            topic.latch = True
        msg = self.topics.convert(topic, op.msg)
        out = self.topics.outgoing(topic, msg, self.stamp())
        self.topics.deliver(topic, out, now, peer)

    def _subscribe(self, peer: Peer, op: o.Subscribe, now: float) -> None:
        name = resolve_name(op.topic)
        if op.fragment_size is not None:
            peer.session.fragment_size = op.fragment_size
        had = op.topic in peer.session.subscriptions
        topic, sub = self.topics.subscribe(peer, op, name)
        if not had:
            self.topics.replay_latched(peer, topic, sub)

    def _unsubscribe(self, peer: Peer, op: o.Unsubscribe, now: float) -> None:
        self.topics.unsubscribe(peer, op.topic, op.id)

    def _call_service(self, peer: Peer, op: o.CallService, now: float) -> None:
        if op.fragment_size is not None:
            peer.session.fragment_size = op.fragment_size
        try:
            name = resolve_name(op.service, "service")
        except ProtocolError as err:
            peer.send(service_response(op.service, str(err), result=False, op_id=op.id))
            return
        self.services.call(peer, op, name, now)

    def _advertise_service(self, peer: Peer, op: o.AdvertiseService, now: float) -> None:
        name = resolve_name(op.service, "service")
        try:
            type_name = normalize_type(op.type, "srv")
        except TypeNotFoundError as err:
            raise ProtocolError(f"advertise_service: {err}") from None
        self.services.advertise(peer, name, type_name, op.service)

    def _unadvertise_service(self, peer: Peer, op: o.UnadvertiseService, now: float) -> None:
        name = resolve_name(op.service, "service")
        if not self.services.unadvertise(peer, name):
            msg = f"unadvertise_service: service {name} is not advertised by this client"
            raise ProtocolError(msg)

    def _service_response(self, peer: Peer, op: o.ServiceResponse, now: float) -> None:
        error = self.services.respond(peer, op)
        if error is not None:
            raise ProtocolError(error)

    def _set_level(self, peer: Peer, op: o.SetLevel, now: float) -> None:
        peer.session.set_level(op.level)
