"""The ROS 2 interface-type registry, built on the rosbags type store.

Type names are accepted as ``pkg/Type`` and ``pkg/msg/Type`` (rosbridge accepts both; rosapi
answers with ``pkg/msg/Type``). Definitions come from rosbags (every standard ROS 2 message);
nothing here hand-writes a message definition. Further interface definitions (services, actions,
simbridge's own) are registered from ``.msg``/``.srv`` text with :meth:`TypeRegistry.register_msg`.
"""

from __future__ import annotations

import functools
import gc
import re
import threading
from dataclasses import dataclass
from typing import Any, Literal

from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.msg import get_types_from_msg
from rosbags.typesys.store import Typestore

from simbridge.errors import TypeNotFoundError


__all__ = [
    "PRIMITIVES",
    "FieldSpec",
    "MessageSpec",
    "TypeRegistry",
    "generate_interfaces_soon",
    "normalize_type",
    "short_type",
]

#: Primitive .msg base types and how they travel in JSON (rosbridge conventions).
PRIMITIVES: frozenset[str] = frozenset(
    {
        "bool",
        "byte",
        "char",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "float32",
        "float64",
        "string",
        "wstring",
    }
)

#: The uint8 member rosbags gives an empty message (CDR needs one); not a ROS field.
_EMPTY_FIELD = "structure_needs_at_least_one_member"
_PKG = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

InterfaceKind = Literal["msg", "srv", "action"]


def normalize_type(name: object, kind: InterfaceKind = "msg") -> str:
    """Return the canonical ``pkg/kind/Type`` spelling of an interface type name.

    ``geometry_msgs/Twist`` and ``geometry_msgs/msg/Twist`` both give
    ``geometry_msgs/msg/Twist``; empty path segments are ignored, as rosbridge does.

    Raises:
        TypeNotFoundError: the name is not of the form ``pkg/Type`` or ``pkg/sub/Type``.
    """
    if not isinstance(name, str):
        msg = f"type must be a string such as 'std_msgs/msg/String', got {name!r}"
        raise TypeNotFoundError(msg)
    parts = [p for p in name.strip().split("/") if p]
    if len(parts) == 2:
        parts.insert(1, kind)
    if (
        len(parts) != 3
        or parts[1] not in ("msg", "srv", "action")
        or not _PKG.match(parts[0])
        or not _NAME.match(parts[2])
    ):
        msg = f"'{name}' is not a valid type string; expected 'pkg/Type' or 'pkg/{kind}/Type'"
        raise TypeNotFoundError(msg)
    return "/".join(parts)


def short_type(name: str) -> str:
    """Return ``pkg/Type`` for ``pkg/msg/Type`` (the ROS 1 style used in rosapi TypeDefs)."""
    parts = name.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 else name


@dataclass(frozen=True, slots=True)
class FieldSpec:
    """One field of a message type.

    Attributes:
        name: field name exactly as ROS spells it.
        base: primitive name (``float64``, ``string``...) or nested type ``pkg/msg/Type``.
        nested: ``base`` is a message type.
        arraylen: -1 scalar, 0 unbounded or bounded sequence, N fixed-size array (rosapi's
            ``fieldarraylen`` convention).
        bound: upper bound of a bounded sequence or string (0 = unbounded).
        string_bound: bound of bounded string elements (0 = unbounded).
    """

    name: str
    base: str
    nested: bool
    arraylen: int
    bound: int
    string_bound: int


@dataclass(frozen=True, slots=True)
class MessageSpec:
    """A message type: its canonical name, fields and constants."""

    name: str
    fields: tuple[FieldSpec, ...]
    constants: tuple[tuple[str, str, Any], ...]


class TypeRegistry:
    """Every interface type simbridge knows, looked up by any accepted spelling."""

    def __init__(self, store: Stores = Stores.LATEST, *, interfaces: bool = True) -> None:
        self._store = get_typestore(store)
        #: Compiled specs by canonical name, filled lazily.
        self._specs: dict[str, MessageSpec] = {}
        self._services: dict[str, tuple[str, str]] = {}
        self._actions: dict[str, tuple[str, str, str]] = {}
        #: The .msg text each registered (non-rosbags) message was defined with.
        self.texts: dict[str, str] = {}
        self._batch: dict[str, Any] | None = None
        #: definition_text results (rosapi topics_and_raw_types is polled every 3 s by Lichtblick).
        self._full_texts: dict[str, str] = {}
        # simbridge's service/action interfaces (simbridge.msgs.interfaces) are added by the first
        # lookup that needs one of them or a full listing: an idle server never does, and their
        # generated classes are 2.9 MB of its resident memory.
        self._interfaces_pending = interfaces
        if interfaces:
            # the few ROS 1 actionlib messages are needed at start-up (the in-process actionlib
            # servers declare their topics), so they come at once, without the rest
            self._add_generated(_actionlib())

    @property
    def store(self) -> Typestore:
        """The rosbags type store: definitions, CDR serializers, message classes (all of them)."""
        self._need()
        return self._store

    @property
    def services(self) -> dict[str, tuple[str, str]]:
        """Services: ``pkg/srv/Type`` -> (request message, response message)."""
        self._need()
        return self._services

    @property
    def actions(self) -> dict[str, tuple[str, str, str]]:
        """Actions: ``pkg/action/Type`` -> (goal, result, feedback messages)."""
        self._need()
        return self._actions

    def _need(self, canonical: str | None = None) -> None:
        """Add the interfaces now, if ``canonical`` is one of their names (None: any listing)."""
        if self._interfaces_pending and (canonical is None or canonical in _interface_names()):
            self._interfaces_pending = False
            self._add_interfaces()

    def _add_interfaces(self) -> None:
        """Add simbridge's service/action interfaces (generated once per process, then copied)."""
        self._add_generated(_interfaces())

    def _add_generated(self, generated: Any) -> None:
        """Copy definitions generated once per process into this registry's store."""
        fielddefs, types, services, actions, texts = generated
        for name in fielddefs.keys() - self._store.fielddefs.keys():
            self._store.fielddefs[name] = fielddefs[name]
            self._store.types[name] = types[name]
        self._services.update(services)
        self._actions.update(actions)
        self.texts.update(texts)

    # -- lookup -----------------------------------------------------------------------------

    def known(self, name: str) -> bool:
        """Return whether the message type (any accepted spelling) is known."""
        try:
            canonical = normalize_type(name)
        except TypeNotFoundError:
            return False
        self._need(canonical)
        return canonical in self._store.fielddefs

    def spec(self, name: str) -> MessageSpec:
        """Return the compiled spec of a message type.

        Raises:
            TypeNotFoundError: the name is malformed or the type is unknown.
        """
        cached = self._specs.get(name)  # the canonical spelling: every nested field's type
        if cached is not None:
            return cached
        canonical = normalize_type(name)
        cached = self._specs.get(canonical)
        if cached is not None:
            return cached
        self._need(canonical)
        try:
            consts, fields = self._store.fielddefs[canonical]
        except KeyError:
            msg = f"unknown message type '{name}'"
            raise TypeNotFoundError(msg) from None
        spec = MessageSpec(
            canonical,
            tuple(_field_spec(fname, desc) for fname, desc in fields if fname != _EMPTY_FIELD),
            tuple((c[0], c[1], c[2]) for c in consts),
        )
        self._specs[canonical] = spec
        return spec

    def types(self) -> list[str]:
        """Return every known message type name, sorted."""
        self._need()
        return sorted(self._store.fielddefs)

    def interface_names(self) -> list[str]:
        """Return every message, service and action type name, sorted (rosapi's interfaces).

        The pending service/action interfaces are listed by name, not generated: generating
        them takes 80 ms here (0.4 s on a Pi 4B) in one go, a gap in every client's /odom at
        the first ``/rosapi/interfaces`` call.
        """
        names = self._store.fielddefs.keys() | self._services.keys() | self._actions.keys()
        if self._interfaces_pending:
            names |= _interface_names()
        return sorted(names)

    def definition_text(self, name: str) -> str:
        """Return the full ``.msg`` text with each dependency in a ``MSG: pkg/Type`` section.

        This is the layout of rosapi's ``typedefs_full_text`` (and ROS 1 ``gendeps --cat``)
        that Foxglove and Lichtblick parse.
        """
        canonical = self.spec(name).name
        cached = self._full_texts.get(canonical)
        if cached is None:
            text, _digest = self._store.generate_msgdef(canonical, ros_version=2)
            cached = self._full_texts[canonical] = str(text)
        return cached

    def service(self, name: str) -> tuple[str, str]:
        """Return the (request, response) message names of a service type.

        Raises:
            TypeNotFoundError: the name is malformed or the service type is unknown.
        """
        canonical = normalize_type(name, "srv")
        self._need(canonical)
        parts = self._services.get(canonical)
        if parts is None:
            msg = f"unknown service type '{name}'"
            raise TypeNotFoundError(msg)
        return parts

    def action(self, name: str) -> tuple[str, str, str]:
        """Return the (goal, result, feedback) message names of an action type.

        Raises:
            TypeNotFoundError: the name is malformed or the action type is unknown.
        """
        canonical = normalize_type(name, "action")
        self._need(canonical)
        parts = self._actions.get(canonical)
        if parts is None:
            msg = f"unknown action type '{name}'"
            raise TypeNotFoundError(msg)
        return parts

    def message_text(self, name: str) -> str:
        """Return the .msg text of one message type (without its dependencies)."""
        canonical = normalize_type(name)
        self._need(canonical)
        text = self.texts.get(canonical)
        if text is not None:
            return text
        full = self.definition_text(canonical)
        return full.split("\n" + "=" * 80 + "\n", 1)[0]

    # -- registration -------------------------------------------------------------------------

    def register_msg(self, name: str, text: str) -> str:
        """Register a message type from ``.msg`` text; return its canonical name.

        Service and action parts are registered as messages named ``pkg/srv/Foo_Request`` etc.
        """
        parts = name.split("/")
        if len(parts) != 3:
            msg = f"register_msg needs 'pkg/kind/Type', got '{name}'"
            raise TypeNotFoundError(msg)
        key = f"{parts[0]}/msg/{parts[2]}"
        parsed = _PARSED.get((key, text))
        if parsed is None:
            parsed = _PARSED[(key, text)] = get_types_from_msg(text or "\n", key)
        renamed = {}
        for k, value in parsed.items():
            renamed[name if k == key else k] = value
        if self._batch is not None:
            self._batch.update(renamed)
        else:
            self._store.register(renamed)
        self._specs.pop(name, None)
        self._full_texts.clear()
        self.texts[name] = text
        return name

    def register_many(self, definitions: list[tuple[str, str, str]]) -> None:
        """Register many ``(kind, name, text)`` definitions at once (one code generation)."""
        self._batch = {}
        try:
            for kind, name, text in definitions:
                if kind == "msg":
                    self.register_msg(name, text)
                elif kind == "srv":
                    self.register_srv(name, text)
                else:
                    self.register_action(name, text)
            batch = self._batch
        finally:
            self._batch = None
        self._store.register(batch)
        self._specs.clear()
        self._full_texts.clear()

    def has_service(self, name: str) -> bool:
        """Return whether the service type is known (without adding the interfaces for it)."""
        canonical = normalize_type(name, "srv")
        return canonical in self._services or (
            self._interfaces_pending and canonical in _interface_names()
        )

    def register_srv(self, name: str, text: str) -> str:
        """Register a service type from ``.srv`` text (request ``---`` response)."""
        canonical = normalize_type(name, "srv")
        request, response = _sections(text, 2, name)
        self.register_msg(f"{canonical}_Request", request)
        self.register_msg(f"{canonical}_Response", response)
        self._services[canonical] = (f"{canonical}_Request", f"{canonical}_Response")
        return canonical

    def register_action(self, name: str, text: str) -> str:
        """Register an action type from ``.action`` text (goal ``---`` result ``---`` feedback)."""
        canonical = normalize_type(name, "action")
        goal, result, feedback = _sections(text, 3, name)
        names = (f"{canonical}_Goal", f"{canonical}_Result", f"{canonical}_Feedback")
        for part, body in zip(names, (goal, result, feedback), strict=True):
            self.register_msg(part, body)
        self._actions[canonical] = names
        return canonical

    def action_wire(self, name: str) -> tuple[str, str, str]:
        """Return the ROS 2 wire types of an action: (send_goal, get_result, feedback message).

        rcl_action carries an action ``pkg/action/Foo`` as the services ``Foo_SendGoal``
        (``goal_id`` and ``goal`` in; ``accepted`` and ``stamp`` out) and ``Foo_GetResult``
        (``goal_id`` in; ``status`` and ``result`` out), the topic type ``Foo_FeedbackMessage``
        (``goal_id`` and ``feedback``), and the fixed ``action_msgs/srv/CancelGoal`` and
        ``action_msgs/msg/GoalStatusArray``. The generated types are registered on first use.

        Raises:
            TypeNotFoundError: the action type is unknown.
        """
        canonical = normalize_type(name, "action")
        goal, result, feedback = self.action(canonical)
        send_goal, get_result = f"{canonical}_SendGoal", f"{canonical}_GetResult"
        message = f"{canonical}_FeedbackMessage"
        if message not in self._store.fielddefs:
            uuid = "unique_identifier_msgs/UUID goal_id"
            self.register_many(
                [
                    ("msg", f"{send_goal}_Request", f"{uuid}\n{goal} goal"),
                    (
                        "msg",
                        f"{send_goal}_Response",
                        "bool accepted\nbuiltin_interfaces/Time stamp",
                    ),
                    ("msg", f"{get_result}_Request", uuid),
                    ("msg", f"{get_result}_Response", f"int8 status\n{result} result"),
                    ("msg", message, f"{uuid}\n{feedback} feedback"),
                ]
            )
            for service in (send_goal, get_result):
                self._services[service] = (f"{service}_Request", f"{service}_Response")
        return send_goal, get_result, message


_INTERFACES: Any = None
_ACTIONLIB: Any = None
#: Held while the interfaces are generated (by :func:`generate_interfaces_soon`'s thread or the
#: first lookup that needs them): a lookup waits for a generation under way, never repeats it.
_GENERATING = threading.Lock()
_WARMUP: threading.Thread | None = None
#: Definitions generated at once (one compiled module each).
_BATCH = 16


def generate_interfaces_soon() -> None:
    """Generate simbridge's service/action interfaces in a background thread, once per process.

    Generated on the loop by a client's first rosapi call (``/rosapi/topics`` is roslibjs's first
    call), they took 80-300 ms in one go on a shared x86 core (a Pi 4B core is ~5x slower): a
    gap in every client's /odom. The thread gives up the GIL every switch interval (5 ms), so
    the loop keeps its ticks meanwhile. The server calls this when its first client connects:
    an idle server keeps its footprint (``tests/test_footprint.py``).

    The garbage collector is paused while they are made (else a full collection ran mid-way,
    in the thread but holding the GIL: 40-70 ms), and what they are made of (47,000 objects
    that live as long as the process) is frozen afterwards, as the startup objects are
    (``simbridge.cli``), so that no full collection walks them again.
    """
    global _WARMUP
    if _INTERFACES is None and _WARMUP is None:

        def run() -> None:
            was = gc.isenabled()
            gc.disable()
            try:
                _interfaces()
            finally:
                gc.freeze()
                if was:
                    gc.enable()

        _WARMUP = threading.Thread(target=run, name="simbridge-interfaces", daemon=True)
        _WARMUP.start()


def _interfaces() -> Any:
    """Return simbridge's service/action interfaces, generating them on the first call."""
    global _INTERFACES
    with _GENERATING:
        if _INTERFACES is None:
            from simbridge.msgs.interfaces import ACTIONS, MESSAGES, SERVICES

            fresh = TypeRegistry(interfaces=False)
            before = set(fresh._store.fielddefs)
            definitions = (
                [("msg", n, t) for n, t in MESSAGES.items()]
                + [("srv", n, t) for n, t in SERVICES.items()]
                + [("action", n, t) for n, t in ACTIONS.items()]
            )
            # in a few batches (messages before the services that use them): each batch's
            # generated code is compiled in one C call that holds the GIL
            for i in range(0, len(definitions), _BATCH):
                fresh.register_many(definitions[i : i + _BATCH])
            added = set(fresh._store.fielddefs) - before
            _INTERFACES = (
                {k: fresh._store.fielddefs[k] for k in added},
                {k: fresh._store.types[k] for k in added},
                fresh._services,
                fresh._actions,
                fresh.texts,
            )
        return _INTERFACES


def _actionlib() -> Any:
    """Return the ROS 1 actionlib messages, generated once per process (as ``_INTERFACES``)."""
    global _ACTIONLIB
    if _ACTIONLIB is None:
        from simbridge.msgs.interfaces import ACTIONLIB_MESSAGES

        fresh = TypeRegistry(interfaces=False)
        before = set(fresh._store.fielddefs)
        fresh.register_many([("msg", n, t) for n, t in ACTIONLIB_MESSAGES.items()])
        added = set(fresh._store.fielddefs) - before
        _ACTIONLIB = (
            {k: fresh._store.fielddefs[k] for k in added},
            {k: fresh._store.types[k] for k in added},
            {},
            {},
            fresh.texts,
        )
    return _ACTIONLIB


@functools.cache
def _interface_names() -> frozenset[str]:
    """Every type name simbridge.msgs.interfaces defines: messages, services, actions, parts."""
    from simbridge.msgs.interfaces import ACTIONS, MESSAGES, SERVICES

    names = set(MESSAGES) | set(SERVICES) | set(ACTIONS)
    names.update(f"{srv}_{part}" for srv in SERVICES for part in ("Request", "Response"))
    names.update(f"{act}_{part}" for act in ACTIONS for part in ("Goal", "Result", "Feedback"))
    return frozenset(names)


#: Parsed .msg texts, shared by every registry of the process (parsing is the slow part).
_PARSED: dict[tuple[str, str], Any] = {}


def _sections(text: str, count: int, name: str) -> list[str]:
    parts: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            parts.append([])
        else:
            parts[-1].append(line)
    if len(parts) != count:
        msg = f"{name}: expected {count} sections separated by '---', got {len(parts)}"
        raise TypeNotFoundError(msg)
    return ["\n".join(p).strip("\n") for p in parts]


def _field_spec(fname: str, desc: tuple[Any, Any]) -> FieldSpec:
    nodetype, detail = desc
    kind = int(nodetype)
    if kind in (3, 4):  # ARRAY (fixed) or SEQUENCE
        (inner_type, inner_detail), count = detail
        arraylen = int(count) if kind == 3 else 0
        bound = 0 if kind == 3 else int(count)
        base, nested, string_bound = _element(int(inner_type), inner_detail)
        return FieldSpec(fname, base, nested, arraylen, bound, string_bound)
    base, nested, string_bound = _element(kind, detail)
    return FieldSpec(fname, base, nested, -1, 0, string_bound)


def _element(kind: int, detail: Any) -> tuple[str, bool, int]:
    if kind == 1:  # BASE: (name, string bound)
        return str(detail[0]), False, int(detail[1])
    return normalize_type(str(detail)), True, 0  # NAME: nested message
