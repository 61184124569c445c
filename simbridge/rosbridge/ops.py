"""rosbridge v2 operations as typed data, parsed and checked from decoded JSON objects.

Field names, types and defaults follow rosbridge_suite 2.1 (ROS 2) capabilities; see
``shared/reference/rosbridge-protocol.md`` section 2. Unlike rosbridge, a malformed op is not
dropped silently: :func:`parse_op` raises :class:`~simbridge.errors.ProtocolError` with a
rosbridge-style text ("Expected a topic field but none was found.") that the server sends back
to the client as a ``status`` message.

Ids (``id``) are opaque: a string or an integer, echoed back exactly as received.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, NewType, TypeAlias

from simbridge.errors import ProtocolError


__all__ = [
    "COMPRESSIONS",
    "OPS",
    "ActionFeedback",
    "ActionResult",
    "Advertise",
    "AdvertiseAction",
    "AdvertiseService",
    "Auth",
    "CallService",
    "CancelActionGoal",
    "ClientId",
    "Compression",
    "Fragment",
    "Op",
    "OpId",
    "Publish",
    "Refusal",
    "SendActionGoal",
    "ServiceResponse",
    "SetLevel",
    "Subscribe",
    "Unadvertise",
    "UnadvertiseAction",
    "UnadvertiseService",
    "Unsubscribe",
    "parse_op",
    "resolve_name",
]

#: Identifies one connected client for the lifetime of the process.
ClientId = NewType("ClientId", int)
#: An interaction id chosen by a client: echoed verbatim in replies.
OpId: TypeAlias = str | int
Compression = Literal["none", "png", "cbor", "cbor-raw"]
COMPRESSIONS: tuple[str, ...] = ("none", "png", "cbor", "cbor-raw")
_NAME = re.compile(r"^/?[A-Za-z_~][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*/?$")


def resolve_name(name: str, what: str = "topic") -> str:
    """Return the absolute ROS name of ``name`` relative to the root namespace.

    ``rosapi/topics`` becomes ``/rosapi/topics`` (roslibjs 2.1 sends relative names); a
    trailing slash is dropped. A NUL, a percent sign or any other character outside ROS names
    is refused here, once, for every op that names a topic, service or action.

    Raises:
        ProtocolError: not a valid ROS name.
    """
    if len(name) > 256 or not _NAME.match(name) or name in ("/", "~"):
        shown = name if len(name) <= 60 else name[:57] + "..."
        shown = shown.encode("unicode_escape").decode("ascii")  # a NUL shows as \x00
        msg = (
            f"{what} name '{shown}' is not a valid ROS name "
            "(letters, digits and underscores, separated by '/')"
        )
        raise ProtocolError(msg)
    name = name.rstrip("/")
    return name if name.startswith("/") else "/" + name


class Refusal(ProtocolError):
    """An op the server will not carry out, with what its answer needs.

    A ``call_service`` is answered with a failed ``service_response`` and a
    ``send_action_goal`` with a failed ``action_result`` (their callers wait for one); every
    other op with a ``status`` error. ``cause`` groups refusals for the status budget (one
    ``status`` per cause per second, see :meth:`Session.refused
    <simbridge.rosbridge.session.Session.refused>`).
    """

    def __init__(
        self,
        text: str,
        *,
        op: str = "",
        target: str = "",
        op_id: OpId | None = None,
        cause: str = "",
    ) -> None:
        super().__init__(text)
        #: The op refused (``"call_service"``...), or ``""`` when unknown.
        self.op = op
        #: The service or action as the client wrote it (echoed in the answer).
        self.target = target
        #: The client's id of the op.
        self.op_id = op_id
        #: What was exceeded or wrong (the budget's key), for rate-limiting the answers.
        self.cause = cause or text


def _named(obj: object, value: str, what: str = "topic") -> None:
    object.__setattr__(obj, "name", resolve_name(value, what))


@dataclass(frozen=True, slots=True)
class Advertise:
    """``advertise``: become a publisher of ``topic`` with message ``type``."""

    topic: str
    type: str
    id: OpId | None = None
    latch: bool = False
    queue_size: int = 100
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.topic)


@dataclass(frozen=True, slots=True)
class Unadvertise:
    """``unadvertise``: stop publishing (one advertise ``id``, or all of this client's)."""

    topic: str
    id: OpId | None = None
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.topic)


@dataclass(frozen=True, slots=True)
class Publish:
    """``publish``: send ``msg`` on ``topic`` (``type`` optional, as in rosbridge PR #1203)."""

    topic: str
    msg: Any
    id: OpId | None = None
    latch: bool = False
    type: str | None = None
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.topic)


@dataclass(frozen=True, slots=True)
class Subscribe:
    """``subscribe``: receive ``topic`` (type inferred when omitted)."""

    topic: str
    type: str | None = None
    id: OpId | None = None
    throttle_rate: int = 0
    queue_length: int = 0
    fragment_size: int | None = None
    compression: str = "none"
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.topic)


@dataclass(frozen=True, slots=True)
class Unsubscribe:
    """``unsubscribe``: drop one subscribe ``id``, or every subscription of the topic."""

    topic: str
    id: OpId | None = None
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.topic)


@dataclass(frozen=True, slots=True)
class CallService:
    """``call_service``: ``args`` is an object or a list (zipped onto the request fields)."""

    service: str
    args: dict[str, Any] | list[Any] | None = None
    id: OpId | None = None
    type: str | None = None
    timeout: float | None = None
    fragment_size: int | None = None
    compression: str = "none"
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.service, "service")


@dataclass(frozen=True, slots=True)
class AdvertiseService:
    """``advertise_service``: this client answers calls to ``service``."""

    service: str
    type: str
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.service, "service")


@dataclass(frozen=True, slots=True)
class UnadvertiseService:
    """``unadvertise_service``."""

    service: str
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.service, "service")


@dataclass(frozen=True, slots=True)
class ServiceResponse:
    """``service_response`` from a client provider; ``result`` may be missing or null."""

    service: str
    id: OpId | None = None
    values: Any = None
    result: bool | None = None
    has_values: bool = False


@dataclass(frozen=True, slots=True)
class AdvertiseAction:
    """``advertise_action``: this client serves goals of ``action``."""

    action: str
    type: str
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.action, "action")


@dataclass(frozen=True, slots=True)
class UnadvertiseAction:
    """``unadvertise_action``."""

    action: str
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.action, "action")


@dataclass(frozen=True, slots=True)
class SendActionGoal:
    """``send_action_goal``."""

    action: str
    action_type: str
    args: dict[str, Any] | list[Any] | None = None
    id: OpId | None = None
    feedback: bool = False
    fragment_size: int | None = None
    compression: str = "none"
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.action, "action")


@dataclass(frozen=True, slots=True)
class CancelActionGoal:
    """``cancel_action_goal`` of an in-flight goal ``id``."""

    action: str
    id: OpId | None = None
    #: The absolute name (resolved once, when the op is made).
    name: str = field(init=False, default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        _named(self, self.action, "action")


@dataclass(frozen=True, slots=True)
class ActionFeedback:
    """``action_feedback`` from a client action server."""

    action: str
    id: OpId | None = None
    values: Any = None


@dataclass(frozen=True, slots=True)
class ActionResult:
    """``action_result`` from a client action server."""

    action: str
    id: OpId | None = None
    values: Any = None
    status: int = 0
    result: bool | None = None


@dataclass(frozen=True, slots=True)
class Fragment:
    """``fragment``: piece ``num`` of ``total`` of a larger JSON message ``id``."""

    id: OpId
    data: str
    num: int
    total: int


@dataclass(frozen=True, slots=True)
class SetLevel:
    """``set_level``: the lowest ``status`` level this client wants to receive."""

    level: str
    id: OpId | None = None


@dataclass(frozen=True, slots=True)
class Auth:
    """``auth`` (rosauth, ROS 1 rosbridge): a MAC over the other fields."""

    mac: str
    client: str
    dest: str
    rand: str
    t: int
    level: str
    end: int


Op: TypeAlias = (
    Advertise
    | Unadvertise
    | Publish
    | Subscribe
    | Unsubscribe
    | CallService
    | AdvertiseService
    | UnadvertiseService
    | ServiceResponse
    | AdvertiseAction
    | UnadvertiseAction
    | SendActionGoal
    | CancelActionGoal
    | ActionFeedback
    | ActionResult
    | Fragment
    | SetLevel
    | Auth
)

_MISSING = object()
_FLOAT_MAX = sys.float_info.max


class _Reader:
    """Reads fields of one op with rosbridge's error texts."""

    __slots__ = ("obj", "op")

    def __init__(self, op: str, obj: dict[str, Any]) -> None:
        self.op = op
        self.obj = obj

    def _fail(self, field: str, kinds: str, value: object) -> ProtocolError:
        text = repr(value)
        if len(text) > 80:
            text = text[:77] + "..."
        msg = f"{self.op}: expected field {field} to be {kinds}; invalid value: {text}"
        return ProtocolError(msg)

    def text(self, field: str, *, required: bool = False, default: str | None = None) -> Any:
        value = self.obj.get(field, _MISSING)
        if value is _MISSING or (value is None and not required):
            if required:
                msg = f"{self.op}: expected a {field} field but none was found"
                raise ProtocolError(msg)
            return default
        if not isinstance(value, str):
            raise self._fail(field, "a string", value)
        if required and not value:
            msg = f"{self.op}: field {field} must not be empty"
            raise ProtocolError(msg)
        return value

    def id(self) -> OpId | None:
        value = self.obj.get("id")
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, str | int):
            raise self._fail("id", "a string or an integer", value)
        if isinstance(value, str) and "\x00" in value:
            msg = f"{self.op}: field id must not contain a NUL character (\\u0000)"
            raise ProtocolError(msg)
        return value

    def flag(self, field: str, default: bool) -> bool:
        value = self.obj.get(field)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise self._fail(field, "a boolean", value)
        return value

    def integer(self, field: str, default: int | None, lo: int = 0, hi: int = 2**31 - 1) -> Any:
        value = self.obj.get(field)
        if value is None:
            return default
        if isinstance(value, float) and value.is_integer():
            value = int(value)  # roslibjs may send 10.0 for 10; rosbridge rounds the same way
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._fail(field, "an integer", value)
        if not lo <= value <= hi:
            msg = f"{self.op}: field {field} = {value} is out of range [{lo}, {hi}]"
            raise ProtocolError(msg)
        return value

    def number(self, field: str) -> float | None:
        value = self.obj.get(field)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self._fail(field, "a number", value)
        if (isinstance(value, int) and abs(value) > _FLOAT_MAX) or not math.isfinite(value):
            raise self._fail(field, "a finite number", value)  # (a huge int: OverflowError)
        return float(value)

    def args(self, field: str) -> dict[str, Any] | list[Any] | None:
        value = self.obj.get(field)
        if value is None or isinstance(value, dict | list):
            return value
        raise self._fail(field, "an object or a list", value)

    def compression(self) -> str:
        value = self.text("compression", default="none")
        if value not in COMPRESSIONS:
            msg = (
                f"{self.op}: compression '{value}' is not supported; "
                f"use one of {', '.join(COMPRESSIONS)}"
            )
            raise ProtocolError(msg)
        return str(value)


def _advertise(r: _Reader) -> Op:
    return Advertise(
        topic=r.text("topic", required=True),
        type=r.text("type", required=True),
        id=r.id(),
        latch=r.flag("latch", False),
        queue_size=r.integer("queue_size", 100),
    )


def _publish(r: _Reader) -> Op:
    msg = r.obj.get("msg", {})
    if msg is None:
        msg = {}
    return Publish(
        topic=r.text("topic", required=True),
        msg=msg,
        id=r.id(),
        latch=r.flag("latch", False),
        type=r.text("type"),
    )


def _subscribe(r: _Reader) -> Op:
    return Subscribe(
        topic=r.text("topic", required=True),
        type=r.text("type") or None,
        id=r.id(),
        throttle_rate=r.integer("throttle_rate", 0, hi=86_400_000),
        queue_length=r.integer("queue_length", 0, hi=100_000),
        fragment_size=r.integer("fragment_size", None, lo=1),
        compression=r.compression(),
    )


def _call_service(r: _Reader) -> Op:
    service = r.text("service", required=True)
    try:
        resolve_name(service, "service")
    except ProtocolError as err:  # answered as a failed call: the caller waits for one
        raise Refusal(str(err), op="call_service", target=service, op_id=r.id()) from None
    return CallService(
        service=r.text("service", required=True),
        args=r.args("args"),
        id=r.id(),
        type=r.text("type"),
        timeout=r.number("timeout"),
        fragment_size=r.integer("fragment_size", None, lo=1),
        compression=r.text("compression", default="none"),
    )


def _service_response(r: _Reader) -> Op:
    result = r.obj.get("result")
    if result is not None and not isinstance(result, bool):
        raise r._fail("result", "a boolean", result)
    return ServiceResponse(
        service=r.text("service", required=True),
        id=r.id(),
        values=r.obj.get("values"),
        result=result,
        has_values="values" in r.obj,
    )


def _send_action_goal(r: _Reader) -> Op:
    action = r.text("action", required=True)
    try:
        resolve_name(action, "action")
    except ProtocolError as err:
        raise Refusal(str(err), op="send_action_goal", target=action, op_id=r.id()) from None
    return SendActionGoal(
        action=r.text("action", required=True),
        action_type=r.text("action_type", required=True),
        args=r.args("args"),
        id=r.id(),
        feedback=r.flag("feedback", False),
        fragment_size=r.integer("fragment_size", None, lo=1),
        compression=r.text("compression", default="none"),
    )


def _action_result(r: _Reader) -> Op:
    result = r.obj.get("result")
    if result is not None and not isinstance(result, bool):
        raise r._fail("result", "a boolean", result)
    return ActionResult(
        action=r.text("action", required=True),
        id=r.id(),
        values=r.obj.get("values"),
        status=r.integer("status", 0, hi=6),
        result=result,
    )


def _fragment(r: _Reader) -> Op:
    op_id = r.id()
    if op_id is None:
        msg = "fragment: expected an id field but none was found"
        raise ProtocolError(msg)
    total = r.obj.get("total")
    if isinstance(total, float) and math.isfinite(total):
        total = math.floor(total)  # rosbridge sends a float total (true division)
    if isinstance(total, bool) or not isinstance(total, int) or not 1 <= total <= 100_000:
        raise r._fail("total", "an integer from 1 to 100000", total)
    num = r.integer("num", None, hi=total - 1)
    if num is None:
        msg = "fragment: expected a num field but none was found"
        raise ProtocolError(msg)
    return Fragment(id=op_id, data=r.text("data", required=True), num=num, total=total)


def _auth(r: _Reader) -> Op:
    return Auth(
        mac=r.text("mac", required=True),
        client=r.text("client", default=""),
        dest=r.text("dest", default=""),
        rand=r.text("rand", default=""),
        t=r.integer("t", 0, hi=2**62),
        level=r.text("level", default=""),
        end=r.integer("end", 0, hi=2**62),
    )


OPS: dict[str, Callable[[_Reader], Op]] = {
    "advertise": _advertise,
    "unadvertise": lambda r: Unadvertise(topic=r.text("topic", required=True), id=r.id()),
    "publish": _publish,
    "subscribe": _subscribe,
    "unsubscribe": lambda r: Unsubscribe(topic=r.text("topic", required=True), id=r.id()),
    "call_service": _call_service,
    "advertise_service": lambda r: AdvertiseService(
        service=r.text("service", required=True), type=r.text("type", required=True)
    ),
    "unadvertise_service": lambda r: UnadvertiseService(service=r.text("service", required=True)),
    "service_response": _service_response,
    "advertise_action": lambda r: AdvertiseAction(
        action=r.text("action", required=True), type=r.text("type", required=True)
    ),
    "unadvertise_action": lambda r: UnadvertiseAction(action=r.text("action", required=True)),
    "send_action_goal": _send_action_goal,
    "cancel_action_goal": lambda r: CancelActionGoal(
        action=r.text("action", required=True), id=r.id()
    ),
    "action_feedback": lambda r: ActionFeedback(
        action=r.text("action", required=True), id=r.id(), values=r.obj.get("values")
    ),
    "action_result": _action_result,
    "fragment": _fragment,
    "set_level": lambda r: SetLevel(level=r.text("level", required=True), id=r.id()),
    "auth": _auth,
}


def parse_op(obj: object) -> Op:
    """Return the typed op of a decoded JSON message.

    Raises:
        ProtocolError: not an object, no ``op``, an unknown op, or a field of the wrong type.
    """
    if not isinstance(obj, dict):
        msg = f"a rosbridge message must be a JSON object, got {type(obj).__name__}"
        raise ProtocolError(msg)
    op = obj.get("op")
    if op is None:
        msg = "received a message without an op field"
        raise ProtocolError(msg)
    if not isinstance(op, str):
        msg = f"the op field must be a string, got {op!r}"
        raise ProtocolError(msg)
    parser = OPS.get(op)
    if parser is None:
        shown = op if len(op) <= 40 else op[:37] + "..."
        msg = f"unknown operation '{shown}'; allowed operations: {', '.join(OPS)}"
        raise ProtocolError(msg)
    return parser(_Reader(op, obj))
