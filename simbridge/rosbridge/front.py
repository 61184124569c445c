"""The rosbridge v2 front end: a client's frames in, its ops carried out on the graph.

:class:`Rosbridge` receives every frame of a rosbridge client, turns it into ops (via the
client's :class:`~simbridge.rosbridge.Session`), lets its
:class:`~simbridge.rosbridge.admission.Admission` decide whether each is allowed, hands each
allowed op to the client's session (ops in, effects out: the session updates what the client
holds and says what must be done) and carries out the effects on the graph's topic, service and
action tables (:meth:`Rosbridge.apply`). A bad op is answered with a ``status`` error to its
sender only (when the sender's ``set_level`` allows it) and logged at debug level; it never
touches other clients or the simulation.

It is sans-I/O like the graph: the server hands it frames and a monotonic ``now``; it hands
frames back to peers through their ``send``.

A ``/cmd_vel`` from a page, in a straight line (each step once):

1. **socket**: the server's connection handler reads the frame (message rate and work share
   of :mod:`simbridge.rosbridge.server`) and calls :meth:`Rosbridge.receive`;
2. **session**: :meth:`Session.parse <simbridge.rosbridge.Session.parse>` decodes it into a
   typed ``Publish`` op, its topic name resolved once (``cmd_vel`` -> ``/cmd_vel``);
   :meth:`Admission.admit <simbridge.rosbridge.admission.Admission.admit>` decides once
   (authenticated, publish rate, scope, type, payload) and returns a
   :class:`~simbridge.rosbridge.admission.Publication`: the topic, its type and the validated
   message; :meth:`Rosbridge._publish` hands it to the client's session (the first time, an
   ``Advertised`` effect, counted against its budgets);
3. **graph**: :meth:`TopicTable.deliver <simbridge.graph.topics.TopicTable.deliver>` hands the
   message, wrapped once, to the subscribers: encoded frames to clients, the message to
   in-process nodes;
4. **robot**: the robot's subscriber (:class:`~simbridge.robot.bridge.RobotBridge`) sets the
   command of its robot in the world (``World.command``); a command it refuses (not finite,
   absurd) comes back to the sender as a ``status`` error.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from simbridge.errors import ProtocolError, SimbridgeError
from simbridge.graph.graph import Graph
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.actions import ActionOps
from simbridge.rosbridge.admission import Admission, Publication, Typed
from simbridge.rosbridge.budget import Limits, Pool
from simbridge.rosbridge.encoding import json_body
from simbridge.rosbridge.ops import ClientId, Op, Refusal
from simbridge.rosbridge.services import ServiceOps
from simbridge.rosbridge.session import (
    Advertised,
    Effect,
    Provided,
    Reply,
    Session,
    Subscribed,
    Unadvertised,
    Unlatched,
    Unsubscribed,
    Withdrawn,
)
from simbridge.rosbridge.subscribers import Client, Subscribers


__all__ = ["Authenticator", "Rosbridge"]

logger = logging.getLogger(__name__)

OpHandler = Callable[[Client, Any, float], None]
EffectHandler = Callable[[Client, Any], None]


class Authenticator(Protocol):
    """What checks a client's ``auth`` op (the application's guard)."""

    def auth(self, peer: Client, op: o.Auth, now: float) -> tuple[str, str]:
        """Admit ``peer`` (its session's access) or refuse; return the ``status`` to send.

        Returns ``(level, text)``; a failed authentication is ``("error", text)`` and the
        client is closed (as ROS 1 rosbridge does).

        Raises:
            ProtocolError: this server takes no ``auth`` op.
        """


class Rosbridge:
    """The rosbridge clients of one graph: their sessions, budgets and ops."""

    def __init__(
        self,
        graph: Graph,
        limits: Limits | None = None,
        pool: Pool | None = None,
        *,
        authenticator: Authenticator | None = None,
        default_queue_length: int = 100,
    ) -> None:
        #: The robot's graph.
        self.graph = graph
        #: The clients' subscriptions to the graph's topics, and how messages reach them.
        self.subscribers = Subscribers(graph.topics, default_queue_length=default_queue_length)
        #: What each client may hold and do, and what all of them together may hold.
        self.limits = limits or Limits()
        self.pool = pool or Pool()
        #: Checks ``auth`` ops (``None``: the server takes none).
        self.authenticator = authenticator
        #: The service ops: their checks and handlers (:mod:`simbridge.rosbridge.services`).
        self.services = ServiceOps(self)
        #: The action ops: their checks and handlers (:mod:`simbridge.rosbridge.actions`).
        self.actions = ActionOps(self)
        #: Decides whether each op of a client is carried out.
        self.admission = Admission(
            graph.topics,
            graph.services,
            graph.access,
            checks={**self.services.checks(), **self.actions.checks()},
        )
        #: Op handlers by op class.
        self.handlers: dict[type, OpHandler] = {
            o.Auth: self._auth,
            o.Advertise: self._advertise,
            o.Unadvertise: self._unadvertise,
            o.Publish: self._publish,
            o.Subscribe: self._subscribe,
            o.Unsubscribe: self._unsubscribe,
            o.SetLevel: self._set_level,
            **self.services.handlers(),
            **self.actions.handlers(),
        }
        #: How each effect of a session is carried out (see :meth:`apply`).
        self.effects: dict[type, EffectHandler] = {
            Reply: lambda peer, e: peer.send(e.frame),
            Subscribed: self._subscribed,
            Unsubscribed: lambda peer, e: self.subscribers.unsubscribed(peer, e.sub, e.gone),
            Advertised: self._advertised,
            Unadvertised: lambda peer, e: graph.topics.unadvertise(e.name, peer, e.op_id),
            Unlatched: lambda peer, e: graph.topics.unlatched(peer, e.name),
            Provided: self._provided,
            Withdrawn: self._withdrawn,
        }

    # -- clients ------------------------------------------------------------------------------

    def new_session(self, token: str | None = None) -> Session:
        """Return a fresh session for a connecting client (its budgets from the settings).

        ``token``: the one it connected with (``?token=``), if any.
        """
        client_id = ClientId(self.graph.next_peer_id())
        return Session(client_id, limits=self.limits, pool=self.pool, token=token)

    def add_peer(self, peer: Client) -> None:
        """Register a connected client with the graph (the guard gives it its access)."""
        self.graph.add_peer(peer)

    def remove_peer(self, peer: Client, *, lost: bool = False) -> None:
        """Forget a client and everything it owned (subscriptions, publishers, services).

        Its session gives back its budgets and says what it held (effects, carried out here
        first); then the graph forgets it (:meth:`Graph.remove_peer
        <simbridge.graph.graph.Graph.remove_peer>`: its calls, the nodes' disconnect rules).
        ``lost``: the client went without closing its connection itself.
        """
        try:
            self._release(peer)
        finally:
            self.graph.remove_peer(peer, lost=lost)

    def _release(self, peer: Client) -> None:
        for effect in peer.session.close():
            try:
                self.effects[type(effect)](peer, effect)
            except Exception:
                logger.exception("%s: cleanup after disconnect failed for %r", peer.label, effect)

    def receive(self, peer: Client, data: str | bytes, now: float) -> None:
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

    def dispatch(self, peer: Client, op: Op, now: float) -> None:
        """Admit one op and carry it out; a :class:`SimbridgeError` becomes an answer to the sender.

        The handler receives what :meth:`Admission.admit
        <simbridge.rosbridge.admission.Admission.admit>` returns (the op, or what was decided for
        it: a ``Publication``, a ``Typed`` op, a service op's ``Call`` or ``Response``, an action
        op's ``GoalRequest``...), hands it to the client's session and carries out the effects.
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

    def refuse(self, peer: Client, err: ProtocolError, now: float, op: Op | None = None) -> None:
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
            self.services.fail(peer, target, text, op_id)
            return
        if kind == "send_action_goal":
            self.actions.refused(peer, target, op_id, text)
            return
        cause = err.cause if isinstance(err, Refusal) else text[:120]
        if op is not None:
            # one text for two kinds of op is two causes: a page that subscribed with the wrong
            # type still hears why its advertise is refused (it waits for that id's answer)
            cause = f"{type(op).__name__}: {cause}"
        replies = peer.session.refused(text, cause, now, op_id)
        if replies:  # most refusals of a flood are counted, not told: no call for them
            self.apply(peer, replies)

    def reject(self, peer: Client, text: str, op_id: Any) -> None:
        """Tell ``peer`` (only) that its op failed, as a ``status`` error (not budgeted)."""
        logger.debug("%s: %s", peer.label, text)
        self.apply(peer, peer.session.status("error", text, op_id))

    def apply(self, peer: Client, effects: Iterable[Effect]) -> None:
        """Carry out the effects a session returned for its client ``peer``, in order."""
        handlers = self.effects
        for effect in effects:
            handlers[type(effect)](peer, effect)

    # -- op handlers ------------------------------------------------------------------------

    def _advertise(self, peer: Client, admitted: Typed, now: float) -> None:
        assert admitted.type is not None  # admitted: the canonical type
        self.apply(peer, peer.session.advertise(admitted.op, admitted.type))

    def _unadvertise(self, peer: Client, op: o.Unadvertise, now: float) -> None:
        self.apply(peer, peer.session.unadvertise(op))

    def _publish(self, peer: Client, admitted: Publication, now: float) -> None:
        op = admitted.op
        name = op.name
        effects = peer.session.publish(name, admitted.type)
        if effects:
            self.apply(peer, effects)  # the first publish: the client becomes a publisher
        topic = admitted.topic
        if topic is None or topic.type is None:
            topic = self.graph.topics.topics.get(name) or self.graph.topics.advertise(
                name, admitted.type, peer, None
            )
        topics = self.graph.topics
        out = topics.outgoing(topic, admitted.msg, self.graph.stamp())
        if op.latch or topic.latch:
            session = peer.session
            session.latch(name, len(json_body(out)))  # what later subscribers will cost
            topics.latch(topic)
            topics.deliver(topic, out, now, peer, release=lambda: session.unlatch(name))
            return
        topics.deliver(topic, out, now, peer)

    def _subscribe(self, peer: Client, admitted: Typed, now: float) -> None:
        self.apply(peer, peer.session.subscribe(admitted.op, admitted.type))

    def _unsubscribe(self, peer: Client, op: o.Unsubscribe, now: float) -> None:
        self.apply(peer, peer.session.unsubscribe(op))

    def _set_level(self, peer: Client, op: o.SetLevel, now: float) -> None:
        self.apply(peer, peer.session.set_level(op))

    # -- effects ------------------------------------------------------------------------------

    def _subscribed(self, peer: Client, effect: Subscribed) -> None:
        topic = self.subscribers.subscribed(peer, effect.sub, effect.type)
        if effect.new:
            self.subscribers.replay_latched(peer, topic, effect.sub)

    def _advertised(self, peer: Client, effect: Advertised) -> None:
        self.graph.topics.advertise(
            effect.name, effect.type, peer, effect.op_id, latch=effect.latch
        )

    def _provided(self, peer: Client, effect: Provided) -> None:
        if effect.kind == "service":
            self.services.provided(peer, effect)
        else:
            self.actions.provided(peer, effect)

    def _withdrawn(self, peer: Client, effect: Withdrawn) -> None:
        if effect.kind == "service":
            self.services.withdrawn(peer, effect)
        else:
            self.actions.withdrawn(peer, effect.name)

    def _auth(self, peer: Client, op: o.Auth, now: float) -> None:
        if self.authenticator is None:
            msg = "auth: this server takes no rosauth MAC; connect with ?token=YOUR_TOKEN"
            raise ProtocolError(msg)
        level, text = self.authenticator.auth(peer, op, now)
        self.apply(peer, peer.session.status(level, text))
        if level == "error":
            close = getattr(peer, "close_soon", None)
            if callable(close):
                close(1008, "authentication failed")
