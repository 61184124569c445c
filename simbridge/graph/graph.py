"""The ROS-graph facade: what clients see of simbridge, whatever simulates behind it.

:class:`Graph` receives every client frame, turns it into ops (via the client's
:class:`~simbridge.protocol.Session`), lets its :class:`~simbridge.graph.admission.Admission`
decide whether each is allowed, and carries them out on its topic, service and action tables. A
bad op is answered with a ``status`` error to its sender only (when the sender's ``set_level``
allows it) and logged at debug level; it never touches other clients or the simulation.

The graph is sans-I/O: the server hands it frames and a monotonic ``now``; it hands frames
back to peers through :meth:`Peer.send`. ``tick(now)`` expires what waits on time.

A ``/cmd_vel`` from a page, in a straight line (each step once):

1. **socket**: the server's connection handler reads the frame (message rate and work share
   of :mod:`simbridge.server`) and calls :meth:`Graph.receive`;
2. **session**: :meth:`Session.parse <simbridge.protocol.Session.parse>` decodes it into a
   typed ``Publish`` op, its topic name resolved once (``cmd_vel`` -> ``/cmd_vel``);
3. **admission**: :meth:`Admission.admit <simbridge.graph.admission.Admission.admit>` decides
   once (authenticated, publish rate, scope, type, payload) and returns a
   :class:`~simbridge.graph.admission.Publication`: the topic, its type and the validated
   message;
4. **graph**: :meth:`Graph._publish` registers the client as a publisher the first time (its
   session counts it against its budgets) and :meth:`TopicTable.deliver
   <simbridge.graph.topics.TopicTable.deliver>` hands the message, wrapped once, to the
   subscribers: encoded frames to clients, the message to in-process nodes;
5. **robot**: the robot's subscriber (:class:`~simbridge.graph.bridge.RobotBridge`) sets the
   command of its robot in the world (``World.command``); a command it refuses (not finite,
   absurd) comes back to the sender as a ``status`` error.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable
from typing import Any

from simbridge.config import ServerSettings
from simbridge.errors import ProtocolError, SimbridgeError
from simbridge.graph.actions import ActionTable
from simbridge.graph.admission import Admission, Publication
from simbridge.graph.params import ParameterStore
from simbridge.graph.services import Handler, ServiceTable, service_response, typed_calls
from simbridge.graph.topics import BRIDGE_NODE, InternalCallback, Peer, Topic, TopicTable
from simbridge.msgs import Converter, TypeRegistry, normalize_type
from simbridge.msgs.cdr import CdrWriter
from simbridge.protocol import (
    ClientId,
    Limits,
    Op,
    Pool,
    Refusal,
    Session,
    ops as o,
    status_frame,
)


__all__ = ["ROSOUT", "Graph", "budgets"]

logger = logging.getLogger(__name__)

ROSOUT = "/rosout"
_LOG_LEVELS = {"debug": 10, "info": 20, "warn": 30, "error": 40, "fatal": 50}
OpHandler = Callable[[Peer, Any, float], None]


def budgets(settings: ServerSettings) -> tuple[Limits, Pool]:
    """Return the per-client limits and the shared pool that ``settings`` ask for."""
    s = settings
    limits = Limits(
        subscriptions=s.max_subscriptions,
        subscribe_ids=s.max_subscribe_ids,
        ids_per_subscription=s.max_ids_per_subscription,
        advertisements=s.max_advertisements,
        advertise_ids=s.max_advertise_ids,
        pending_calls=s.max_pending_calls,
        call_timeout=s.max_call_timeout,
        fragment_sets=s.max_fragment_sets,
        fragment_bytes=s.max_message_size,
        frame_values=s.max_frame_values,
        frame_bytes=min(s.max_frame_bytes, s.max_message_size),
        latched_bytes=s.max_latched_bytes,
        publish_rate=s.publish_rate,
        publish_burst=s.publish_burst,
        statuses_per_second=s.statuses_per_second,
        work_share=s.client_work_share,
    )
    pool = Pool(
        {
            "subscribe_ids": s.global_subscribe_ids,
            "advertise_ids": s.global_advertise_ids,
            "pending_calls": s.global_pending_calls,
            "fragment_bytes": s.global_fragment_bytes,
            "latched_bytes": s.global_latched_bytes,
        }
    )
    return limits, pool


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
        #: What each client may hold and do, and what all of them together may hold.
        self.limits, self.pool = budgets(self.settings)
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
        #: Actions (client-served and in-process) and the goals in flight.
        self.actions = ActionTable(self)
        #: Decides whether each op of a client is carried out (the guard sets its access rules).
        self.admission = Admission(self.topics, self.services, self.actions)
        #: Services that need admin rights (see :mod:`simbridge.graph.guard`).
        self.admin_services = self.admission.admin_services
        self.handlers.update(self.actions.handlers())
        self.on_disconnect.append(self.actions.drop_peer)
        self._ids = itertools.count(1)
        self.topics.advertise(ROSOUT, "rcl_interfaces/msg/Log", "/simbridge")
        self.nodes["/simbridge"] = "simbridge itself (/rosout)"

    # -- clients ------------------------------------------------------------------------------

    def new_session(self) -> Session:
        """Return a fresh session for a connecting client (its budgets from the settings)."""
        return Session(ClientId(next(self._ids)), limits=self.limits, pool=self.pool)

    def add_peer(self, peer: Peer) -> None:
        """Register a connected client."""
        self.peers.add(peer)
        for callback in self.on_connect:
            callback(peer)

    def remove_peer(self, peer: Peer) -> None:
        """Forget a client and everything it owned (subscriptions, publishers, services).

        Every callback runs, whatever an earlier one raised; the session's budgets are given
        back last.
        """
        self.peers.discard(peer)
        # each part runs whatever failed before it: stop-on-disconnect must never be skipped
        for callback in (self.topics.drop_peer, self.services.drop_peer, *self.on_disconnect):
            try:
                callback(peer)
            except Exception:
                logger.exception("%s: cleanup after disconnect failed in %r", peer.label, callback)
        peer.session.close()

    def receive(self, peer: Peer, data: str | bytes, now: float) -> None:
        """Handle one frame from ``peer``: every op in it, in order.

        The straight line of every op: the client's session parses it (names resolved,
        strings checked, nothing but ``auth`` before the client is admitted), the admission
        decides whether it is allowed, its handler carries it out on the graph.
        """
        for item in peer.session.parse(data, now):
            if isinstance(item, ProtocolError):
                self.refuse(peer, item, now)
            else:
                self.dispatch(peer, item, now)

    def dispatch(self, peer: Peer, op: Op, now: float) -> None:
        """Admit one op and carry it out; a :class:`SimbridgeError` becomes an answer to the sender.

        The handler receives what :meth:`Admission.admit
        <simbridge.graph.admission.Admission.admit>` returns: the op, or for a ``publish`` its
        :class:`~simbridge.graph.admission.Publication`.
        """
        handler = self.handlers.get(type(op))
        try:
            admitted = self.admission.admit(peer, op, now)
            if admitted is None:
                return
            if handler is None:
                name = type(op).__name__
                msg = f"operation {name} is not supported by this server yet"
                raise ProtocolError(msg)
            handler(peer, admitted, now)
        except Refusal as err:
            self.refuse(peer, err, now, op)
        except SimbridgeError as err:
            self.refuse(peer, Refusal(str(err), op_id=getattr(op, "id", None)), now, op)

    def refuse(self, peer: Peer, err: ProtocolError, now: float, op: Op | None = None) -> None:
        """Answer ``peer`` (only) that an op was refused, in the shape its op needs.

        A call (``call_service``, ``send_action_goal``) always gets its failed answer: its
        caller waits for one. Anything else gets a ``status`` error within the client's status
        budget (:meth:`Session.may_tell`).
        """
        if isinstance(op, o.CallService):
            kind, target, op_id = "call_service", op.service, op.id
        elif isinstance(op, o.SendActionGoal):
            kind, target, op_id = "send_action_goal", op.action, op.id
        elif isinstance(err, Refusal):
            kind, target, op_id = err.op, err.target, err.op_id
        else:
            kind, target, op_id = "", "", None
        text = str(err)
        logger.debug("%s: %s", peer.label, text)
        if kind == "call_service":
            self.services.reply(peer, service_response(target, text, result=False, op_id=op_id))
            return
        if kind == "send_action_goal":
            self.actions.fail(peer, target, op_id, text)
            return
        cause = err.cause if isinstance(err, Refusal) else text[:120]
        if op is not None:
            # one text for two kinds of op is two causes: a page that subscribed with the wrong
            # type still hears why its advertise is refused (it waits for that id's answer)
            cause = f"{type(op).__name__}: {cause}"
        if peer.session.wants_status("error") and peer.session.may_tell(cause, now):
            peer.send(status_frame("error", text, op_id))

    def reject(self, peer: Peer, text: str, op_id: object) -> None:
        """Tell ``peer`` (only) that its op failed, as a ``status`` error (not budgeted)."""
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
        fresh = peer.session.advertise(op.name, op.id, op.type)
        try:
            topic = self.topics.advertise(op.name, op.type, peer, op.id, latch=op.latch)
        except ProtocolError:
            if fresh:
                peer.session.unadvertise(op.name, op.id)
            raise
        peer.session.advertisements[op.name][op.id] = topic.type or op.type

    def _unadvertise(self, peer: Peer, op: o.Unadvertise, now: float) -> None:
        ads = peer.session.advertisements.get(op.name)
        if ads is None:
            return
        one = op.id if op.id is not None and op.id in ads else None
        peer.session.unadvertise(op.name, one)
        self.topics.unadvertise(op.name, peer, one)

    def _publish(self, peer: Peer, admitted: Publication, now: float) -> None:
        op, topic, session = admitted.op, admitted.topic, peer.session
        name = op.name
        if (
            topic is None
            or op.type is not None
            or topic.type is None
            or name not in session.advertisements
        ):
            # rosbridge registers a publishing client as a publisher implicitly
            session.advertise(name, None, admitted.type)
            topic = self.topics.advertise(name, admitted.type, peer, None)
        out = self.topics.outgoing(topic, admitted.msg, self.stamp())
        if op.latch or topic.latch:
            session.latch(name, len(out.json_body()))  # what later subscribers will cost
            topic.latch = True
        self.topics.deliver(topic, out, now, peer)

    def _subscribe(self, peer: Peer, op: o.Subscribe, now: float) -> None:
        if op.fragment_size is not None:
            peer.session.fragment_size = op.fragment_size
        topic, sub, new = self.topics.subscribe(peer, op)
        if new:
            self.topics.replay_latched(peer, topic, sub)

    def _unsubscribe(self, peer: Peer, op: o.Unsubscribe, now: float) -> None:
        self.topics.unsubscribe(peer, op.topic, op.id)

    def _call_service(self, peer: Peer, op: o.CallService, now: float) -> None:
        if op.fragment_size is not None:
            peer.session.fragment_size = op.fragment_size
        self.services.call(peer, op, op.name, now)

    def _advertise_service(self, peer: Peer, op: o.AdvertiseService, now: float) -> None:
        type_name = normalize_type(op.type, "srv")  # admitted: well formed
        self.services.advertise(peer, op.name, type_name, op.service)

    def _unadvertise_service(self, peer: Peer, op: o.UnadvertiseService, now: float) -> None:
        if not self.services.unadvertise(peer, op.name):
            msg = f"unadvertise_service: service {op.name} is not advertised by this client"
            raise ProtocolError(msg)

    def _service_response(self, peer: Peer, op: o.ServiceResponse, now: float) -> None:
        error = self.services.respond(peer, op)
        if error is not None:
            raise ProtocolError(error)

    def _set_level(self, peer: Peer, op: o.SetLevel, now: float) -> None:
        peer.session.set_level(op.level)
