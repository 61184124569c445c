"""The ROS-graph facade: what clients see of simbridge, whatever simulates behind it.

:class:`Graph` receives every client frame, turns it into ops (via the client's
:class:`~simbridge.rosbridge.Session`), lets its :class:`~simbridge.graph.admission.Admission`
decide whether each is allowed, hands each allowed op to the client's session (ops in, effects
out: the session updates what the client holds and says what the graph must do), and carries out
the effects on its topic, service and action tables (:meth:`Graph.apply`). A bad op is answered
with a ``status`` error to its sender only (when the sender's ``set_level`` allows it) and logged
at debug level; it never touches other clients or the simulation.

The graph is sans-I/O: the server hands it frames and a monotonic ``now``; it hands frames
back to peers through :meth:`Peer.send`. ``tick(now)`` expires what waits on time.

A ``/cmd_vel`` from a page, in a straight line (each step once):

1. **socket**: the server's connection handler reads the frame (message rate and work share
   of :mod:`simbridge.rosbridge.server`) and calls :meth:`Graph.receive`;
2. **session**: :meth:`Session.parse <simbridge.rosbridge.Session.parse>` decodes it into a
   typed ``Publish`` op, its topic name resolved once (``cmd_vel`` -> ``/cmd_vel``);
3. **admission**: :meth:`Admission.admit <simbridge.graph.admission.Admission.admit>` decides
   once (authenticated, publish rate, scope, type, payload) and returns a
   :class:`~simbridge.graph.admission.Publication`: the topic, its type and the validated
   message;
4. **session, then graph**: :meth:`Graph._publish` hands the publication to the client's session
   (:meth:`Session.publish <simbridge.rosbridge.Session.publish>`: the first time, an
   ``Advertised`` effect, counted against its budgets; after that, nothing) and carries out
   what it returns; :meth:`TopicTable.deliver <simbridge.graph.topics.TopicTable.deliver>`
   hands the message, wrapped once, to the subscribers: encoded frames to clients, the message
   to in-process nodes;
5. **robot**: the robot's subscriber (:class:`~simbridge.robot.bridge.RobotBridge`) sets the
   command of its robot in the world (``World.command``); a command it refuses (not finite,
   absurd) comes back to the sender as a ``status`` error.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from simbridge.app.settings import ServerSettings, budgets
from simbridge.errors import ProtocolError, SimbridgeError
from simbridge.graph.actions import ActionTable
from simbridge.graph.admission import (
    Admission,
    Call,
    GoalRequest,
    GoalUpdate,
    Publication,
    Response,
    Typed,
)
from simbridge.graph.params import ParameterStore
from simbridge.graph.services import Handler, ServiceTable, service_response, typed_calls
from simbridge.graph.topics import BRIDGE_NODE, InternalCallback, Peer, Topic, TopicTable
from simbridge.msgs import Converter, TypeRegistry
from simbridge.rosbridge import (
    Advertised,
    ClientId,
    Effect,
    Op,
    Provided,
    Refusal,
    Reply,
    Session,
    Subscribed,
    Unadvertised,
    Unlatched,
    Unsubscribed,
    Withdrawn,
    ops as o,
)


if TYPE_CHECKING:
    from simbridge.msgs.cdr import CdrWriter


__all__ = ["ROSOUT", "Graph"]

logger = logging.getLogger(__name__)

ROSOUT = "/rosout"
_LOG_LEVELS = {"debug": 10, "info": 20, "warn": 30, "error": 40, "fatal": 50}
OpHandler = Callable[[Peer, Any, float], None]
EffectHandler = Callable[[Peer, Any], None]


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
        self.topics.cdr_factory = self._cdr  # cbor-raw
        self._cdr_writer: CdrWriter | None = None
        #: Services.
        self.services = ServiceTable(default_timeout=self.settings.service_timeout)
        prepare, finish = typed_calls(self.registry, self.converter)
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
            o.AdvertiseAction: self._advertise_action,
            o.UnadvertiseAction: self._unadvertise_action,
            o.SendActionGoal: self._send_action_goal,
            o.ActionFeedback: self._action_feedback,
            o.ActionResult: self._action_result,
            o.SetLevel: self._set_level,
        }
        #: How each effect of a session is carried out (see :meth:`apply`).
        self.effects: dict[type, EffectHandler] = {
            Reply: lambda peer, e: peer.send(e.frame),
            Subscribed: self._subscribed,
            Unsubscribed: lambda peer, e: self.topics.unsubscribed(peer, e.sub, e.gone),
            Advertised: self._advertised,
            Unadvertised: lambda peer, e: self.topics.unadvertise(e.name, peer, e.op_id),
            Unlatched: lambda peer, e: self.topics.unlatched(peer, e.name),
            Provided: self._provided,
            Withdrawn: self._withdrawn,
        }
        #: Called with each peer that leaves, after the graph cleaned up (extensions).
        self.on_disconnect: list[Callable[[Peer], None]] = []
        #: Called before :attr:`on_disconnect` with each peer lost without closing its
        #: connection (killed, crashed, unreachable; see :meth:`remove_peer`).
        self.on_lost: list[Callable[[Peer], None]] = []
        #: Called with each peer that connects, before its first op (extensions).
        self.on_connect: list[Callable[[Peer], None]] = []
        #: Actions (client-served and in-process) and the goals in flight.
        self.actions = ActionTable(self)
        #: Decides whether each op of a client is carried out (the guard sets its access rules).
        self.admission = Admission(
            self.topics, self.services, self.actions, prepare=prepare, finish=finish
        )
        #: Services that need admin rights (see :mod:`simbridge.graph.guard`).
        self.admin_services = self.admission.admin_services
        self.handlers.update(self.actions.handlers())
        self.on_disconnect.append(self.actions.drop_peer)
        self._ids = itertools.count(1)
        self.topics.advertise(ROSOUT, "rcl_interfaces/msg/Log", "/simbridge")
        self.nodes["/simbridge"] = "simbridge itself (/rosout)"

    # -- clients ------------------------------------------------------------------------------

    def new_session(self, token: str | None = None) -> Session:
        """Return a fresh session for a connecting client (its budgets from the settings).

        ``token``: the one it connected with (``?token=``), if any.
        """
        return Session(ClientId(next(self._ids)), limits=self.limits, pool=self.pool, token=token)

    def add_peer(self, peer: Peer) -> None:
        """Register a connected client."""
        self.peers.add(peer)
        for callback in self.on_connect:
            callback(peer)

    def remove_peer(self, peer: Peer, *, lost: bool = False) -> None:
        """Forget a client and everything it owned (subscriptions, publishers, services).

        Its session gives back its budgets and says what it held (effects, carried out here);
        every callback runs, whatever an earlier one raised. ``lost``: the client went without
        closing its connection itself (a killed browser or script, a crash, a peer the
        keepalive or the server dropped); :attr:`on_lost` runs too.
        """
        self.peers.discard(peer)
        callbacks: list[Callable[[Peer], None]] = [self._release, self.services.drop_peer]
        callbacks += [*(self.on_lost if lost else []), *self.on_disconnect]
        # each part runs whatever failed before it: stop-on-disconnect must never be skipped
        for callback in callbacks:
            try:
                callback(peer)
            except Exception:
                logger.exception("%s: cleanup after disconnect failed in %r", peer.label, callback)

    def _release(self, peer: Peer) -> None:
        for effect in peer.session.close():
            try:
                self.effects[type(effect)](peer, effect)
            except Exception:
                logger.exception("%s: cleanup after disconnect failed for %r", peer.label, effect)

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
        <simbridge.graph.admission.Admission.admit>` returns (the op, or what was decided for
        it: a ``Publication``, a ``Typed`` op, a ``Call``, a ``GoalRequest``), hands it to the
        client's session and carries out the effects.
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
        replies = peer.session.refused(text, cause, now, op_id)
        if replies:  # most refusals of a flood are counted, not told: no call for them
            self.apply(peer, replies)

    def reject(self, peer: Peer, text: str, op_id: Any) -> None:
        """Tell ``peer`` (only) that its op failed, as a ``status`` error (not budgeted)."""
        logger.debug("%s: %s", peer.label, text)
        self.apply(peer, peer.session.status("error", text, op_id))

    def apply(self, peer: Peer, effects: Iterable[Effect]) -> None:
        """Carry out the effects a session returned for its client ``peer``, in order."""
        handlers = self.effects
        for effect in effects:
            handlers[type(effect)](peer, effect)

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
        if topic is None or not (topic.subscriptions or topic.internal):
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

    # -- op handlers ------------------------------------------------------------------------

    def _advertise(self, peer: Peer, admitted: Typed, now: float) -> None:
        assert admitted.type is not None  # admitted: the canonical type
        self.apply(peer, peer.session.advertise(admitted.op, admitted.type))

    def _unadvertise(self, peer: Peer, op: o.Unadvertise, now: float) -> None:
        self.apply(peer, peer.session.unadvertise(op))

    def _publish(self, peer: Peer, admitted: Publication, now: float) -> None:
        op = admitted.op
        name = op.name
        effects = peer.session.publish(name, admitted.type)
        if effects:
            self.apply(peer, effects)  # the first publish: the client becomes a publisher
        topic = admitted.topic
        if topic is None or topic.type is None:
            topic = self.topics.topics.get(name) or self.topics.advertise(
                name, admitted.type, peer, None
            )
        out = self.topics.outgoing(topic, admitted.msg, self.stamp())
        if op.latch or topic.latch:
            peer.session.latch(name, len(out.json_body()))  # what later subscribers will cost
            self.topics.latch(topic)
        self.topics.deliver(topic, out, now, peer)

    def _subscribe(self, peer: Peer, admitted: Typed, now: float) -> None:
        self.apply(peer, peer.session.subscribe(admitted.op, admitted.type))

    def _unsubscribe(self, peer: Peer, op: o.Unsubscribe, now: float) -> None:
        self.apply(peer, peer.session.unsubscribe(op))

    def _call_service(self, peer: Peer, call: Call, now: float) -> None:
        service = call.service
        deadline = peer.session.call_service(
            call.op, now, waits=service.handler is None, default=self.services.default_timeout
        )
        self.services.call(peer, call.op, service, call.request, deadline)

    def _advertise_service(self, peer: Peer, admitted: Typed, now: float) -> None:
        op, type_name = admitted.op, admitted.type
        assert type_name is not None
        self.apply(peer, peer.session.provide("service", op.name, type_name, op.service))

    def _unadvertise_service(self, peer: Peer, op: o.UnadvertiseService, now: float) -> None:
        self.apply(peer, peer.session.withdraw("service", op.name))

    def _advertise_action(self, peer: Peer, admitted: Typed, now: float) -> None:
        op, type_name = admitted.op, admitted.type
        assert type_name is not None
        self.apply(peer, peer.session.provide("action", op.name, type_name, op.action, op.type))

    def _unadvertise_action(self, peer: Peer, op: o.UnadvertiseAction, now: float) -> None:
        self.apply(peer, peer.session.withdraw("action", op.name))

    def _send_action_goal(self, peer: Peer, goal: GoalRequest, now: float) -> None:
        op = goal.op
        assert op is not None
        self.actions.submit(
            peer,
            goal.action,
            goal.message,
            op_id=op.id,
            written=op.action,
            feedback=op.feedback,
            sent_type=op.action_type,
            now=now,
        )

    def _action_feedback(self, peer: Peer, update: GoalUpdate, now: float) -> None:
        update.goal.feedback(update.values)

    def _action_result(self, peer: Peer, update: GoalUpdate, now: float) -> None:
        assert isinstance(update.op, o.ActionResult)
        self.actions.result(update.goal, update.op, update.values)

    def _service_response(self, peer: Peer, response: Response, now: float) -> None:
        self.services.respond(response.call, response.values, ok=response.ok)

    def _set_level(self, peer: Peer, op: o.SetLevel, now: float) -> None:
        self.apply(peer, peer.session.set_level(op))

    # -- effects ------------------------------------------------------------------------------

    def _subscribed(self, peer: Peer, effect: Subscribed) -> None:
        topic = self.topics.subscribed(peer, effect.sub, effect.type)
        if effect.new:
            self.topics.replay_latched(peer, topic, effect.sub)

    def _advertised(self, peer: Peer, effect: Advertised) -> None:
        self.topics.advertise(effect.name, effect.type, peer, effect.op_id, latch=effect.latch)

    def _provided(self, peer: Peer, effect: Provided) -> None:
        if effect.kind == "service":
            self.services.advertise(peer, effect.name, effect.type, effect.written)
        else:
            self.actions.provided(peer, effect)

    def _withdrawn(self, peer: Peer, effect: Withdrawn) -> None:
        if effect.kind == "service":
            self.services.unadvertise(peer, effect.name)
        else:
            self.actions.remove(peer, effect.name)
