"""Settings declared once, on pydantic: each field gives its bounds, description and option.

A setting is one annotated field of a :class:`Record` (a pydantic model)::

    max_clients: Annotated[Count, Option(group=SECURITY)] = Field(
        200, description="WebSocket clients at most; one more is refused with HTTP 503"
    )

That one declaration is the field of :class:`ServerSettings` with its bounds (``Count``: an
integer > 0) and its description; :class:`Option` makes it the command-line option
``--max-clients`` (help text: the description, the default and the variable) and the
environment variable ``SIMBRIDGE_MAX_CLIENTS`` (read by pydantic-settings, :func:`environment`);
:class:`Budget` makes a field one of the rosbridge budgets (:func:`budgets` builds
:class:`~simbridge.rosbridge.budget.Limits` and :class:`~simbridge.rosbridge.budget.Pool` from
those fields, with no hand mapping).

Every refusal is a :class:`SettingsError` naming the field path, the reason and the value, in
one line: ``robot.wheel_radius: must be greater than 0 (got -1)``. Values are read as files and
environment variables need them (numbers from numeric text, booleans from ``yes``/``off``/``1``),
but a boolean is never a number (``rays: yes`` is a mistake, not 1), ``"1e3"`` is not an integer,
numbers are finite, a string is not a boolean's spelling (YAML 1.1's ``off`` is refused for a
string field: quote it) and unknown keys are refused by name.
"""

from __future__ import annotations

import os
import types
import typing
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any, Literal, Self

import pydantic
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator
from pydantic.fields import FieldInfo
from pydantic_core import ErrorDetails

from simbridge.errors import ConfigError


if TYPE_CHECKING:
    from simbridge.rosbridge.budget import Limits, Pool


__all__ = [
    "FOXGLOVE",
    "SECURITY",
    "Budget",
    "Count",
    "Float",
    "Int",
    "Item",
    "Items",
    "LogLevel",
    "Option",
    "Port",
    "Rate",
    "Record",
    "RosDistro",
    "RunOptions",
    "Seconds",
    "ServerSettings",
    "SettingsError",
    "budgets",
    "environment",
    "options",
    "server_settings",
    "unknown_variables",
]


# -- errors: pydantic's refusals in simbridge's words -------------------------------------------


def _join(key: str, path: str) -> str:
    if not path:
        return key
    if not key:
        return path
    return f"{key}{path}" if path.startswith("[") else f"{key}.{path}"


class SettingsError(ConfigError, ValueError):
    """Values refused by a record: each with its field path and the reason.

    ``str(err)`` is every refusal, ``path: reason``, joined by ``"; "`` (a refusal of the whole
    record, a relation between fields, has no path). A ``ValueError`` (parameter services catch
    those) and a :class:`~simbridge.errors.ConfigError`.

    Attributes:
        errors: ``(path, reason)`` pairs: ``("robot.mass", "must be greater than 0 (got -1)")``,
            ``("walls[1]", ...)``; the path is ``""`` for the record as a whole.
    """

    def __init__(self, errors: Sequence[tuple[str, str]]) -> None:
        self.errors = list(errors)
        super().__init__(self.describe())

    def __reduce__(self) -> tuple[type[SettingsError], tuple[list[tuple[str, str]]]]:
        """Pickle by the refusals (an exception pickles its message otherwise, not ``errors``)."""
        return type(self), (self.errors,)

    @classmethod
    def one(cls, reason: str, path: str = "") -> SettingsError:
        """Return an error of one refusal."""
        return cls([(path, reason)])

    @classmethod
    def of(cls, err: pydantic.ValidationError) -> SettingsError:
        """Return pydantic's refusals as simbridge's (paths ``a.b[2]``, reasons in words)."""
        out: list[tuple[str, str]] = []
        short: dict[str, int] = {}  # a fixed-length list with items missing: path -> its length
        for e in err.errors():
            inner = e.get("ctx", {}).get("error")
            loc, value = e["loc"], e["input"]
            if isinstance(inner, SettingsError):  # a nested record's own (its __init__ is ours)
                out += inner.within(_path(loc)).errors
            elif e["type"] == "missing" and loc and isinstance(loc[-1], int):
                path = _path(loc[:-1])
                if path not in short:
                    out.append((path, ""))
                short[path] = max(short.get(path, 0), loc[-1] + 1)
                got = f"{len(value)}: {value!r}" if isinstance(value, list | tuple) else repr(value)
                reason = f"must have {short[path]} items (got {got})"
                out = [(p, reason if p == path else r) for p, r in out]
            else:
                out.append((_path(loc), _reason(e)))
        return cls(out)

    def describe(self, name: Callable[[str], str] = str) -> str:
        """Return the refusals as one line, each path shown as ``name(path)``."""
        return "; ".join(f"{name(p)}: {r}" if p else r for p, r in self.errors)

    def within(self, key: str) -> SettingsError:
        """Return this error with every path under ``key`` (``mass`` -> ``robot.mass``)."""
        return SettingsError([(_join(key, p), r) for p, r in self.errors])


def _path(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out = _join(out, f"[{part}]" if isinstance(part, int) else str(part))
    return out


def _number(value: Any) -> str:
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def _items(value: object) -> str:
    return "characters" if isinstance(value, str) else "items"


#: Reasons by pydantic error type: a format of the error's context (``ctx``).
_REASONS: dict[str, str] = {
    "greater_than": "must be greater than {gt}",
    "greater_than_equal": "must be greater than or equal to {ge}",
    "less_than": "must be less than {lt}",
    "less_than_equal": "must be less than or equal to {le}",
    "float_type": "must be a number",
    "float_parsing": "must be a number",
    "finite_number": "must be a finite number",
    "int_type": "must be a valid integer",
    "int_parsing": "must be a valid integer",
    "int_from_float": "must be a valid integer",
    "bool_type": "must be a valid boolean: true/false, yes/no, on/off or 1/0",
    "bool_parsing": "must be a valid boolean: true/false, yes/no, on/off or 1/0",
    "string_type": "must be a string",
    "literal_error": "must be {expected}",
    "list_type": "must be a list",
    "tuple_type": "must be a list",
    "dict_type": "must be a mapping",
    "model_type": "must be a mapping of keys",
    "model_attributes_type": "must be a mapping of keys",
}


def _reason(e: ErrorDetails) -> str:
    kind, ctx, value = e["type"], e.get("ctx", {}), e["input"]
    got = f" (got {value!r})"
    if kind in _REASONS:
        shown = {k: _number(v) for k, v in ctx.items()}
        return _REASONS[kind].format(**shown) + got
    if kind in ("too_short", "string_too_short"):
        if ctx.get("min_length") == 1:
            return f"must not be empty{got}"
        return f"must have at least {ctx.get('min_length')} {_items(value)}{got}"
    if kind in ("too_long", "string_too_long"):
        size = len(value) if hasattr(value, "__len__") else "more"
        return f"must have at most {ctx.get('max_length')} {_items(value)} (got {size})"
    if kind == "missing":
        return "required, but missing"
    if kind == "extra_forbidden":
        return "unknown key (check its spelling and nesting)"
    if kind == "invalid_key":
        return "keys must be names (strings)"
    if kind in ("frozen_instance", "frozen_field"):
        return "cannot be changed: these settings are frozen"
    if kind in ("value_error", "assertion_error") and "error" in ctx:
        return str(ctx["error"])
    return f"{e['msg']}{got}"


# -- value types: each bound written once, for fields, options and variables alike --------------


def _not_bool(value: Any) -> Any:
    """Refuse a boolean where a number is expected (Python's or numpy's ``bool_``)."""
    if isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b":
        msg = f"must be a number, not a boolean (got {value!r})"
        raise ValueError(msg)
    return value


#: A finite number (an int, a float or numeric text; never a boolean).
Float = Annotated[float, BeforeValidator(_not_bool)]
#: An integer (an int, a float without fraction or integer text; never a boolean or ``"1e3"``).
Int = Annotated[int, BeforeValidator(_not_bool)]
#: A TCP port; 0 picks a free one.
Port = Annotated[Int, Field(ge=0, le=65535)]
Count = Annotated[Int, Field(gt=0)]
Seconds = Annotated[Float, Field(gt=0)]
Rate = Annotated[Float, Field(gt=0)]
LogLevel = Literal["debug", "info", "warning", "error"]
#: The ROS 2 distributions whose middlewares simbridge matches (``simbridge.ros2.typehash``).
RosDistro = Literal["humble", "jazzy", "kilted"]


def _split(value: Any) -> Any:
    """Read a text of comma-separated items (an environment variable's) as their list.

    An empty item (``a,,b``, a trailing comma) stays, to be refused naming its place.
    """
    if isinstance(value, str):
        return [item.strip() for item in value.split(",")]
    return value


#: One item of a list-valued option: a text that is not empty.
Item = Annotated[str, Field(min_length=1)]
#: A list-valued option's items (a tuple: the settings are frozen); comma-separated as text.
Items = Annotated[tuple[Item, ...], BeforeValidator(_split)]


# -- records ------------------------------------------------------------------------------------


class Record(BaseModel):
    """Base of the settings records: a pydantic model that refuses in simbridge's words.

    Unknown keys are refused, numbers are finite, assignments are validated; construction,
    :meth:`parse` and assignment raise :class:`SettingsError` (never pydantic's own error).
    Relations between fields are ``@model_validator(mode="after")`` methods raising
    ``ValueError``.
    """

    # defer_build: a record's validator is built when first used, not at import (the task
    # records of a run that reads no task are never built: cold start 0.47 instead of 0.50 s,
    # 2.26 instead of 2.47 s in the Pi budget, bench.pi.cold_start)
    model_config = ConfigDict(
        extra="forbid", allow_inf_nan=False, validate_assignment=True, defer_build=True
    )

    def __init__(self, /, **values: Any) -> None:  # positional-only: a key may be ``self``
        try:
            super().__init__(**values)
        except pydantic.ValidationError as err:
            raise SettingsError.of(err) from None

    @classmethod
    def parse(cls, data: Mapping[str, Any]) -> Self:
        """Return a record of the keys of ``data`` (a YAML document, a JSON object).

        Raises:
            SettingsError: a key is unknown or missing, or a value is refused.
        """
        if not isinstance(data, Mapping):
            raise SettingsError.one(f"must be a mapping of keys (got {data!r})")
        bad = [k for k in data if not isinstance(k, str)]
        if bad:
            raise SettingsError([(repr(k), "keys must be names (strings)") for k in bad])
        try:
            return cls.model_validate(data)
        except pydantic.ValidationError as err:
            raise SettingsError.of(err) from None

    def __setattr__(self, name: str, value: Any) -> None:
        if name not in type(self).model_fields:
            raise SettingsError.one(f"{type(self).__name__} has no setting {name!r}", name)
        old, given = self.__dict__.get(name), set(self.model_fields_set)
        try:
            super().__setattr__(name, value)
        except pydantic.ValidationError as err:
            # a relation refused it after the value was set: the record keeps its old value
            self.__dict__[name] = old
            object.__setattr__(self, "__pydantic_fields_set__", given)
            raise SettingsError.of(err) from None

    @property
    def given(self) -> frozenset[str]:
        """The fields given at construction or assigned since (not left at their default)."""
        return frozenset(self.model_fields_set)

    def replace(self, **changes: Any) -> Self:
        """Return a copy with ``changes`` (validated as at construction).

        Raises:
            SettingsError: a change is refused.
        """
        kept = {name: getattr(self, name) for name in self.model_fields_set}
        return self.parse({**kept, **changes})

    def as_dict(self) -> dict[str, Any]:
        """Return the values by field name; nested records (also in lists) as dicts."""
        return self.model_dump()


# -- metadata of a field: its command-line option, its budget -----------------------------------

#: Option groups of ``simbridge --help``.
SECURITY = "security and limits (see docs/security.md)"
ZENOH = 'ROS 2 through Zenoh, as rmw_zenoh (needs: pip install "simbridge[zenoh]")'
DDS = 'ROS 2 through DDS, as rmw_fastrtps or rmw_cyclonedds (needs: pip install "simbridge[dds]")'
FOXGLOVE = (
    'Foxglove, Lichtblick and PlotJuggler natively (needs: pip install "simbridge[foxglove]")'
)


@dataclass(frozen=True, slots=True)
class Option:
    """Field metadata: the setting is a command-line option and an environment variable.

    The option is ``--<name>`` (``name`` defaults to the field's, ``_`` as ``-``) and the
    variable ``SIMBRIDGE_<NAME>``; its help is the field's description, its default and the
    variable. A boolean field is a flag (``--use-sim-time``). A list-valued field (a tuple, of
    :data:`Items`) takes one or more values and may be repeated (``--zenoh-connect A
    --zenoh-connect B``, ``--record-topics /odom /cmd_vel``); its variable holds them separated
    by commas, and the command line's replace the variable's.
    """

    name: str = ""
    metavar: str | None = None
    group: str | None = None
    #: Shown as the default instead of the field's (``None``: the field's default).
    default: str | None = None


@dataclass(frozen=True, slots=True)
class Budget:
    """Field metadata: the setting is a per-client limit or a shared pool of the rosbridge budgets.

    ``limit`` names the :class:`~simbridge.rosbridge.budget.Limits` field it sets, ``pool`` the
    :class:`~simbridge.rosbridge.budget.Pool` resource; ``at_most`` the setting that caps it
    (a frame is never longer than the largest message).
    """

    limit: str | None = None
    pool: str | None = None
    at_most: str | None = None


def _metadata(info: FieldInfo, kind: type[Any]) -> Any:
    return next((m for m in info.metadata if isinstance(m, kind)), None)


def _foxglove_scope(value: Any) -> Any:
    """The access of a Foxglove port: ``admin``, ``*`` or a robot name."""
    from simbridge.sim.parameters import ROBOT_NAME

    if (
        value is None
        or value in ("admin", "*")
        or (isinstance(value, str) and ROBOT_NAME.match(value))
    ):
        return value
    msg = f"{value!r} is not an access: give 'admin', '*' or a robot name (e.g. r1)"
    raise ValueError(msg)


def check_ros2_role(role: object) -> str | None:
    """Return ``role`` if it is a ROS 2 peers' role or None (``ServerSettings.ros2_role``).

    Raises:
        ValueError: it is not.
    """
    from simbridge.sim.parameters import check_robot_name

    if role is None:
        return None
    if isinstance(role, str) and role in ("none", "robots", "admin"):
        return role
    if isinstance(role, str) and role.startswith("robot:"):
        check_robot_name(role.removeprefix("robot:"))
        return role
    msg = f"{role!r} is not a ROS 2 role: use none, robot:NAME, robots or admin"
    raise ValueError(msg)


class ServerSettings(Record):
    """Network and limit settings of one simbridge process (most are command-line options).

    Validated like the files: ``ServerSettings(stall_timeout=-5)`` raises
    :class:`SettingsError` naming the field; :func:`server_settings` says they are settings.
    Frozen: validated once, never changed.
    """

    model_config = ConfigDict(frozen=True)

    host: Annotated[str, Option(default="0.0.0.0, every interface")] = Field(
        "0.0.0.0", description="address to listen on; 127.0.0.1 keeps it on this machine"
    )
    port: Annotated[Port, Option()] = Field(
        9090, description="rosbridge WebSocket port, ws://HOST:PORT/ (0 picks a free port)"
    )
    http_port: Annotated[Port | None, Option()] = Field(
        8080, description="HTTP port of the browser page and /healthz"
    )
    max_message_size: Annotated[Count, Option(group=SECURITY), Budget("fragment_bytes")] = Field(
        10_000_000,
        description="largest incoming message, bytes (rosbridge's max_message_size is 10 MB)",
    )
    max_queue_bytes: Count = Field(
        8_000_000,
        description="pending outgoing bytes per client before the oldest queued messages are "
        "dropped",
    )
    default_queue_length: Count = Field(
        100, description="pending messages per subscription when the client asked for 0"
    )
    service_timeout: Seconds = Field(
        5.0,
        description="seconds a service call may wait for a client provider when the call "
        "gives no timeout",
    )
    ping_interval: Annotated[Seconds | None, Option(group=SECURITY)] = Field(
        20.0,
        description="keepalive ping every this many seconds; a peer that does not answer "
        "within as long is dropped",
    )
    ping_timeout: Seconds | None = Field(
        20.0, description="seconds a keepalive ping may wait for its pong (None disables)"
    )
    admin_token: Annotated[
        str | None, Option(metavar="TOKEN", default="none, every admin change is refused")
    ] = Field(
        None,
        description="token the instructor's page http://HOST:HTTP-PORT/admin and the "
        "administrative services need for every change",
    )
    use_sim_time: Annotated[bool, Option()] = Field(
        False,
        description="stamp headers with the simulated time published on /clock instead of the "
        "wall clock (as ROS nodes with use_sim_time:=true expect)",
    )
    demo_nodes: Annotated[bool, Option()] = Field(
        False,
        description="also run the ROS tutorial nodes: talker/listener on /chatter, "
        "/add_two_ints, the /fibonacci action (ROS 2 and ROS 1 actionlib); or demo_nodes: "
        "true in the world file",
    )
    # -- reliability and security (docs/security.md) --
    max_clients: Annotated[Count, Option(group=SECURITY)] = Field(
        200, description="WebSocket clients at most; one more is refused with HTTP 503"
    )
    max_http_connections: Annotated[Count, Option(group=SECURITY)] = Field(
        256,
        description="open connections of the HTTP port at most (page, /healthz, /admin); when "
        "all are busy one more is refused with 503, else the longest-idle one is closed for it",
    )
    max_http_connections_per_address: Annotated[Count, Option(group=SECURITY)] = Field(
        16,
        description="open connections of the HTTP port from one client address (an IPv6 "
        "address: its /64) at most; a request with the admin token always gets in",
    )
    max_subscriptions: Annotated[Count, Budget("subscriptions")] = Field(
        200, description="subscribed topic spellings per client at most"
    )
    max_advertisements: Annotated[Count, Budget("advertisements")] = Field(
        100, description="advertised topics, services and actions per client at most"
    )
    max_subscribe_ids: Annotated[Count, Budget("subscribe_ids")] = Field(
        1_000, description="subscribe ids of one client over every topic"
    )
    max_ids_per_subscription: Annotated[Count, Budget("ids_per_subscription")] = Field(
        100, description="subscribe ids of one client on one topic"
    )
    global_subscribe_ids: Annotated[Count, Budget(pool="subscribe_ids")] = Field(
        20_000, description="subscribe ids of all clients together"
    )
    max_advertise_ids: Annotated[Count, Budget("advertise_ids")] = Field(
        1_000, description="advertise ids of one client over every topic"
    )
    global_advertise_ids: Annotated[Count, Budget(pool="advertise_ids")] = Field(
        20_000, description="advertise ids of all clients together"
    )
    max_pending_calls: Annotated[Count, Budget("pending_calls")] = Field(
        100, description="calls of one client waiting for a client provider"
    )
    global_pending_calls: Annotated[Count, Budget(pool="pending_calls")] = Field(
        2_000, description="calls of all clients waiting for a client provider"
    )
    max_call_timeout: Annotated[Seconds, Budget("call_timeout")] = Field(
        60.0, description="longest wait of a call for a client provider, s (timeout: 0 too)"
    )
    max_fragment_sets: Annotated[Count, Budget("fragment_sets")] = Field(
        16,
        description="incomplete fragmented messages per client (their bytes: at most "
        "max_message_size per client, global_fragment_bytes for all)",
    )
    global_fragment_bytes: Annotated[Count, Budget(pool="fragment_bytes")] = Field(
        40_000_000, description="bytes of incomplete fragments of all clients together"
    )
    max_frame_bytes: Annotated[Count, Budget("frame_bytes", at_most="max_message_size")] = Field(
        1_000_000,
        description="length of one frame (or reassembled fragmented message) of a client "
        "without the admin token, at most max_message_size; longer ones are refused before "
        "parsing",
    )
    max_frame_values: Annotated[Count, Budget("frame_values")] = Field(
        100_000,
        description="JSON values in one frame of a client without the admin token, each "
        "object counting 32 and each array 4; more are refused before parsing",
    )
    max_latched_bytes: Annotated[Count, Budget("latched_bytes")] = Field(
        16_000_000, description="bytes of latched messages (JSON) one client's publishes leave"
    )
    global_latched_bytes: Annotated[Count, Budget(pool="latched_bytes")] = Field(
        64_000_000, description="bytes of latched messages of all clients together"
    )
    statuses_per_second: Annotated[Count, Budget("statuses_per_second")] = Field(
        10, description="status refusals per client per second (one per cause); the rest counted"
    )
    client_work_share: Annotated[Float, Budget("work_share")] = Field(
        0.25, gt=0, le=1, description="share of the loop's time one client's frames may take"
    )
    publish_rate: Annotated[Rate, Budget("publish_rate")] = Field(
        200.0, description="sustained publish ops per second per client"
    )
    publish_burst: Annotated[Count, Budget("publish_burst")] = Field(
        400, description="publish ops one client may send at once above publish_rate"
    )
    message_rate: Rate = Field(
        1000.0, description="sustained incoming WebSocket messages per second per client"
    )
    message_burst: Count = Field(
        2000, description="incoming WebSocket messages at once above message_rate"
    )
    stall_timeout: Annotated[Seconds | None, Option(group=SECURITY)] = Field(
        30.0,
        description="disconnect a client that reads nothing for this many seconds while "
        "messages wait for it",
    )
    auth_timeout: Seconds = Field(
        5.0,
        description="seconds a connection that owes a token has to authenticate with the "
        "auth op; then it is closed",
    )
    max_unauthenticated: Count = Field(
        20,
        description="connections that owe a token, at most at once (their own pool, apart "
        "from max_clients)",
    )
    tf_requests_per_client: Count = Field(
        10, description="TF requests (/republish_tfs topics, tf2_web_republisher goals) per client"
    )
    tf_transforms_per_client: Rate = Field(
        1000.0, description="transforms a second one client's TF requests may send"
    )
    tf_transforms_total: Rate = Field(
        10000.0, description="transforms a second all clients' TF requests may send"
    )
    tf_max_timeout: Seconds = Field(
        60.0, description="longest timeout of a /republish_tfs topic without subscribers, s"
    )
    # -- issue 29: what a client makes the server hold, in length, count and age (docs/security.md,
    # "Ids, goals, answers, latches and tokens") --
    max_id_length: Annotated[Count, Budget("id_length")] = Field(
        1_000,
        description="length of an op's id (characters of a string, digits of an integer); a "
        "longer one is refused",
    )
    max_pending_goals: Annotated[Count, Budget("pending_goals")] = Field(
        100, description="goals of one client in flight"
    )
    global_pending_goals: Annotated[Count, Budget(pool="pending_goals")] = Field(
        2_000, description="goals of all clients in flight"
    )
    max_goal_timeout: Annotated[Seconds, Budget("goal_timeout")] = Field(
        600.0,
        description="longest a goal to an action that a client serves waits for its result, s "
        "(then it is aborted)",
    )
    max_parameter_names: Count = Field(
        1_000, description="names (parameters, prefixes) in one request to parameter services"
    )
    max_estop_latches: Count = Field(
        200,
        description="e-stop latches kept at once; past it a stop of robots already held is "
        "answered without a new latch",
    )
    max_connections_per_token: Count = Field(
        20,
        description="WebSocket connections of one token at once (they share one "
        "client_work_share; admin connections do not count in max_clients)",
    )
    client_tokens: dict[str, str] = Field(
        default_factory=dict,
        description="client tokens (?token=): token -> scope, '*' (any topic) or a robot name "
        "(publish only under /<name>/); empty: no client tokens",
    )
    auth_secret: str | None = Field(
        None, description="rosauth shared secret for the auth op (None: the op is refused)"
    )
    auth_time_delta: Seconds = Field(
        5.0, description="seconds of clock difference an auth op's t may have"
    )
    allowed_origins: tuple[str, ...] | None = Field(
        None, description="allowed Origin headers of WebSocket upgrades (None: any)"
    )
    certfile: Annotated[str | None, Option(metavar="PEM", group=SECURITY)] = Field(
        None, description="TLS certificate chain: serve wss:// and https://"
    )
    keyfile: Annotated[
        str | None, Option(metavar="PEM", group=SECURITY, default="in the certfile")
    ] = Field(None, description="TLS private key")
    # -- ROS 2 peers (--zenoh; docs/security.md "ROS 2 peers") --
    ros2_role: Annotated[
        str | None,
        BeforeValidator(check_ros2_role),
        Option(
            metavar="ROLE",
            group=ZENOH,
            default="as a client without a token, none once client tokens are set",
        ),
    ] = Field(
        None,
        description="what ROS 2 peers may do: none (read only), robot:NAME (drive robot NAME), "
        "robots (drive every robot), admin (everything: a trusted network only)",
    )
    zenoh_max_sample_bytes: Count = Field(
        1_000_000, description="bytes of one Zenoh sample at most; bigger ones are dropped"
    )
    zenoh_inbox_bytes: Count = Field(
        16_000_000,
        description="bytes of Zenoh samples waiting for the event loop at most (past it, the "
        "oldest are dropped)",
    )
    zenoh_max_remote_tokens: Count = Field(
        20_000, description="liveliness tokens of other processes kept at most"
    )
    # -- ROS 2 over DDS (--dds, the [dds] extra; docs/dds.md) --
    dds_max_sample_bytes: Count = Field(
        1_000_000,
        description="bytes of one DDS sample from another participant at most; bigger ones are "
        "dropped",
    )
    dds_inbox_bytes: Count = Field(
        16_000_000,
        description="bytes of DDS samples waiting for the event loop at most (past it, new "
        "ones are dropped)",
    )
    dds_max_remote_endpoints: Count = Field(
        20_000,
        description="writers and readers of other participants kept at most (each) from DDS "
        "discovery",
    )
    # -- the Foxglove WebSocket protocol (the [foxglove] extra) --
    foxglove_port: Annotated[Port | None, Option(group=FOXGLOVE, default="off")] = Field(
        None,
        description="also serve the Foxglove WebSocket protocol (foxglove.sdk.v1) on this port, "
        "e.g. 8765: ws://HOST:8765 in Foxglove, Lichtblick or PlotJuggler",
    )
    foxglove_scope: Annotated[
        str | None,
        BeforeValidator(_foxglove_scope),
        Option(metavar="ACCESS", group=FOXGLOVE, default="what a client without a token gets"),
    ] = Field(
        None,
        description="what every Foxglove client may do: admin, * or a robot name; the protocol "
        "carries no token, so with --client-tokens the port opens only with this",
    )
    foxglove_max_clients: Annotated[Count, Option(metavar="N", group=FOXGLOVE)] = Field(
        200,
        description="connections of the Foxglove port at most; one past it is closed naming this",
    )
    # -- grading (simbridge.grading): tasks, and the journal of the class's attempts --
    results_file: Annotated[
        str | None, Option("results", metavar="FILE", default="none, results are lost on restart")
    ] = Field(
        None,
        description="the class's grading results: a journal of JSON lines, appended and read "
        "back at start (the runs' bags go beside it, in <name>-bags/)",
    )
    tasks_dir: Annotated[
        str | None, Option("tasks", metavar="DIR", default="the bundled config/tasks")
    ] = Field(None, description="directory of the instructor's task files (*.yaml)")
    grading_max_attempts: Count = Field(
        200,
        description="attempts one robot may have in the results (~15 kB each); past it a start "
        "is refused naming this setting",
    )

    @model_validator(mode="after")
    def _foxglove_in_a_class(self) -> Self:
        """Check that a Foxglove port in a class was opened on purpose (``foxglove_scope``)."""
        if self.foxglove_port is not None and self.auth_required and self.foxglove_scope is None:
            msg = (
                "foxglove_port: the Foxglove protocol carries no token, so in a class (client "
                "tokens or an auth secret) the port stays closed; open it for every Foxglove "
                "client with foxglove_scope (--foxglove-scope admin, * or a robot name)"
            )
            raise ValueError(msg)
        return self

    @property
    def auth_required(self) -> bool:
        """Whether clients must authenticate (a client token or a rosauth MAC)."""
        return bool(self.client_tokens) or self.auth_secret is not None


def server_settings(**values: Any) -> ServerSettings:
    """Return validated :class:`ServerSettings`.

    Raises:
        ConfigError: a value is out of its bounds or of the wrong type, or a name is unknown;
            the text names each (``settings: stall_timeout: must be greater than 0 (got -5)``).
    """
    try:
        return ServerSettings(**values)
    except SettingsError as err:
        raise ConfigError(f"settings: {err}") from None


def budgets(settings: ServerSettings) -> tuple[Limits, Pool]:
    """Return the per-client limits and the shared pool that ``settings`` ask for.

    Each comes from the fields declared with a :class:`Budget`; a limit with ``at_most`` is
    capped by that setting.
    """
    from simbridge.rosbridge.budget import Limits, Pool  # here: check-config needs no protocol

    limits: dict[str, Any] = {}
    pool: dict[str, int] = {}
    for name, info in type(settings).model_fields.items():
        budget = _metadata(info, Budget)
        if budget is None:
            continue
        value = getattr(settings, name)
        if budget.at_most is not None:
            value = min(value, getattr(settings, budget.at_most))
        if budget.limit is not None:
            limits[budget.limit] = value
        if budget.pool is not None:
            pool[budget.pool] = value
    return Limits(**limits), Pool(pool)


# -- the command line and the environment: generated from the fields with an Option -------------


class RunOptions(Record):
    """The options of ``simbridge`` that are not server settings one for one.

    Files to read (the world, the parameters, client tokens, the rosauth secret), what to run
    (no simulation, Zenoh, a recording) and the log level. Declared like the settings: each
    field with an :class:`Option` is an option and a ``SIMBRIDGE_*`` variable.
    """

    world: Annotated[str | None, Option(metavar="FILE", default="the bundled default.yaml")] = (
        Field(None, description="world file (YAML: walls, obstacles, robot start pose)")
    )
    params: Annotated[
        str | None,
        Option(
            metavar="FILE", default="the bundled pi4b_params.yaml, the Raspberry Pi 4B platform"
        ),
    ] = Field(None, description="robot and LiDAR parameter file (YAML)")
    client_tokens: Annotated[str | None, Option(metavar="FILE", group=SECURITY)] = Field(
        None,
        description="YAML file 'tokens: {TOKEN: ROBOT}': clients must connect with "
        "?token=TOKEN and may command only their robot (see "
        "config/classroom_tokens.example.yaml)",
    )
    auth_secret_file: Annotated[str | None, Option(metavar="FILE", group=SECURITY)] = Field(
        None,
        description="file holding a rosauth secret (one line): clients may authenticate with "
        "the rosbridge 'auth' op",
    )
    allowed_origins: Annotated[
        str | None, Option(metavar="LIST", group=SECURITY, default="any")
    ] = Field(
        None,
        description="comma-separated Origins whose pages may connect, e.g. https://pi.local:8080",
    )
    zenoh: Annotated[bool, Option(group=ZENOH)] = Field(
        False,
        description="join the ROS 2 graph as an rmw_zenoh node does: peer, router "
        "tcp/localhost:7447, domain ROS_DOMAIN_ID (default 0); ZENOH_SESSION_CONFIG_URI and "
        "ZENOH_CONFIG_OVERRIDE apply as for rmw_zenoh",
    )
    zenoh_connect: Annotated[Items, Option(metavar="ENDPOINT", group=ZENOH)] = Field(
        (), description="connect to this Zenoh endpoint instead, e.g. tcp/192.168.1.10:7447"
    )
    zenoh_listen: Annotated[Items, Option(metavar="ENDPOINT", group=ZENOH)] = Field(
        (), description="listen on this Zenoh endpoint instead of tcp/localhost:0"
    )
    ros_distro: Annotated[
        RosDistro | None, Option(group=ZENOH, default="$ROS_DISTRO, else jazzy")
    ] = Field(
        None,
        description="match this distribution's rmw_zenoh and DDS middlewares: humble has no "
        "type hashes (and 24-byte GIDs over DDS), jazzy and kilted use RIHS01",
    )
    dds: Annotated[bool, Option(group=DDS)] = Field(
        False,
        description="join the ROS 2 graph over DDS as a default ROS 2 install does: domain "
        "ROS_DOMAIN_ID (default 0), ROS_LOCALHOST_ONLY and ROS_AUTOMATIC_DISCOVERY_RANGE "
        "honoured; --ros2-role and --ros-distro apply",
    )
    no_sim: Annotated[bool, Option()] = Field(
        False,
        description="run the bridge alone, without the simulated world and robot (with "
        "--zenoh: a rosbridge in front of ROS 2 nodes, or a classroom front-end)",
    )
    no_http: Annotated[bool, Option()] = Field(
        False,
        description="do not serve HTTP on a port of its own (the WebSocket port still answers "
        "/healthz and the page)",
    )
    record: Annotated[str | None, Option(metavar="DIR")] = Field(
        None,
        description="record topics into the rosbag2 MCAP bag DIR while serving (finished on stop)",
    )
    record_topics: Annotated[
        Items | None, Option(metavar="TOPIC", default="every topic, also later ones")
    ] = Field(None, description="topics --record records")
    log_level: Annotated[LogLevel, Option()] = Field("info", description="log verbosity")


@dataclass(frozen=True, slots=True)
class Declared:
    """One option of the command line, as a field declares it."""

    #: The field's name (``results_file``) and the option's (``results``: ``--results``).
    field: str
    name: str
    info: FieldInfo
    option: Option

    @property
    def flag(self) -> str:
        """The option, ``--max-clients``."""
        return "--" + self.name.replace("_", "-")

    @property
    def variable(self) -> str:
        """The environment variable, ``SIMBRIDGE_MAX_CLIENTS``."""
        return f"SIMBRIDGE_{self.name.upper()}"

    @property
    def kind(self) -> Any:
        """The field's type with its bounds (``Annotated[int, ...]``), for checking one value."""
        extra = [m for m in self.info.metadata if not isinstance(m, Option | Budget)]
        return Annotated[(self.info.annotation, *extra)] if extra else self.info.annotation

    @property
    def flag_only(self) -> bool:
        """Whether the option is a flag (a boolean field)."""
        return self.info.annotation is bool

    @property
    def item(self) -> Any | None:
        """A list-valued option's item type with its bounds; None for a single value."""
        kind = _unwrap_optional(self.info.annotation)
        if typing.get_origin(kind) is Annotated:
            kind = typing.get_args(kind)[0]
        if typing.get_origin(kind) is tuple:
            return typing.get_args(kind)[0]
        return None

    @property
    def metavar(self) -> str | None:
        """How the value is shown: the declared metavar, ``N`` for integers, or the choices."""
        if self.option.metavar is not None:
            return self.option.metavar
        kind = _unwrap_optional(self.info.annotation)
        if typing.get_origin(kind) is Annotated:
            kind = typing.get_args(kind)[0]
        if typing.get_origin(kind) is Literal:
            return "{" + ",".join(str(a) for a in typing.get_args(kind)) + "}"
        return "N" if kind is int else None

    def help(self) -> str:
        """The option's help: the description, the default and the variable.

        A list-valued option says it is repeatable and that its variable's items are
        comma-separated.
        """
        default = self.option.default
        listed = self.item is not None
        if default is None and not (self.flag_only or listed) and self.info.default is not None:
            default = _number(self.info.default)
        notes = [f"default: {default}"] if default else []
        notes += ["repeatable"] if listed else []
        shown = f" ({'; '.join(notes)})" if notes else ""
        variable = f"{self.variable}, comma-separated" if listed else self.variable
        return f"{self.info.description}{shown} [{variable}]"


def _unwrap_optional(kind: Any) -> Any:
    """Return ``X`` of ``X | None``, else ``kind``."""
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        return next(a for a in typing.get_args(kind) if a is not type(None))
    return kind


def options(*models: type[Record]) -> Iterator[Declared]:
    """Yield the options that the fields of ``models`` declare, in declaration order."""
    for model in models:
        for name, info in model.model_fields.items():
            option = _metadata(info, Option)
            if option is not None:
                yield Declared(name, option.name or name, info, option)


def check(declared: Declared, text: str) -> Any:
    """Return ``text`` read as one value of the option ``declared`` (of a list: one item).

    Raises:
        SettingsError: it is not such a value (the reason in the settings' own words).
    """
    kind = declared.kind if declared.item is None else declared.item
    adapter: pydantic.TypeAdapter[Any] = pydantic.TypeAdapter(
        kind, config=ConfigDict(allow_inf_nan=False)
    )
    try:
        return adapter.validate_python(text)
    except pydantic.ValidationError as err:
        raise SettingsError.of(err) from None


#: ``SIMBRIDGE_*`` variables that are not the server's options: the command-line tools' (the
#: server to reach, a grader's robot, token and goal; ``simbridge healthcheck``'s URL), the
#: image's build argument (Docker gives it to the build's ``check-config``), the benchmarks'
#: (the checkouts compared) and the test suite's ``SIMBRIDGE_TEST_*``.
OTHER_VARIABLES = (
    "SIMBRIDGE_URL",
    "SIMBRIDGE_TOKEN",
    "SIMBRIDGE_ROBOT",
    "SIMBRIDGE_GOAL",
    "SIMBRIDGE_HEALTHCHECK_URL",
    "SIMBRIDGE_EXTRAS",
    "SIMBRIDGE_BASELINE",
    "SIMBRIDGE_TREE",
)
OTHER_PREFIX = "SIMBRIDGE_TEST_"


def unknown_variables(environ: Mapping[str, str] | None = None) -> list[str]:
    """Say which ``SIMBRIDGE_*`` variables of ``environ`` no option reads (a typo, most often).

    One line each, with the closest option's variable when there is one, e.g.
    ``SIMBRIDGE_MAX_CLIENT is not a setting (did you mean SIMBRIDGE_MAX_CLIENTS?): ignored``.
    """
    import difflib

    source = os.environ if environ is None else environ
    known = [d.variable for d in options(ServerSettings, RunOptions)]
    lines = []
    for name, value in sorted(source.items()):
        if not name.startswith("SIMBRIDGE_") or name.startswith(OTHER_PREFIX):
            continue
        if not value.strip():
            continue  # blank: unset, as for the options
        if name in known or name in OTHER_VARIABLES:
            continue
        # compared without the prefix they share, which would make any two names look alike
        close = difflib.get_close_matches(name[10:], [k[10:] for k in known], n=1, cutoff=0.75)
        hint = f" (did you mean SIMBRIDGE_{close[0]}?)" if close else ""
        lines.append(f"{name} is not a setting{hint}: ignored")
    return lines


def environment(environ: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Return the ``SIMBRIDGE_*`` variables of ``environ`` (``os.environ``), validated.

    Keys are the options' names (``max_clients``, ``results``); unset, empty and blank variables
    are left out (the option's default applies). Read by pydantic-settings, each variable with
    its option's type and bounds; a list-valued option's variable holds its items separated by
    commas (``SIMBRIDGE_ZENOH_CONNECT=tcp/10.0.0.1:7447,tcp/10.0.0.2:7447``), not JSON.

    Raises:
        ConfigError: a variable's value is invalid; the text names the variable, the value
            and the bound, e.g. ``environment variable SIMBRIDGE_STALL_TIMEOUT: must be
            greater than 0 (got '-5')``.
    """
    source = os.environ if environ is None else environ
    # blank values count as unset, as compose's ${VAR:-} gives them
    given = {k: v for k, v in source.items() if k.startswith("SIMBRIDGE_") and v.strip()}
    if not given:
        return {}  # pydantic-settings (and the asyncio it imports) only when there is one
    from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict
    from pydantic_settings.sources import EnvSettingsSource

    declared = {d.name: d for d in options(ServerSettings, RunOptions)}

    class Variables(EnvSettingsSource):
        def _load_env_vars(self) -> Mapping[str, str | None]:
            return {k.lower(): v for k, v in given.items()}

    class Environment(BaseSettings):
        # enable_decoding off: a list is comma-separated text (Items), not JSON
        model_config = SettingsConfigDict(
            env_prefix="SIMBRIDGE_",
            extra="ignore",
            allow_inf_nan=False,
            frozen=True,
            enable_decoding=False,
        )

        @classmethod
        def settings_customise_sources(
            cls,
            settings_cls: type[BaseSettings],
            init_settings: PydanticBaseSettingsSource,
            env_settings: PydanticBaseSettingsSource,
            dotenv_settings: PydanticBaseSettingsSource,
            file_secret_settings: PydanticBaseSettingsSource,
        ) -> tuple[PydanticBaseSettingsSource, ...]:
            return (Variables(settings_cls),)

    fields: dict[str, Any] = {name: (d.kind | None, None) for name, d in declared.items()}
    model = pydantic.create_model("Environment", __base__=Environment, **fields)
    try:
        values = model()
    except pydantic.ValidationError as err:

        def variable(path: str) -> str:  # zenoh_connect[1]: SIMBRIDGE_ZENOH_CONNECT[1]
            name, _, rest = path.partition("[")
            where = f"[{rest}" if rest else ""
            return f"environment variable {declared[name.partition('.')[0]].variable}{where}"

        text = SettingsError.of(err).describe(variable)
        raise ConfigError(text) from None
    return {name: getattr(values, name) for name in values.model_fields_set}
