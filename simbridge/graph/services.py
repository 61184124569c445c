"""Services of the ROS graph: in-process handlers and services provided by clients.

Every ``call_service`` is answered with a ``service_response``, whatever happens: an unknown
service, a handler error, a timeout, a provider that unadvertised or disconnected all give
``result: false`` with the reason as ``values`` (rosbridge instead leaves some of these hanging:
#905, #1027). Calls never block the caller's other ops.

Replies from client providers (``service_response``) are routed back by the server-chosen id
``service_request:<service>:<n>``. Clients disagree on the reply shape (protocol reference
section 8, item 14), so simbridge reads it as follows (:meth:`Admission.response
<simbridge.rosbridge.admission.Admission.response>`, then :meth:`ServiceTable.respond`):

* ``values`` an object: success, whatever ``result`` says. This is rosbridge's behaviour (its
  ``service_response`` capability builds the ROS response from ``values`` and never reads
  ``result``), and what roslibpy's own test expects of a callback that fills the response and
  returns ``False``; the caller gets ``result: true`` and the values as JSON;
* ``result: true`` without ``values`` (or ``null``): success with ``{}``;
* otherwise failure: ``values`` as the reason when it is a string (roslibjs 2.1
  ``advertiseAsync`` sends the error text), else a sentence saying what came, with the values as
  JSON. rosbridge leaves the caller waiting in these cases.
"""

from __future__ import annotations

import heapq
import itertools
import logging
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from simbridge.errors import ConversionError, ProtocolError, ServiceError, TypeNotFoundError
from simbridge.graph.topics import BRIDGE_NODE, Peer
from simbridge.msgs import Converter, TypeRegistry, positional_args, short_type
from simbridge.rosbridge import Frame, OpId, json_frame, split_frame
from simbridge.rosbridge.ops import CallService, ServiceResponse


__all__ = [
    "Finish",
    "Handler",
    "PendingCall",
    "Prepare",
    "Service",
    "ServiceTable",
    "caller",
    "service_response",
    "typed_calls",
]

logger = logging.getLogger(__name__)

#: An in-process service: request -> response object. The request is the complete, validated
#: request message when the service type is known (admission validated it, see
#: :func:`typed_calls`), else ``args`` as sent (object, list or None). Raise
#: :class:`ServiceError` to answer ``result: false`` with the error text.
Handler = Callable[[Any], dict[str, Any]]
#: The client whose call an in-process handler is answering (None outside a call): handlers
#: whose answer depends on who asks (the e-stop's scope, ``/simbridge/access``) read it.
caller: ContextVar[Peer | None] = ContextVar("caller", default=None)
#: Turns ``(service type, args as sent)`` into the request to hand on, or raises
#: :class:`ServiceError`; ``None`` from it means "type unknown: pass args through unchanged".
Prepare = Callable[[str, Any], Any]
#: Checks and completes a client provider's response values: ``(service type, values)``.
Finish = Callable[[str, Any], Any]


def service_response(service: str, values: Any, *, result: bool, op_id: OpId | None) -> Frame:
    """Return a ``service_response`` frame (``id`` only when the request had one)."""
    body: dict[str, Any] = {
        "op": "service_response",
        "service": service,
        "values": values,
        "result": result,
    }
    if op_id is not None:
        body["id"] = op_id
    return json_frame(body)


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
    """One service: answered in process (``handler``) or by a client (``provider``)."""

    name: str
    type: str
    node: str
    handler: Handler | None = None
    provider: Peer | None = None
    #: The name as the provider wrote it in ``advertise_service`` (roslibjs routes by it).
    written: str = ""


@dataclass(eq=False, slots=True)
class PendingCall:
    """A call forwarded to a client provider, waiting for its ``service_response``."""

    server_id: str
    service: Service
    caller: Peer
    caller_id: OpId | None
    #: The service name as the caller wrote it (echoed in the reply).
    written: str
    deadline: float


class ServiceTable:
    """Every service, and the calls waiting for client providers."""

    def __init__(self, *, default_timeout: float = 5.0) -> None:
        #: Seconds to wait for a client provider when the call gives no ``timeout``.
        self.default_timeout = default_timeout
        #: Services by absolute name.
        self.services: dict[str, Service] = {}
        #: Bumped by every service added, replaced or removed (see ``TopicTable.changes``).
        self.changes = 0
        #: Calls forwarded to providers, by server id.
        self.pending: dict[str, PendingCall] = {}
        # the same calls by caller and by service, and their deadlines in a heap: answering,
        # expiring or dropping one never scans the others
        self._by_caller: dict[Peer, dict[str, PendingCall]] = {}
        self._by_service: dict[Service, dict[str, PendingCall]] = {}
        self._deadlines: list[tuple[float, int, str]] = []
        self._counter = itertools.count(1)
        self._fragments = itertools.count(1)

    def add(self, name: str, type_name: str, node: str, handler: Handler) -> Service:
        """Register an in-process service (replacing any previous one of that name)."""
        service = Service(name, type_name, node, handler=handler)
        self.services[name] = service
        self.changes += 1
        return service

    def advertise(self, peer: Peer, name: str, type_name: str, written: str = "") -> Service:
        """Make ``peer`` the provider of ``name``; a previous provider's pending calls fail.

        A client provider that loses the name to ``peer`` is told (its session disowns it).
        """
        old = self.services.get(name)
        if old is not None:
            self._fail_pending(old, f"service {name} was re-advertised by another provider")
            if old.provider is not None and old.provider is not peer:
                old.provider.session.disown("service", name)
        service = Service(name, type_name, BRIDGE_NODE, provider=peer, written=written or name)
        self.services[name] = service
        self.changes += 1
        return service

    def unadvertise(self, peer: Peer, name: str) -> bool:
        """Remove ``peer``'s service ``name``; return whether it was its provider."""
        service = self.services.get(name)
        if service is None or service.provider is not peer:
            return False
        del self.services[name]
        self.changes += 1
        self._fail_pending(service, f"service {name} was unadvertised by its provider")
        return True

    def call(
        self, peer: Peer, op: CallService, service: Service, request: Any, deadline: float | None
    ) -> None:
        """Answer an admitted ``call_service``: at once, or when the provider replies or times out.

        ``request`` is validated (admission); ``deadline`` is when a call to a client provider
        times out (the caller's session counted it as pending).
        """
        name = service.name
        if service.handler is not None:
            token = caller.set(peer)
            try:
                values: Any = service.handler(request)
                ok = True
            except ServiceError as err:
                values, ok = str(err), False
            except Exception as err:  # a handler bug must not break the connection
                logger.exception("service %s failed", name)
                values, ok = f"service {name} failed: {err}", False
            finally:
                caller.reset(token)
            self.reply(peer, service_response(op.service, values, result=ok, op_id=op.id))
            return
        provider = service.provider
        assert provider is not None and deadline is not None
        seq = next(self._counter)
        server_id = f"service_request:{name}:{seq}"
        call = PendingCall(server_id, service, peer, op.id, op.service, deadline)
        self.pending[server_id] = call
        self._by_caller.setdefault(peer, {})[server_id] = call
        self._by_service.setdefault(service, {})[server_id] = call
        heapq.heappush(self._deadlines, (deadline, seq, server_id))
        args = request if request is not None else {}
        provider.send(
            json_frame(
                {"op": "call_service", "id": server_id, "service": service.written, "args": args}
            )
        )

    def reply(self, peer: Peer, frame: Frame) -> None:
        """Send a response, in ``fragment`` pieces when the client asked for a fragment size."""
        size = peer.session.fragment_size
        if size is None or len(frame.data) <= size:
            peer.send(frame)
            return
        for piece in split_frame(frame, size, f"service_response:{next(self._fragments)}"):
            peer.send(piece)

    def answering(self, peer: Peer, op: ServiceResponse) -> PendingCall:
        """Return the call a provider's ``service_response`` answers.

        Raises:
            ProtocolError: no call waits under that id, or ``peer`` does not provide it.
        """
        call = self.pending.get(op.id) if isinstance(op.id, str) else None
        if call is None:
            msg = f"service_response for unknown or expired id {op.id!r} on {op.service}"
            raise ProtocolError(msg)
        if call.service.provider is not peer:
            msg = f"service_response for {op.id!r} from a client that does not provide it"
            raise ProtocolError(msg)
        return call

    def respond(self, call: PendingCall, values: Any, *, ok: bool) -> None:
        """Answer ``call``'s caller with a provider's response (admitted: read and validated)."""
        self._forget(call)
        self.reply(
            call.caller, service_response(call.written, values, result=ok, op_id=call.caller_id)
        )

    def expire(self, now: float) -> None:
        """Answer every call whose deadline has passed with a timeout failure."""
        heap = self._deadlines
        while heap and heap[0][0] <= now:
            _deadline, _seq, server_id = heapq.heappop(heap)
            call = self.pending.get(server_id)
            if call is None:
                continue  # answered or dropped before its deadline
            self._forget(call)
            self.reply(
                call.caller,
                service_response(
                    call.written,
                    f"service {call.service.name} timed out waiting for its provider",
                    result=False,
                    op_id=call.caller_id,
                ),
            )
        if not self.pending:
            heap.clear()

    def drop_peer(self, peer: Peer) -> None:
        """Forget the calls of a client that left (its services go with its session's effects)."""
        for call in list(self._by_caller.get(peer, {}).values()):
            self._forget(call)

    def _forget(self, call: PendingCall) -> None:
        """Remove a pending call from every index and end it in its caller's budget."""
        del self.pending[call.server_id]
        mine = self._by_caller.get(call.caller, {})
        mine.pop(call.server_id, None)
        if not mine:
            self._by_caller.pop(call.caller, None)
        theirs = self._by_service.get(call.service, {})
        theirs.pop(call.server_id, None)
        if not theirs:
            self._by_service.pop(call.service, None)
        call.caller.session.end_call()

    def _fail_pending(self, service: Service, reason: str) -> None:
        for call in list(self._by_service.get(service, {}).values()):
            self._forget(call)
            self.reply(
                call.caller,
                service_response(call.written, reason, result=False, op_id=call.caller_id),
            )
