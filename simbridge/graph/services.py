"""Services of the ROS graph: in-process handlers and services provided by peers of front ends.

A front end calls a service with :meth:`ServiceTable.call`, handing in ``done(ok, values)``: the
table calls it exactly once, whatever happens (answered, failed, timed out, provider gone), with
``ok`` true and the response message or ``ok`` false and the reason as text. A front end that
counts its peer's waiting calls hands in ``release`` too, called once when a call to a provider
ends (before ``done``). The table never blocks the caller and never sends anything itself.

* **in-process** (:meth:`ServiceTable.add`): the handler runs at once with :data:`caller` set to
  the calling peer (handlers whose answer depends on who asks read ``caller.get().access``); a
  :class:`ServiceError` is a failed answer with its text, any other exception one naming the
  service (a handler bug never breaks the caller's connection).
* **provided by a peer** (:meth:`ServiceTable.provide`): the peer's front end gives a
  ``forward(call, request)`` that puts the call on its wire, and answers it later with
  :meth:`ServiceTable.respond`; a call not answered by its ``deadline`` fails when the graph's
  tick passes it (:meth:`ServiceTable.expire`); a provider that withdraws, leaves or loses the
  name to another provider fails the calls waiting for it, and one that loses the name is told
  through the ``lost`` callback its front end gave.

Requests and responses are canonical messages (:mod:`simbridge.msgs`) when the service type is
known: :func:`typed_calls` gives the checks a front end runs on requests and responses written as
JSON values (rosbridge's ``args`` and ``values``, Foxglove's JSON encoding); a front end that
decodes a typed wire (CDR) has them complete already.
"""

from __future__ import annotations

import heapq
import itertools
import logging
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from simbridge.errors import ConversionError, ServiceError, TypeNotFoundError
from simbridge.graph.topics import BRIDGE_NODE, Peer
from simbridge.msgs import Converter, TypeRegistry, positional_args, short_type


__all__ = [
    "Done",
    "Finish",
    "Forward",
    "Handler",
    "Lost",
    "PendingCall",
    "Prepare",
    "Service",
    "ServiceTable",
    "caller",
    "typed_calls",
]

logger = logging.getLogger(__name__)

#: An in-process service: request -> response object. The request is the complete, validated
#: request message when the service type is known (the caller's front end validated it, see
#: :func:`typed_calls`), else the request as the caller wrote it. Raise :class:`ServiceError`
#: to answer with failure and the error text.
Handler = Callable[[Any], dict[str, Any]]
#: The peer whose call an in-process handler is answering (None outside a call): handlers
#: whose answer depends on who asks (the e-stop's scope, ``/simbridge/access``) read its access.
caller: ContextVar[Peer | None] = ContextVar("caller", default=None)
#: Turns ``(service type, request as written in JSON values)`` into the request to hand on, or
#: raises :class:`ServiceError`; ``None`` from it means "type unknown: pass it on unchanged".
Prepare = Callable[[str, Any], Any]
#: Checks and completes a provider's response values: ``(service type, values)``.
Finish = Callable[[str, Any], Any]
#: The caller's front end told the answer of one call: ``(ok, values)``: the response when
#: ``ok``, else why the call failed (text).
Done = Callable[[bool, Any], None]
#: The provider's front end puts one call on its wire: ``(call, request)``; it answers with
#: :meth:`ServiceTable.respond` (or leaves the call to time out).
Forward = Callable[["PendingCall", Any], None]
#: The provider's front end told that its peer no longer provides a name (another took it).
Lost = Callable[[str], None]


def typed_calls(registry: TypeRegistry, converter: Converter) -> tuple[Prepare, Finish]:
    """Return the request and response checks for services whose type ``registry`` knows.

    A request (``args`` as an object, or a list zipped onto the request fields in declaration
    order, protocol reference section 3.5) becomes the complete request message: missing fields
    get their defaults, unknown fields and wrong types are refused. A service type simbridge
    does not know passes ``args`` through unchanged.
    """

    def parts(type_name: str) -> tuple[str, str] | None:
        try:
            return registry.service(type_name)
        except TypeNotFoundError:
            return None

    def convert(name: str, value: Any, what: str) -> Any:
        spec = registry.spec(name)
        try:
            return converter.from_json(name, value)
        except ConversionError as err:
            fields = ", ".join(f.name for f in spec.fields) or "no fields"
            msg = f"{err} ({what} of {short_type(name)}; expected {fields})"
            raise ServiceError(msg) from None

    def prepare(type_name: str, args: Any) -> Any:
        found = parts(type_name)
        if found is None:
            return None
        request = found[0]
        if args is None:
            args = {}
        elif isinstance(args, list):
            names = [f.name for f in registry.spec(request).fields]
            try:
                args = positional_args(args, names, f"request of {type_name}")
            except ConversionError as err:
                raise ServiceError(str(err)) from None
        return convert(request, args, "request")

    def finish(type_name: str, values: Any) -> Any:
        found = parts(type_name)
        if found is None:
            return values
        return convert(found[1], values, "response")

    return prepare, finish


@dataclass(eq=False, slots=True)
class Service:
    """One service: answered in process (``handler``) or by a front end's peer (``provider``)."""

    name: str
    type: str
    node: str
    handler: Handler | None = None
    provider: Peer | None = None
    #: How a provider's front end puts a call on its wire.
    forward: Forward | None = None
    #: How a provider's front end hears that another provider took the name.
    lost: Lost | None = None
    #: The name as the provider wrote it (rosbridge clients route by it).
    written: str = ""


@dataclass(eq=False, slots=True)
class PendingCall:
    """A call forwarded to a provider, waiting for :meth:`ServiceTable.respond`."""

    #: The graph's id of the call (``service_request:<service>:<n>``), unique in the process.
    id: str
    service: Service
    caller: Peer
    done: Done
    #: When it times out (the graph's monotonic clock).
    deadline: float
    #: The caller's front end's budget hook (called once when the call ends), if any.
    release: Callable[[], None] | None = None


class ServiceTable:
    """Every service, and the calls waiting for providers."""

    def __init__(self, *, default_timeout: float = 5.0) -> None:
        #: Seconds a call to a provider waits when its caller gives no timeout.
        self.default_timeout = default_timeout
        #: Services by absolute name.
        self.services: dict[str, Service] = {}
        #: Bumped by every service added, replaced or removed (see ``TopicTable.changes``).
        self.changes = 0
        #: Calls forwarded to providers, by id.
        self.pending: dict[str, PendingCall] = {}
        # the same calls by caller and by service, and their deadlines in a heap: answering,
        # expiring or dropping one never scans the others
        self._by_caller: dict[Peer, dict[str, PendingCall]] = {}
        self._by_service: dict[Service, dict[str, PendingCall]] = {}
        self._deadlines: list[tuple[float, int, str]] = []
        self._counter = itertools.count(1)

    def add(self, name: str, type_name: str, node: str, handler: Handler) -> Service:
        """Register an in-process service (replacing any previous one of that name)."""
        service = Service(name, type_name, node, handler=handler)
        self._replace(name, service)
        return service

    def lookup(self, name: str) -> Service:
        """Return the service ``name`` (absolute).

        Raises:
            ServiceError: there is none (the text is what the caller is told).
        """
        service = self.services.get(name)
        if service is None:
            msg = f"Service {name} does not exist"
            raise ServiceError(msg)
        return service

    def provide(
        self,
        peer: Peer,
        name: str,
        type_name: str,
        forward: Forward,
        *,
        lost: Lost | None = None,
        node: str = BRIDGE_NODE,
        written: str = "",
    ) -> Service:
        """Make ``peer`` the provider of ``name``: calls reach it through ``forward``.

        A previous service of that name is replaced: its waiting calls fail, and a previous
        provider other than ``peer`` is told through its ``lost`` callback.
        """
        service = Service(
            name,
            type_name,
            node,
            provider=peer,
            forward=forward,
            lost=lost,
            written=written or name,
        )
        self._replace(name, service)
        return service

    def withdraw(self, peer: Peer, name: str) -> bool:
        """Remove ``peer``'s service ``name``; return whether it was its provider.

        Its waiting calls fail.
        """
        service = self.services.get(name)
        if service is None or service.provider is not peer:
            return False
        del self.services[name]
        self.changes += 1
        self._fail_pending(service, f"service {name} was unadvertised by its provider")
        return True

    def call(
        self,
        peer: Peer,
        service: Service,
        request: Any,
        deadline: float,
        done: Done,
        *,
        release: Callable[[], None] | None = None,
    ) -> PendingCall | None:
        """Call ``service`` for ``peer``; ``done(ok, values)`` gets the answer, exactly once.

        ``request`` is what the caller's front end validated (complete when the type is
        known). An in-process handler answers at once (``release`` is not called: nothing
        waited); a provider gets the call through its ``forward`` and has until ``deadline``.
        Returns the waiting call, or None when it was answered already.
        """
        if service.handler is not None:
            ok, values = self._run(peer, service, request)
            done(ok, values)
            return None
        forward = service.forward
        assert forward is not None  # a provided service has its front end's forwarder
        seq = next(self._counter)
        call_id = f"service_request:{service.name}:{seq}"
        call = PendingCall(call_id, service, peer, done, deadline, release)
        self.pending[call_id] = call
        self._by_caller.setdefault(peer, {})[call_id] = call
        self._by_service.setdefault(service, {})[call_id] = call
        heapq.heappush(self._deadlines, (deadline, seq, call_id))
        try:
            forward(call, request)
        except Exception as err:  # a front end's fault fails this call, never the caller's
            logger.exception("service %s: forwarding a call failed", service.name)
            self.respond(call, f"service {service.name} failed: {err}", ok=False)
        return call

    def respond(self, call: PendingCall, values: Any, *, ok: bool) -> bool:
        """Answer ``call``'s caller with its provider's response; False if it ended already.

        ``values`` is the response (validated by the provider's front end) when ``ok``, else
        why the call failed.
        """
        if self.pending.get(call.id) is not call:
            return False  # answered, timed out or dropped before
        self._end(call, values, ok=ok)
        return True

    def expire(self, now: float) -> None:
        """Fail every call whose deadline has passed (timed out waiting for its provider)."""
        heap = self._deadlines
        while heap and heap[0][0] <= now:
            _deadline, _seq, call_id = heapq.heappop(heap)
            call = self.pending.get(call_id)
            if call is None:
                continue  # answered or dropped before its deadline
            text = f"service {call.service.name} timed out waiting for its provider"
            self._end(call, text, ok=False)
        if not self.pending:
            heap.clear()

    def drop_peer(self, peer: Peer) -> None:
        """Forget a peer that left: its calls (unanswered) and the services it still provides."""
        for call in list(self._by_caller.get(peer, {}).values()):
            self._forget(call)
        for name in [n for n, s in self.services.items() if s.provider is peer]:
            self.withdraw(peer, name)

    # -- internals ----------------------------------------------------------------------------

    def _run(self, peer: Peer, service: Service, request: Any) -> tuple[bool, Any]:
        handler = service.handler
        assert handler is not None
        token = caller.set(peer)
        try:
            return True, handler(request)
        except ServiceError as err:
            return False, str(err)
        except Exception as err:  # a handler bug must not break the connection
            logger.exception("service %s failed", service.name)
            return False, f"service {service.name} failed: {err}"
        finally:
            caller.reset(token)

    def _replace(self, name: str, service: Service) -> None:
        old = self.services.get(name)
        self.services[name] = service
        self.changes += 1
        if old is None:
            return
        self._fail_pending(old, f"service {name} was re-advertised by another provider")
        if old.provider is not None and old.provider is not service.provider and old.lost:
            old.lost(name)

    def _end(self, call: PendingCall, values: Any, *, ok: bool) -> None:
        self._forget(call)
        call.done(ok, values)

    def _forget(self, call: PendingCall) -> None:
        """Remove a waiting call from every index and end it in its caller's budget."""
        del self.pending[call.id]
        mine = self._by_caller.get(call.caller, {})
        mine.pop(call.id, None)
        if not mine:
            self._by_caller.pop(call.caller, None)
        theirs = self._by_service.get(call.service, {})
        theirs.pop(call.id, None)
        if not theirs:
            self._by_service.pop(call.service, None)
        if call.release is not None:
            call.release()

    def _fail_pending(self, service: Service, reason: str) -> None:
        for call in list(self._by_service.get(service, {}).values()):
            self._end(call, reason, ok=False)
