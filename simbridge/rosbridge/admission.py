"""Admission: the one place that decides whether a client's op is carried out.

Every op of a client passes :meth:`Admission.admit` between its session's parse (names resolved
once, strings checked: :meth:`Session.parse <simbridge.rosbridge.Session.parse>`) and its
handler on the graph, which then only carries it out. The checks, in this order:

1. **authentication**: nothing but ``auth`` from a client that still owes a token;
2. **fragment size**: a ``fragment_size`` below :data:`MIN_FRAGMENT_SIZE` bytes is refused;
3. **rate**: ``publish`` ops above the client's ``publish_rate`` are dropped, told at most once
   a second (the session's token bucket);
4. **scope and rights**: a client scoped to robot ``r1`` may publish and advertise (topics,
   services, actions) only under ``/r1/`` and may not call services or send goals under
   another robot's namespace, nor fix the type of a topic outside its namespace with a typed
   subscribe; administrative services (:attr:`Admission.admin_services`) need admin rights; a
   service or action the server provides cannot be advertised by a client;
5. **type**: the type of a ``publish``, ``advertise`` or typed ``subscribe`` is well formed and
   is the topic's type (rosbridge's TypeConflictException); a ``publish`` without a type takes
   the topic's; a service or action type is well formed; the op carries on with the canonical
   spelling;
6. **payload**: a ``publish`` message, the request of a ``call_service`` and the goal of a
   ``send_action_goal`` are validated against their types and completed with defaults
   (:class:`~simbridge.msgs.Converter`; ``args`` given as a list are zipped onto the fields in
   declaration order; a type simbridge does not know passes as it is, a message of it must be a
   JSON object); a call or goal to a service or action that does not exist is refused here. The
   answers of a client provider are checked the same way: the ``values`` of a
   ``service_response`` (read as :mod:`~simbridge.graph.services` says; values that do not fit
   the response type become a failed answer to the caller) and of an ``action_feedback`` or
   ``action_result`` (refused), each for a call or goal that this client serves.

Checks 1-4 are access rules. They apply once a :class:`~simbridge.app.guard.Guard` is
installed (it authenticates clients and gives each session its scope and rights, and sets
:attr:`Admission.guarded`); a graph without one trusts every client. What a client may *hold*
(subscriptions, advertisements, pending calls, latched bytes) is not decided here but by its
session's budgets, when the handler takes it; names it may own are counted here too, so that a
scope refusal comes before a budget one.

What :meth:`Admission.admit` returns is what the op's handler carries out: a
:class:`Publication`, a :class:`Typed` op, a :class:`Call`, a :class:`GoalRequest`, a
:class:`Response` or a :class:`GoalUpdate` (the tables receive payloads already validated), or
the op itself. A refused op raises
:class:`~simbridge.rosbridge.Refusal` or :class:`ProtocolError`, answered to its sender only by
the graph (a refused call or goal gets its failed answer, its caller waits for one).
Admission reads the client's session (its access, what it holds) and changes nothing in it but
the charge of its publish rate.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from simbridge.errors import ConversionError, ProtocolError, ServiceError, TypeNotFoundError
from simbridge.graph.access import ANY_SCOPE, AccessRules, in_namespace
from simbridge.graph.actions import Action, ActionTable, Goal
from simbridge.graph.services import Finish, PendingCall, Prepare, Service, ServiceTable
from simbridge.graph.topics import Peer, Topic, TopicTable
from simbridge.msgs import normalize_type, positional_args
from simbridge.msgs.registry import MAX_TYPE_LENGTH
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.ops import Op, Refusal
from simbridge.rosbridge.session import NOT_AUTHENTICATED, Session


__all__ = [
    "MIN_FRAGMENT_SIZE",
    "Admission",
    "Call",
    "GoalRequest",
    "GoalUpdate",
    "Publication",
    "Response",
    "Typed",
]

logger = logging.getLogger(__name__)

#: Smallest ``fragment_size`` accepted (smaller ones would cost a message per few bytes).
MIN_FRAGMENT_SIZE = 256


@dataclass(frozen=True, slots=True)
class Publication:
    """An admitted ``publish``: what its handler carries out, decided once."""

    op: o.Publish
    #: The topic published on (``None``: not in the graph yet; the publish creates it).
    topic: Topic | None
    #: The topic's canonical type.
    type: str
    #: The message, validated and completed (canonical), or the client's object as it is
    #: when simbridge does not know the type.
    msg: Any


@dataclass(frozen=True, slots=True)
class Typed:
    """An admitted ``advertise``, ``subscribe``, ``advertise_service`` or ``advertise_action``."""

    op: Any
    #: The canonical spelling of the op's type (``None``: a subscribe without one).
    type: str | None


@dataclass(frozen=True, slots=True)
class Call:
    """An admitted ``call_service``: the service called and the request, validated."""

    op: o.CallService
    service: Service
    #: The complete request message when the service type is known, else ``args`` as sent.
    request: Any


@dataclass(frozen=True, slots=True)
class GoalRequest:
    """An admitted goal: the action and the goal message, validated."""

    action: Action
    #: The complete goal message when the action type is known, else ``args`` as sent.
    message: Any
    #: The client's ``send_action_goal`` (``None``: a goal from outside the protocol).
    op: o.SendActionGoal | None = None


@dataclass(frozen=True, slots=True)
class Response:
    """An admitted ``service_response``: the call it answers and the answer for its caller."""

    call: PendingCall
    ok: bool
    #: The response, validated and completed when the service type is known (``ok``), or why
    #: the call failed.
    values: Any


@dataclass(frozen=True, slots=True)
class GoalUpdate:
    """An admitted ``action_feedback`` or ``action_result`` of a goal the client serves."""

    goal: Goal
    op: o.ActionFeedback | o.ActionResult
    #: The feedback or result, validated and completed when the action type is known (a
    #: failed result's reason as sent).
    values: Any


class Admission:
    """Decides, for every op of a client, whether the graph carries it out."""

    def __init__(
        self,
        topics: TopicTable,
        services: ServiceTable,
        actions: ActionTable,
        rules: AccessRules | None = None,
        *,
        prepare: Prepare | None = None,
        finish: Finish | None = None,
    ) -> None:
        #: The graph's topics (types of existing topics; payload validation).
        self.topics = topics
        #: Validates and completes the requests of known service types
        #: (:func:`~simbridge.graph.services.typed_calls`), and their responses.
        self.prepare = prepare
        self.finish = finish
        #: The graph's services and actions (a client may not advertise what the server
        #: provides).
        self.services = services
        self.actions = actions
        #: The graph's access rules (checks 1-4 apply once a guard turned them on).
        self.rules = rules or AccessRules()

    @property
    def guarded(self) -> bool:
        """Access rules (checks 1-4) apply: a guard authenticates the clients."""
        return self.rules.guarded

    def admit(self, peer: Peer, op: Op, now: float) -> Any:
        """Return what the op's handler carries out, or ``None`` if the op is dropped.

        That is a :class:`Publication`, :class:`Typed`, :class:`Call` or :class:`GoalRequest`
        (see the module doc), or the op itself.

        Raises:
            ProtocolError: the op is refused (a :class:`Refusal` says how to answer it).
        """
        session = peer.session
        if self.guarded:
            if not session.authenticated and not isinstance(op, o.Auth):
                raise Refusal(NOT_AUTHENTICATED, cause="unauthenticated")
            size = getattr(op, "fragment_size", None)
            if size is not None and size < MIN_FRAGMENT_SIZE:
                msg = (
                    f"fragment_size {size} is too small: at least {MIN_FRAGMENT_SIZE} bytes "
                    "(tiny fragments multiply the server's work)"
                )
                raise Refusal(msg, cause="fragment_size")
        check = _CHECKS.get(type(op))
        return op if check is None else check(self, peer, session, op, now)

    # -- one check per kind of op -----------------------------------------------------------

    def _publish(self, peer: Peer, session: Session, op: o.Publish, now: float) -> Any:
        name = op.name
        if self.guarded:
            if not session.take_publish(now):
                limits = session.limits
                msg = (
                    f"publish {name}: dropped, more than {limits.publish_rate:g} publishes per "
                    f"second (the server's publish_rate, burst {limits.publish_burst}); slow down"
                )
                raise Refusal(msg, cause="publish_rate")
            self._may_own(session, "publish", name, not session.advertises(name))
        topic = self.topics.topics.get(name)
        if op.type is not None:
            canonical = self.topics.check_type(name, op.type)
            if topic is not None and topic.type is not None:
                known = topic.known
            else:
                known = self.topics.registry.known(canonical)
        elif topic is None or topic.type is None:
            msg = (
                f"publish: cannot infer the type of topic {name}: it is not advertised; "
                "advertise it first or give a type"
            )
            raise ProtocolError(msg)
        else:
            canonical, known = topic.type, topic.known
        return Publication(op, topic, canonical, self.topics.validate(canonical, known, op.msg))

    def _advertise(self, peer: Peer, session: Session, op: o.Advertise, now: float) -> Any:
        if self.guarded:
            self._may_own(session, "advertise", op.name, not session.advertises(op.name))
        return Typed(op, self.topics.check_type(op.name, op.type))

    def _subscribe(self, peer: Peer, session: Session, op: o.Subscribe, now: float) -> Any:
        if not op.type:
            return Typed(op, None)
        if self.guarded and session.scope != ANY_SCOPE:
            # a typed subscription fixes the type of a topic nobody publishes yet: outside its
            # own namespace that would squat a name (a robot spawned later could not take it)
            name = op.name
            topic = self.topics.topics.get(name)
            if not in_namespace(session.scope, name) and (topic is None or topic.type is None):
                msg = (
                    f"subscribe {name}: refused with a type, the topic is outside "
                    f"/{session.scope}/ and nothing publishes it yet (the type would claim the "
                    "name); subscribe without a type and it waits for the topic"
                )
                raise Refusal(msg, cause="typed subscribe outside scope")
        return Typed(op, self.topics.check_type(op.name, op.type))

    def _advertise_service(
        self, peer: Peer, session: Session, op: o.AdvertiseService, now: float
    ) -> Any:
        if self.guarded:
            existing = self.services.services.get(op.name)
            if existing is not None and existing.handler is not None:
                msg = (
                    f"advertise_service {op.name}: refused, the server provides this service "
                    "itself; choose another name"
                )
                raise Refusal(msg, cause="server service")
            new = not session.provides("service", op.name)
            self._may_own(session, "advertise_service", op.name, new)
        return Typed(op, _interface_type(op.type, "srv", "advertise_service"))

    def _advertise_action(
        self, peer: Peer, session: Session, op: o.AdvertiseAction, now: float
    ) -> Any:
        name = op.name
        if self.guarded:
            self._may_own(session, "advertise_action", name, not session.provides("action", name))
        existing = self.actions.actions.get(name)
        if existing is not None and existing.server is not None:
            # what the server provides stays the server's: taking it over would break it for
            # every client, and it would be gone for everyone when this client left
            msg = (
                f"advertise_action {name}: refused, the server provides this action itself; "
                "choose another name"
            )
            raise ProtocolError(msg)
        return Typed(op, _interface_type(op.type, "action", "advertise_action"))

    def _call_service(self, peer: Peer, session: Session, op: o.CallService, now: float) -> Any:
        if not self.guarded:
            return self.call(op)
        name = op.name
        if self.rules.admin_only(name) and not session.admin:
            reason = (
                f"service {name} is administrative: connect with the admin token "
                "(?token=ADMIN_TOKEN) to call it"
            )
        elif not self.rules.may_reach(session.access, name):
            reason = f"service {name} belongs to another robot; this connection may not call it"
        else:
            return self.call(op)
        logger.info("%s: %s", peer.label, reason)
        raise Refusal(reason, op="call_service", target=op.service, op_id=op.id)

    def _send_action_goal(
        self, peer: Peer, session: Session, op: o.SendActionGoal, now: float
    ) -> Any:
        if self.guarded and not self.rules.may_reach(session.access, op.name):
            msg = f"action {op.name} belongs to another robot; this connection may not use it"
            raise Refusal(msg, op="send_action_goal", target=op.action, op_id=op.id)
        if len(op.action_type) > MAX_TYPE_LENGTH:  # a goal keeps it while it runs
            msg = (
                f"send_action_goal {op.name}: refused, its action_type is "
                f"{len(op.action_type)} characters long: at most {MAX_TYPE_LENGTH}, e.g. "
                "'example_interfaces/action/Fibonacci'"
            )
            raise Refusal(msg, op="send_action_goal", target=op.action, op_id=op.id)
        return self.goal(op.name, op.args, op)

    def _service_response(
        self, peer: Peer, session: Session, op: o.ServiceResponse, now: float
    ) -> Any:
        return self.response(peer, op)

    def _action_feedback(
        self, peer: Peer, session: Session, op: o.ActionFeedback, now: float
    ) -> Any:
        goal = self._served_goal(peer, op.id, "action_feedback")
        return GoalUpdate(goal, op, self._complete(goal, 2, op.values, "action_feedback"))

    def _action_result(self, peer: Peer, session: Session, op: o.ActionResult, now: float) -> Any:
        goal = self._served_goal(peer, op.id, "action_result")
        if op.result is False:  # a failure: its reason goes to the caller as it is
            return GoalUpdate(goal, op, op.values)
        return GoalUpdate(goal, op, self._complete(goal, 1, op.values, "action_result"))

    # -- payloads of calls and goals (also for callers outside the protocol: Zenoh) ----------

    def call(self, op: o.CallService) -> Call:
        """Return the call with its service and validated request.

        Raises:
            Refusal: no such service, or ``args`` do not fit its request type (answered as a
                failed ``service_response``).
        """
        name = op.name
        service = self.services.services.get(name)
        if service is None:
            text = f"Service {name} does not exist"
            raise Refusal(text, op="call_service", target=op.service, op_id=op.id)
        request: Any = op.args
        if self.prepare is not None:
            try:
                prepared = self.prepare(service.type, op.args)
            except ServiceError as err:
                text = str(err)
                raise Refusal(text, op="call_service", target=op.service, op_id=op.id) from None
            if prepared is not None:
                request = prepared
        return Call(op, service, request)

    def goal(self, name: str, args: Any, op: o.SendActionGoal | None = None) -> GoalRequest:
        """Return the action ``name`` and its goal message made of ``args``, validated.

        Raises:
            ProtocolError: no such action, or ``args`` do not fit its goal type (answered as a
                failed ``action_result``).
        """
        action = self.actions.actions.get(name)
        if action is None:
            msg = f"Action {name} does not exist (no server advertised it)"
            raise ProtocolError(msg)
        registry = self.topics.registry
        try:
            goal_type = registry.action(action.type)[0]
        except TypeNotFoundError:
            return GoalRequest(action, args if args is not None else {}, op)
        try:
            if args is None:
                args = {}
            elif isinstance(args, list):
                names = [f.name for f in registry.spec(goal_type).fields]
                args = positional_args(args, names, f"goal of {action.type}")
            return GoalRequest(action, self.topics.converter.from_json(goal_type, args), op)
        except ConversionError as err:
            msg = f"invalid goal for {action.type}: {err}"
            raise ProtocolError(msg) from None

    def response(self, peer: Peer, op: o.ServiceResponse) -> Response:
        """Return the answer a provider's ``service_response`` gives its call's caller.

        Read as :mod:`~simbridge.graph.services` says; values of a known response type are
        validated and completed (values that do not fit are a failed answer, naming why).

        Raises:
            ProtocolError: no call waits under that id, or ``peer`` does not provide it.
        """
        call = self.services.answering(peer, op)
        values = op.values
        if isinstance(values, dict) or (op.result is True and values is None):
            ok, values = True, values if isinstance(values, dict) else {}
        elif isinstance(values, str) and op.result is False:
            ok = False
        elif op.result is False and values is None:
            ok, values = False, "service provider reported failure"
        else:
            ok = False
            shown = json.dumps(values, default=repr)
            values = f"service provider sent no result object (values: {shown})"
        if ok and self.finish is not None:
            try:
                values = self.finish(call.service.type, values)
            except ServiceError as err:
                ok, values = False, f"service provider sent an invalid response: {err}"
        return Response(call, ok, values)

    def _served_goal(self, peer: Peer, op_id: Any, what: str) -> Goal:
        goal = self.actions.goals.get(op_id) if isinstance(op_id, str) else None
        if goal is None or goal.action.provider is not peer:
            msg = f"{what} for unknown or finished goal id {op_id!r}"
            raise ProtocolError(msg)
        return goal

    def _complete(self, goal: Goal, part: int, values: Any, what: str) -> Any:
        """Check and complete feedback (part 2) or result (part 1) values of a known type."""
        try:
            name = self.topics.registry.action(goal.action.type)[part]
        except TypeNotFoundError:
            return values
        try:
            return self.topics.converter.from_json(name, {} if values is None else values)
        except ConversionError as err:
            msg = f"{what} for {goal.action.name}: {err}"
            raise ProtocolError(msg) from None

    # -- scope -----------------------------------------------------------------------------

    def _may_own(self, session: Session, what: str, name: str, new: bool) -> None:
        if not in_namespace(session.scope, name):
            msg = (
                f"{what} {name}: not allowed; this connection may only use names under "
                f"/{session.scope}/ (its robot)"
            )
            raise Refusal(msg, cause=f"scope {what}")
        session.may_own(what, name, new)


def _interface_type(type_name: str, kind: Literal["srv", "action"], op: str) -> str:
    """Return the canonical spelling of a service or action type, or refuse the op."""
    try:
        return normalize_type(type_name, kind)
    except TypeNotFoundError as err:
        raise ProtocolError(f"{op}: {err}") from None


_CHECKS: dict[type, Callable[[Admission, Peer, Session, Any, float], Any]] = {
    o.Publish: Admission._publish,
    o.Advertise: Admission._advertise,
    o.Subscribe: Admission._subscribe,
    o.AdvertiseService: Admission._advertise_service,
    o.AdvertiseAction: Admission._advertise_action,
    o.CallService: Admission._call_service,
    o.SendActionGoal: Admission._send_action_goal,
    o.ServiceResponse: Admission._service_response,
    o.ActionFeedback: Admission._action_feedback,
    o.ActionResult: Admission._action_result,
}
