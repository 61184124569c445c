"""The message definitions simbridge ships, so that a run asks rosbags only for what it alone does.

rosbags' ROS 2 type store is a chain of modules (kilted on jazzy on iron ... on foxy), each a
dict of definitions and a dataclass per message: 2.5 MB of a Raspberry Pi server's memory and
90 ms to import, with its parser and serializers 0.4-1.8 MB more (issue 16). A run needs the
definitions (names, fields, constants), not the classes: ``definitions.txt``, next to this
module, holds them as data, one type a line, ``KIND NAME JSON``:

``standard``
    every message of rosbags' latest ROS 2 store: JSON ``[constants, fields]``;
``parsed``
    simbridge's own ``.msg`` texts (:mod:`simbridge.msgs.interfaces`, and what the robot graph
    registers at start: the fleet's and the clock's types), as rosbags parses and registers
    them: JSON ``[text, constants, fields]``. A text that differs from the one shipped (edited
    since the file was made) is parsed by rosbags when it is registered, as before.

Both in rosbags' layout: a constant is ``[name, type, value]``, a field ``[name, [nodetype,
detail]]`` with the nodetypes :data:`BASE` (detail ``[primitive, string bound]``), :data:`NAME`
(detail ``pkg/msg/Type``), :data:`ARRAY` and :data:`SEQUENCE` (detail ``[[nodetype, detail],
length or bound]``); an empty message has rosbags' one ``uint8`` placeholder field. The file is
written by ``scripts/definitions.py`` from the installed rosbags and simbridge's texts;
``tests/msgs/test_definitions.py`` checks that it is what the script writes now and that a
registry's definitions equal those of a rosbags store given the same registrations.

The file is read at the first registry, a line at a time (one JSON document for the whole file
left 0.4 MB more resident, its parse freed between what was kept); a line's JSON is parsed when
its type is first looked up (a standard message) or registered (a ``parsed`` text).
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import orjson


__all__ = [
    "ARRAY",
    "BASE",
    "DATA",
    "NAME",
    "PLACEHOLDER",
    "SEQUENCE",
    "Definition",
    "frozen",
    "parsed",
    "standard",
]

#: Nodetypes of a field descriptor (rosbags' ``Nodetype`` values).
BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4
#: The uint8 member rosbags gives an empty message (CDR needs one); not a ROS field.
PLACEHOLDER = "structure_needs_at_least_one_member"
#: The shipped file.
DATA = Path(__file__).with_name("definitions.txt")

#: A message definition: (constants ``(name, type, value)``, fields ``(name, (nodetype,
#: detail))``), rosbags' ``fielddefs`` layout in tuples.
Definition = tuple[tuple[Any, ...], tuple[Any, ...]]


def frozen(value: Any) -> Any:
    """Return ``value`` with lists as tuples and strings interned (shared by every definition)."""
    if isinstance(value, list | tuple):
        return tuple(frozen(v) for v in value)
    if isinstance(value, str):
        return sys.intern(value)
    if isinstance(value, int) and not isinstance(value, bool):
        return int(value)  # rosbags' Nodetype is an IntEnum
    return value


class _Standard(Mapping[str, Definition]):
    """rosbags' standard messages by name; a type's line is parsed by its first lookup."""

    def __init__(self, lines: dict[str, str]) -> None:
        self._lines = lines
        self._parsed: dict[str, Definition] = {}

    def __getitem__(self, name: str) -> Definition:
        found = self._parsed.get(name)
        if found is None:
            found = self._parsed[name] = frozen(orjson.loads(self._lines[name]))
        return found

    def __contains__(self, name: object) -> bool:
        return name in self._lines

    def __iter__(self) -> Iterator[str]:
        return iter(self._lines)

    def __len__(self) -> int:
        return len(self._lines)


@functools.cache
def _data() -> tuple[_Standard, dict[str, str]]:
    standard: dict[str, str] = {}
    own: dict[str, str] = {}
    with DATA.open(encoding="utf-8") as lines:
        for line in lines:
            if line.startswith("#"):
                continue
            kind, name, value = line.split(" ", 2)
            (standard if kind == "standard" else own)[sys.intern(name)] = value
    return _Standard(standard), own


def standard() -> Mapping[str, Definition]:
    """Every message of rosbags' latest ROS 2 store, by canonical name (shared by the process).

    The file is read once; a type's definition is parsed by its first lookup: none by an idle
    default server, 26 of the 163 once a page has subscribed to /odom, /scan and /tf and asked
    rosapi for the raw definitions (all of them parsed at once held 0.15 MB more).
    """
    return _data()[0]


def parsed(name: str, text: str) -> Definition | None:
    """Return the shipped definition of ``name`` registered from ``text``; None if not shipped."""
    line = _data()[1].get(name)
    if line is None:
        return None
    shipped, consts, fields = orjson.loads(line)
    if shipped != text:
        return None
    definition: Definition = frozen((consts, fields))
    return definition
