"""rosbridge's service ops, each with its check and its action: protocol reference section 3.5.

* ``call_service``: refused (a failed ``service_response``: its caller waits for an answer)
  when the guard's rules say no (an administrative service without admin rights, another
  robot's service), when the service does not exist, or when ``args`` do not fit the request
  type (:func:`~simbridge.graph.services.typed_calls`: a list is zipped onto the fields in
  declaration order, defaults fill the rest); a call to a client provider counts against the
  client's pending-call budgets (:meth:`Session.call_service
  <simbridge.rosbridge.session.Session.call_service>`: ``max_pending_calls``,
  ``global_pending_calls``, the timeout capped by ``max_call_timeout``) until it ends. Every
  call is answered with a ``service_response``, whatever happens: an unknown service, a handler
  error, a timeout, a provider that unadvertised or disconnected all give ``result: false``
  with the reason as ``values`` (rosbridge instead leaves some of these hanging: #905, #1027),
  in ``fragment`` pieces when the client asked for a ``fragment_size``. Calls never block the
  caller's other ops.
* ``advertise_service``: refused for a name the server provides itself or outside the client's
  scope; the client becomes the service's provider (its session records it and the graph's
  table forwards calls to it as ``call_service`` ops with the server-chosen id
  ``service_request:<service>:<n>``). Another provider taking the name over is the session's
  to forget (:meth:`Session.disown <simbridge.rosbridge.session.Session.disown>`).
* ``unadvertise_service``: the client's own service only; its waiting calls fail.
* ``service_response``: routed back by id, from the provider of that call only. Clients
  disagree on the reply shape (protocol reference section 8, item 14), so simbridge reads it
  as follows (:meth:`ServiceOps._admit_response`):

  * ``values`` an object: success, whatever ``result`` says. This is rosbridge's behaviour (its
    ``service_response`` capability builds the ROS response from ``values`` and never reads
    ``result``), and what roslibpy's own test expects of a callback that fills the response
    and returns ``False``; the caller gets ``result: true`` and the values as JSON;
  * ``result: true`` without ``values`` (or ``null``): success with ``{}``;
  * otherwise failure: ``values`` as the reason when it is a string (roslibjs 2.1
    ``advertiseAsync`` sends the error text), else a sentence saying what came, with the values
    as JSON. rosbridge leaves the caller waiting in these cases.

  Values of a known response type are validated and completed; values that do not fit become a
  failed answer naming why.
"""

from __future__ import annotations

import itertools
import json
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Protocol

from simbridge.errors import ProtocolError, ServiceError
from simbridge.graph.graph import Graph
from simbridge.graph.services import PendingCall, Service, typed_calls
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.admission import Admission, Check, Typed, interface_type
from simbridge.rosbridge.encoding import Frame, json_frame
from simbridge.rosbridge.fragments import split_frame
from simbridge.rosbridge.ops import OpId, Refusal
from simbridge.rosbridge.session import Effect, Provided, Session, Withdrawn
from simbridge.rosbridge.subscribers import Client


__all__ = ["Call", "Response", "ServiceOps", "service_response"]

logger = logging.getLogger(__name__)

#: A handler of one admitted op: ``(peer, admitted, now)``.
Handler = Callable[[Client, Any, float], None]


class Front(Protocol):
    """What the service ops use of the front end (:class:`~simbridge.rosbridge.front.Rosbridge`)."""

    graph: Graph
    admission: Admission

    def apply(self, peer: Client, effects: Iterable[Effect]) -> None:
        """Carry out the effects a session returned for its client ``peer``."""


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


@dataclass(frozen=True, slots=True)
class Call:
    """An admitted ``call_service``: the service called and the request, validated."""

    op: o.CallService
    service: Service
    #: The complete request message when the service type is known, else ``args`` as sent.
    request: Any


@dataclass(frozen=True, slots=True)
class Response:
    """An admitted ``service_response``: the call it answers and the answer for its caller."""

    call: PendingCall
    ok: bool
    #: The response, validated and completed when the service type is known (``ok``), or why
    #: the call failed.
    values: Any


class ServiceOps:
    """The service ops of a graph's rosbridge clients (see the module doc)."""

    def __init__(self, front: Front) -> None:
        self.front = front
        #: The graph whose service table the clients call and provide.
        self.graph = front.graph
        self.table = front.graph.services
        #: Validate and complete requests and responses of known service types.
        self.prepare, self.finish = typed_calls(self.graph.registry, self.graph.converter)
        self._fragments = itertools.count(1)

    def checks(self) -> dict[type, Check]:
        """Return the admission checks of the service ops, by op class."""
        return {
            o.CallService: self._admit_call,
            o.AdvertiseService: self._admit_advertise,
            o.ServiceResponse: self._admit_response,
        }

    def handlers(self) -> dict[type, Handler]:
        """Return the handlers of the service ops, by op class."""
        return {
            o.CallService: self._call,
            o.AdvertiseService: self._advertise,
            o.UnadvertiseService: self._unadvertise,
            o.ServiceResponse: self._respond,
        }

    # -- answers ------------------------------------------------------------------------------

    def reply(self, peer: Client, frame: Frame) -> None:
        """Send a response, in ``fragment`` pieces when the client asked for a fragment size."""
        size = peer.session.fragment_size
        if size is None or len(frame.data) <= size:
            peer.send(frame)
            return
        for piece in split_frame(frame, size, f"service_response:{next(self._fragments)}"):
            peer.send(piece)

    def fail(self, peer: Client, service: str, text: str, op_id: OpId | None) -> None:
        """Answer a refused ``call_service`` (``service`` as the caller wrote it)."""
        self.reply(peer, service_response(service, text, result=False, op_id=op_id))

    # -- call_service -------------------------------------------------------------------------

    def _admit_call(self, peer: Client, session: Session, op: o.CallService, now: float) -> Call:
        """Return the call with its service and validated request.

        Raises:
            Refusal: the guard's rules refuse it, there is no such service, or ``args`` do not
                fit its request type (answered as a failed ``service_response``).
        """
        name = op.name
        rules = self.graph.access
        if rules.guarded:
            reason = None
            if rules.admin_only(name) and not session.admin:
                reason = (
                    f"service {name} is administrative: connect with the admin token "
                    "(?token=ADMIN_TOKEN) to call it"
                )
            elif not rules.may_reach(session.access, name):
                reason = f"service {name} belongs to another robot; this connection may not call it"
            if reason is not None:
                logger.info("%s: %s", peer.label, reason)
                raise Refusal(reason, op="call_service", target=op.service, op_id=op.id)
        service = self.table.services.get(name)
        if service is None:
            text = f"Service {name} does not exist"
            raise Refusal(text, op="call_service", target=op.service, op_id=op.id)
        request: Any = op.args
        try:
            prepared = self.prepare(service.type, op.args)
        except ServiceError as err:
            raise Refusal(str(err), op="call_service", target=op.service, op_id=op.id) from None
        if prepared is not None:
            request = prepared
        return Call(op, service, request)

    def _call(self, peer: Client, call: Call, now: float) -> None:
        """Call the service; the answer goes back to ``peer`` (a ``service_response``)."""
        op = call.op
        session = peer.session
        service = call.service
        waits = service.handler is None
        deadline = session.call_service(op, now, waits=waits, default=self.table.default_timeout)

        def done(ok: bool, values: Any) -> None:
            self.reply(peer, service_response(op.service, values, result=ok, op_id=op.id))

        release = session.end_call if waits else None
        self.table.call(
            peer,
            service,
            call.request,
            now if deadline is None else deadline,
            done,
            release=release,
        )

    # -- advertise_service, unadvertise_service -----------------------------------------------

    def _admit_advertise(
        self, peer: Client, session: Session, op: o.AdvertiseService, now: float
    ) -> Typed:
        """Return the ``advertise_service`` with its canonical type, if the client may make it.

        Raises:
            ProtocolError: the server provides the name itself, it lies outside the client's
                scope, the client owns too many names, or the type is malformed.
        """
        if self.graph.access.guarded:
            existing = self.table.services.get(op.name)
            if existing is not None and existing.handler is not None:
                msg = (
                    f"advertise_service {op.name}: refused, the server provides this service "
                    "itself; choose another name"
                )
                raise Refusal(msg, cause="server service")
            new = not session.provides("service", op.name)
            self.front.admission.may_own(session, "advertise_service", op.name, new)
        return Typed(op, interface_type(op.type, "srv", "advertise_service"))

    def _advertise(self, peer: Client, admitted: Typed, now: float) -> None:
        op, type_name = admitted.op, admitted.type
        assert type_name is not None
        effects = peer.session.provide("service", op.name, type_name, op.service)
        self.front.apply(peer, effects)  # Provided: :meth:`provided`

    def _unadvertise(self, peer: Client, op: o.UnadvertiseService, now: float) -> None:
        self.front.apply(peer, peer.session.withdraw("service", op.name))  # :meth:`withdrawn`

    def provided(self, peer: Client, effect: Provided) -> None:
        """Make the client the provider of the service its session recorded."""
        session = peer.session

        def forward(call: PendingCall, request: Any) -> None:
            args = request if request is not None else {}
            body = {"op": "call_service", "id": call.id, "service": effect.written, "args": args}
            peer.send(json_frame(body))

        def lost(name: str) -> None:
            session.disown("service", name)

        self.table.provide(
            peer, effect.name, effect.type, forward, lost=lost, written=effect.written
        )

    def withdrawn(self, peer: Client, effect: Withdrawn) -> None:
        """Remove the service the client's session no longer provides."""
        self.table.withdraw(peer, effect.name)

    # -- service_response ---------------------------------------------------------------------

    def _admit_response(
        self, peer: Client, session: Session, op: o.ServiceResponse, now: float
    ) -> Response:
        """Return the answer a provider's ``service_response`` gives its call's caller.

        Read as the module doc says; values of a known response type are validated and
        completed (values that do not fit are a failed answer, naming why).

        Raises:
            ProtocolError: no call waits under that id, or ``peer`` does not provide it.
        """
        call = self.table.pending.get(op.id) if isinstance(op.id, str) else None
        if call is None:
            msg = f"service_response for unknown or expired id {op.id!r} on {op.service}"
            raise ProtocolError(msg)
        if call.service.provider is not peer:
            msg = f"service_response for {op.id!r} from a client that does not provide it"
            raise ProtocolError(msg)
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
        if ok:
            try:
                values = self.finish(call.service.type, values)
            except ServiceError as err:
                ok, values = False, f"service provider sent an invalid response: {err}"
        return Response(call, ok, values)

    def _respond(self, peer: Client, response: Response, now: float) -> None:
        self.table.respond(response.call, response.values, ok=response.ok)
