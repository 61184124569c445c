"""The ROS 2 interface-type registry: rosbags' definitions, its type store only when needed.

Type names are accepted as ``pkg/Type`` and ``pkg/msg/Type`` (rosbridge accepts both; rosapi
answers with ``pkg/msg/Type``). Definitions are rosbags' (every standard ROS 2 message), shipped
as data generated from it (:mod:`simbridge.msgs.definitions`); nothing here hand-writes a message
definition. Further interface definitions (services, actions, simbridge's own) are registered
from ``.msg``/``.srv`` text with :meth:`TypeRegistry.register_msg`, parsed by rosbags unless the
same text's parse is shipped. rosbags' type store itself (its message classes, CDR by rosbags,
bags, type hashes) is made on first use of :attr:`TypeRegistry.store`: a run that serves the
standard and simbridge's own types never imports it (issue 16).
"""

from __future__ import annotations

import functools
import gc
import re
import threading
from collections import ChainMap
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

from simbridge.errors import TypeNotFoundError
from simbridge.msgs.definitions import (
    ARRAY,
    BASE,
    NAME,
    PLACEHOLDER,
    Definition,
    frozen,
    parsed,
    standard,
)


if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


__all__ = [
    "PRIMITIVES",
    "FieldSpec",
    "MessageSpec",
    "TypeRegistry",
    "generate_interfaces",
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

#: The longest type string read (a ROS name is at most 256 characters here too).
MAX_TYPE_LENGTH = 256
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
    if len(name) > MAX_TYPE_LENGTH:  # a topic keeps its type: 900 kB ones held 90 MB a client
        msg = (
            f"a type string of {len(name)} characters is not a valid type: at most "
            f"{MAX_TYPE_LENGTH}, e.g. 'std_msgs/msg/String'"
        )
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

    def __init__(self, *, interfaces: bool = True) -> None:
        #: Every message definition by canonical name: those registered here, then rosbags'
        #: standard messages (shipped, shared by every registry of the process).
        self._registered: dict[str, Definition] = {}
        self._defs = ChainMap(self._registered, cast("dict[str, Definition]", standard()))
        #: rosbags' type store with every type of ``_defs``, made by the first use of ``store``.
        self._store: Typestore | None = None
        #: Compiled specs by canonical name, filled lazily.
        self._specs: dict[str, MessageSpec] = {}
        self._services: dict[str, tuple[str, str]] = {}
        self._actions: dict[str, tuple[str, str, str]] = {}
        #: The .msg text each registered (non-rosbags) message was defined with.
        self.texts: dict[str, str] = {}
        self._batch: dict[str, Definition] | None = None
        #: definition_text results (rosapi topics_and_raw_types is polled every 3 s by Lichtblick).
        self._full_texts: dict[str, str] = {}
        # simbridge's service/action interfaces (simbridge.msgs.interfaces) are added by the first
        # lookup that needs one of them or a full listing: an idle server never does.
        self._interfaces_pending = interfaces
        if interfaces:
            # the few ROS 1 actionlib messages are needed at start-up (the in-process actionlib
            # servers declare their topics), so they come at once, without the rest
            self._add_generated(_actionlib())

    @property
    def fielddefs(self) -> Mapping[str, Definition]:
        """Every message definition, in rosbags' ``fielddefs`` layout (interfaces included)."""
        self._need()
        return self._defs

    @property
    def store(self) -> Typestore:
        """The rosbags type store with every type here: its message classes, CDR, hashes, bags.

        Made on first use: rosbags' latest ROS 2 store (2.5 MB of modules, 90 ms to import, more
        on a Pi) and a class generated for each registered type. Lookups, validation, rosapi and
        simbridge's own CDR codec need only the definitions, which the registry holds without it.
        """
        self._need()
        if self._store is None:
            from rosbags.typesys import Stores, get_typestore

            store = get_typestore(Stores.LATEST)
            added: dict[str, Any] = {
                name: d for name, d in self._registered.items() if name not in store.fielddefs
            }
            if added:
                store.register(added)
            self._store = store
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
        """Add simbridge's service/action interfaces (made once per process, then copied)."""
        self._add_generated(_interfaces())

    def _add_generated(self, generated: Any) -> None:
        """Copy definitions made once per process into this registry."""
        defs, services, actions, texts = generated
        self._install({name: d for name, d in defs.items() if name not in self._defs})
        self._services.update(services)
        self._actions.update(actions)
        self.texts.update(texts)

    def _install(self, defs: dict[str, Definition]) -> None:
        """Add definitions (those of names already here are kept, as rosbags' store does).

        Raises:
            TypesysError: a name here has different fields (rosbags' error, as its store raises).
        """
        for name, (_consts, fields) in defs.items():
            have = self._defs.get(name)
            if have is not None and _lowered(have[1]) != _lowered(fields):
                from rosbags.typesys import TypesysError

                msg = f"Type {name!r} is already present with different definition."
                raise TypesysError(msg)
        added: dict[str, Any] = {name: d for name, d in defs.items() if name not in self._defs}
        self._registered.update(added)
        if self._store is not None and added:
            self._store.register(added)

    # -- lookup -----------------------------------------------------------------------------

    def known(self, name: str) -> bool:
        """Return whether the message type (any accepted spelling) is known."""
        try:
            canonical = normalize_type(name)
        except TypeNotFoundError:
            return False
        self._need(canonical)
        return canonical in self._defs

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
            consts, fields = self._defs[canonical]
        except KeyError:
            msg = f"unknown message type '{name}'"
            raise TypeNotFoundError(msg) from None
        spec = MessageSpec(
            canonical,
            tuple(_field_spec(fname, desc) for fname, desc in fields if fname != PLACEHOLDER),
            tuple((c[0], c[1], c[2]) for c in consts),
        )
        self._specs[canonical] = spec
        return spec

    def types(self) -> list[str]:
        """Return every known message type name, sorted."""
        self._need()
        return sorted(self._defs)

    def interface_names(self) -> list[str]:
        """Return every message, service and action type name, sorted (rosapi's interfaces).

        The pending service/action interfaces are listed by name, not added.
        """
        names = self._defs.keys() | self._services.keys() | self._actions.keys()
        if self._interfaces_pending:
            names |= _interface_names()
        return sorted(names)

    def definition_text(self, name: str) -> str:
        """Return the full ``.msg`` text with each dependency in a ``MSG: pkg/Type`` section.

        This is the layout of rosapi's ``typedefs_full_text`` (and ROS 1 ``gendeps --cat``)
        that Foxglove and Lichtblick parse: the type's constants (``type NAME=value``) and
        fields, then each message it refers to, directly or not, once, in the order of first
        reference, after a line of 80 ``=`` and ``MSG: pkg/Type``; the text rosbags'
        ``generate_msgdef`` gives for ROS 2 (tests/msgs/test_definitions.py compares them).
        """
        canonical = self.spec(name).name
        cached = self._full_texts.get(canonical)
        if cached is None:
            sections: dict[str, str] = {}
            first = self._own_text(canonical, sections)
            cached = "".join(
                [first, *(f"{'=' * 80}\nMSG: {short_type(k)}\n{v}" for k, v in sections.items())]
            )
            self._full_texts[canonical] = cached
        return cached

    def _own_text(self, name: str, sections: dict[str, str]) -> str:
        """Return the lines of one type; add each message it refers to, once, to ``sections``."""
        try:
            consts, fields = self._defs[name]
        except KeyError:
            msg = f"unknown message type '{name}'"
            raise TypeNotFoundError(msg) from None
        lines = [f"{ctype} {cname}={value}" for cname, ctype, value in consts]
        for fname, (kind, detail) in fields:
            if fname == PLACEHOLDER:
                continue
            if kind in (BASE, NAME):
                lines.append(f"{self._element_text(kind, detail, sections)} {fname}")
                continue
            (inner_kind, inner_detail), count = detail
            size = "" if count == 0 else str(count) if kind == ARRAY else f"<={count}"
            element = self._element_text(inner_kind, inner_detail, sections)
            lines.append(f"{element}[{size}] {fname}")
        lines.append("")
        return "\n".join(lines)

    def _element_text(self, kind: int, detail: Any, sections: dict[str, str]) -> str:
        if kind == BASE:
            base, bound = detail
            return f"string<={bound}" if base == "string" and bound else str(base)
        if detail not in sections:
            sections[detail] = ""  # its place: first referred to, before what it refers to
            sections[detail] = self._own_text(detail, sections)
        return short_type(detail)

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

        Raises:
            TypesysError: the text does not parse, or the name is known with other fields
                (rosbags' errors).
        """
        parts = name.split("/")
        if len(parts) != 3:
            msg = f"register_msg needs 'pkg/kind/Type', got '{name}'"
            raise TypeNotFoundError(msg)
        key = f"{parts[0]}/msg/{parts[2]}"
        shipped = parsed(name, text)
        if shipped is not None:
            renamed = {name: shipped}
        else:
            found = _PARSED.get((key, text))
            if found is None:
                found = _PARSED[(key, text)] = _parse(text, key)
            renamed = {name if k == key else k: value for k, value in found.items()}
        if self._batch is not None:
            self._batch.update(renamed)
        else:
            self._install(renamed)
        self._specs.pop(name, None)
        self._full_texts.clear()
        self.texts[name] = text
        return name

    def register_many(self, definitions: list[tuple[str, str, str]]) -> None:
        """Register many ``(kind, name, text)`` definitions at once (in the store, if made, too)."""
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
        self._install(batch)
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
        if message not in self._defs:
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


def _lowered(fields: Any) -> list[tuple[str, Any]]:
    """Fields as rosbags' store compares them (names without case)."""
    return [(fname.lower(), frozen(desc)) for fname, desc in fields]


def _parse(text: str, key: str) -> dict[str, Definition]:
    """Parse ``.msg`` text with rosbags, into the definitions its store would register.

    rosbags' code generation gives an empty message its one ``uint8`` placeholder field.
    """
    from rosbags.typesys.msg import get_types_from_msg

    placeholder: Any = (PLACEHOLDER, (BASE, ("uint8", 0)))
    return {
        name: frozen((consts, fields or [placeholder]))
        for name, (consts, fields) in get_types_from_msg(text or "\n", key).items()
    }


_INTERFACES: Any = None
_ACTIONLIB: Any = None
#: Held while the interfaces are made (by :func:`generate_interfaces` in the server's worker
#: thread, or the first lookup that needs them): a lookup waits for one under way, never
#: repeats it.
_GENERATING = threading.Lock()


def generate_interfaces() -> None:
    """Make simbridge's service/action interfaces now, once per process (thread-safe).

    Their definitions are shipped (:mod:`simbridge.msgs.definitions`): made from them, they take
    a few ms. A text edited since the file was made is parsed by rosbags (80-300 ms for all of
    them on a shared x86 core, a Pi 4B core is ~5x slower), which on the loop, at a client's
    first rosapi call, is a gap in every client's /odom: the server runs this in a worker thread
    when its first client connects (an idle server keeps its footprint,
    ``tests/test_footprint.py``); a thread gives up the GIL every switch interval (5 ms), so the
    loop keeps its ticks meanwhile. A lookup that needs them meanwhile waits for this one.

    The garbage collector is paused while they are made, and what they are made of (objects that
    live as long as the process) is frozen afterwards, as the startup objects are
    (``simbridge.app.tuning``), so that no full collection walks them again.
    """
    if _INTERFACES is not None:
        return
    was = gc.isenabled()
    gc.disable()
    try:
        _interfaces()
    finally:
        gc.freeze()
        if was:
            gc.enable()


def _interfaces() -> Any:
    """Return simbridge's service/action interfaces, making them on the first call."""
    global _INTERFACES
    with _GENERATING:
        if _INTERFACES is None:
            from simbridge.msgs.interfaces import ACTIONS, MESSAGES, SERVICES

            fresh = TypeRegistry(interfaces=False)
            fresh.register_many(
                [("msg", n, t) for n, t in MESSAGES.items()]
                + [("srv", n, t) for n, t in SERVICES.items()]
                + [("action", n, t) for n, t in ACTIONS.items()]
            )
            _INTERFACES = (
                fresh._registered,
                fresh._services,
                fresh._actions,
                fresh.texts,
            )
        return _INTERFACES


def _actionlib() -> Any:
    """Return the ROS 1 actionlib messages, made once per process (as ``_INTERFACES``)."""
    global _ACTIONLIB
    if _ACTIONLIB is None:
        from simbridge.msgs.interfaces import ACTIONLIB_MESSAGES

        fresh = TypeRegistry(interfaces=False)
        fresh.register_many([("msg", n, t) for n, t in ACTIONLIB_MESSAGES.items()])
        _ACTIONLIB = (
            fresh._registered,
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


#: .msg texts parsed by rosbags, shared by every registry of the process (parsing is slow).
_PARSED: dict[tuple[str, str], dict[str, Definition]] = {}


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
