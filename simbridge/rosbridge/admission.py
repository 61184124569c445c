"""Admission: the one place that decides whether a client's op is carried out.

Every op of a client passes :meth:`Admission.admit` between its session's parse (names resolved
once, strings checked: :meth:`Session.parse <simbridge.rosbridge.Session.parse>`) and its
handler on the graph, which then only carries it out. The checks, in this order:

1. **authentication**: nothing but ``auth`` from a client that still owes a token;
2. **fragment size**: a ``fragment_size`` below :data:`MIN_FRAGMENT_SIZE` bytes is refused;
3. **rate**: ``publish`` ops above the client's ``publish_rate`` are dropped, told at most once
   a second (the session's token bucket);
4. **scope and rights**: a client scoped to robot ``r1`` may publish and advertise topics
   only under ``/r1/``, nor fix the type of a topic outside its namespace with a typed
   subscribe;
5. **type**: the type of a ``publish``, ``advertise`` or typed ``subscribe`` is well formed and
   is the topic's type (rosbridge's TypeConflictException); a ``publish`` without a type takes
   the topic's; the op carries on with the canonical spelling;
6. **payload**: a ``publish`` message is validated against its type and completed with
   defaults (:class:`~simbridge.msgs.Converter`; a type simbridge does not know passes as it
   is, a message of it must be a JSON object).

The service ops' checks (rights and scope, requests, a provider's responses) are in
:mod:`simbridge.rosbridge.services`, and the action ops' (scope, goal payloads, a provider's
feedback and results) in :mod:`simbridge.rosbridge.actions`, each beside its handlers; the front
end hands them to :class:`Admission` (``checks``), which runs them in the same place of this
order.

Checks 1-4 are access rules. They apply once a :class:`~simbridge.app.guard.Guard` is
installed (it authenticates clients and gives each session its scope and rights, and sets
:attr:`Admission.guarded`); a graph without one trusts every client. What a client may *hold*
(subscriptions, advertisements, pending calls, latched bytes) is not decided here but by its
session's budgets, when the handler takes it; names it may own are counted here too, so that a
scope refusal comes before a budget one.

What :meth:`Admission.admit` returns is what the op's handler carries out: a
:class:`Publication` or a :class:`Typed` op (the tables receive payloads already
validated), what a service or action op's check returns, or the op itself. A refused op raises
:class:`~simbridge.rosbridge.Refusal` or :class:`ProtocolError`, answered to its sender only by
the graph (a refused call or goal gets its failed answer, its caller waits for one).
Admission reads the client's session (its access, what it holds) and changes nothing in it but
the charge of its publish rate.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from simbridge.errors import ProtocolError, TypeNotFoundError
from simbridge.graph.access import ANY_SCOPE, AccessRules, in_namespace
from simbridge.graph.services import ServiceTable
from simbridge.graph.topics import Topic, TopicTable
from simbridge.msgs import normalize_type
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.ops import Op, Refusal
from simbridge.rosbridge.session import NOT_AUTHENTICATED, Session
from simbridge.rosbridge.subscribers import Client


__all__ = [
    "MIN_FRAGMENT_SIZE",
    "Admission",
    "Check",
    "Publication",
    "Typed",
    "interface_type",
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


#: An op's check: ``(peer, its session, op, now) -> what the op's handler carries out``.
Check = Callable[[Client, Session, Any, float], Any]


class Admission:
    """Decides, for every op of a client, whether the graph carries it out."""

    def __init__(
        self,
        topics: TopicTable,
        services: ServiceTable,
        rules: AccessRules | None = None,
        *,
        checks: dict[type, Check] | None = None,
    ) -> None:
        #: The graph's topics (types of existing topics; payload validation).
        self.topics = topics
        #: The graph's services (a client may not advertise what the server provides).
        self.services = services
        #: The graph's access rules (checks 1-4 apply once a guard turned them on).
        self.rules = rules or AccessRules()
        #: The checks of the other kinds of op (the service and action ops', given by the
        #: front end).
        self.checks: dict[type, Check] = dict(checks or {})

    @property
    def guarded(self) -> bool:
        """Access rules (checks 1-4) apply: a guard authenticates the clients."""
        return self.rules.guarded

    def admit(self, peer: Client, op: Op, now: float) -> Any:
        """Return what the op's handler carries out, or ``None`` if the op is dropped.

        That is a :class:`Publication`, :class:`Typed`, what a service or action op's check
        returns (see the module doc), or the op itself.

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
        if check is not None:
            return check(self, peer, session, op, now)
        other = self.checks.get(type(op))
        return op if other is None else other(peer, session, op, now)

    # -- one check per kind of op -----------------------------------------------------------

    def _publish(self, peer: Client, session: Session, op: o.Publish, now: float) -> Any:
        name = op.name
        if self.guarded:
            if not session.take_publish(now):
                limits = session.limits
                msg = (
                    f"publish {name}: dropped, more than {limits.publish_rate:g} publishes per "
                    f"second (the server's publish_rate, burst {limits.publish_burst}); slow down"
                )
                raise Refusal(msg, cause="publish_rate")
            self.may_own(session, "publish", name, not session.advertises(name))
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

    def _advertise(self, peer: Client, session: Session, op: o.Advertise, now: float) -> Any:
        if self.guarded:
            self.may_own(session, "advertise", op.name, not session.advertises(op.name))
        return Typed(op, self.topics.check_type(op.name, op.type))

    def _subscribe(self, peer: Client, session: Session, op: o.Subscribe, now: float) -> Any:
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

    # -- scope -----------------------------------------------------------------------------

    def may_own(self, session: Session, what: str, name: str, new: bool) -> None:
        """Check that ``session`` may own ``name`` (its scope; its budget when ``new``).

        Raises:
            Refusal: outside the client's namespace, or its advertisement budget is spent.
        """
        if not in_namespace(session.scope, name):
            msg = (
                f"{what} {name}: not allowed; this connection may only use names under "
                f"/{session.scope}/ (its robot)"
            )
            raise Refusal(msg, cause=f"scope {what}")
        session.may_own(what, name, new)


def interface_type(type_name: str, kind: Literal["srv", "action"], op: str) -> str:
    """Return the canonical spelling of a service or action type, or refuse the op."""
    try:
        return normalize_type(type_name, kind)
    except TypeNotFoundError as err:
        raise ProtocolError(f"{op}: {err}") from None


_CHECKS: dict[type, Callable[[Admission, Client, Session, Any, float], Any]] = {
    o.Publish: Admission._publish,
    o.Advertise: Admission._advertise,
    o.Subscribe: Admission._subscribe,
}
