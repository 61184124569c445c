"""ROS 2 parameters of the in-process nodes (``/virtual_robot``'s robot and LiDAR settings).

A node's parameters are a flat mapping of dotted names (``robot.mass``, ``lidar.mount``) to
values of a fixed ROS 2 parameter type (bool, integer, double, string, double array). A change
is all-or-nothing: the new values are type-checked and the whole settings model re-validated
(ranges, relations such as ``range_min < range_max``) before anything is applied; a refusal
says why and changes nothing. Applied changes take effect at once (the next step or scan).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from simbridge.errors import ServiceError
from simbridge.msgs.convert import finite_number


__all__ = ["Bounds", "ParamNode", "ParameterRefused", "ParameterStore", "param_type"]


@dataclass(frozen=True, slots=True)
class Bounds:
    """Declared bounds of a numeric parameter (``describe_parameters`` shows them)."""

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None

    def __bool__(self) -> bool:
        return any(v is not None for v in (self.gt, self.ge, self.lt, self.le))

    def text(self) -> str:
        """The bounds in words for a person: ``> 0 and <= 1000`` (``""``: none)."""
        parts = [
            f"{sign} {value}"
            for sign, value in ((">", self.gt), (">=", self.ge), ("<", self.lt), ("<=", self.le))
            if value is not None
        ]
        return " and ".join(parts)


class ParameterRefused(ValueError):
    """A node's ``write`` refuses new values; the text names each refused parameter itself."""


#: rcl_interfaces/msg/ParameterType numbers.
PARAMETER_NOT_SET = 0
PARAMETER_BOOL = 1
PARAMETER_INTEGER = 2
PARAMETER_DOUBLE = 3
PARAMETER_STRING = 4
PARAMETER_DOUBLE_ARRAY = 8


def param_type(value: object) -> int:
    """Return the rcl_interfaces ParameterType number of a Python value."""
    if isinstance(value, bool):
        return PARAMETER_BOOL
    if isinstance(value, int):
        return PARAMETER_INTEGER
    if isinstance(value, float):
        return PARAMETER_DOUBLE
    if isinstance(value, str):
        return PARAMETER_STRING
    if isinstance(value, list | tuple):
        return PARAMETER_DOUBLE_ARRAY
    return PARAMETER_NOT_SET


def _coerce(name: str, old: Any, new: Any) -> Any:
    """Return ``new`` converted to the type of ``old``, or raise ServiceError."""
    kind = param_type(old)
    if kind == PARAMETER_BOOL and isinstance(new, bool):
        return new
    if kind == PARAMETER_STRING and isinstance(new, str):
        return new
    if kind in (PARAMETER_INTEGER, PARAMETER_DOUBLE):
        if isinstance(new, bool) or not isinstance(new, int | float):
            msg = f"parameter {name} is a number; got {new!r}"
            raise ServiceError(msg)
        if not finite_number(new):
            msg = f"parameter {name} must be finite; got {new!r}"
            raise ServiceError(msg)
        if kind == PARAMETER_INTEGER:
            if not float(new).is_integer():
                msg = f"parameter {name} is an integer; got {new!r}"
                raise ServiceError(msg)
            return int(new)
        return float(new)
    if kind == PARAMETER_DOUBLE_ARRAY and isinstance(new, list | tuple):
        if len(new) != len(old):
            msg = f"parameter {name} needs {len(old)} numbers; got {len(new)}"
            raise ServiceError(msg)
        out = []
        for x in new:
            if not finite_number(x):
                msg = f"parameter {name} needs finite numbers; got {x!r}"
                raise ServiceError(msg)
            out.append(float(x))
        return out
    msg = f"parameter {name} has type {type(old).__name__}; got {type(new).__name__} {new!r}"
    raise ServiceError(msg)


@dataclass(eq=False)
class ParamNode:
    """The parameters of one node.

    Attributes:
        name: the node name (``/virtual_robot``).
        read: returns the current values, flat (``{"robot.mass": 1.5, ...}``).
        write: validates and applies a complete new flat mapping; raises ``ValueError`` with
            a reason when the combination is invalid (nothing applied then).
        descriptions: one line per parameter, shown by ``describe_parameters``.
        bounds: the declared bounds of numeric parameters (``describe_parameters`` shows them
            as ROS 2 ranges and constraints).
        read_only: names that cannot be changed at run time.
    """

    name: str
    read: Callable[[], dict[str, Any]]
    write: Callable[[dict[str, Any]], None]
    descriptions: dict[str, str] = field(default_factory=dict)
    bounds: dict[str, Bounds] = field(default_factory=dict)
    read_only: frozenset[str] = frozenset()
    #: Called with the changed names after every applied change.
    on_change: list[Callable[[list[str]], None]] = field(default_factory=list)


class ParameterStore:
    """Parameters of every in-process node."""

    def __init__(self) -> None:
        #: Nodes by name.
        self.nodes: dict[str, ParamNode] = {}
        #: Called with each node added (e.g. to offer its rcl_interfaces services).
        self.on_add: list[Callable[[ParamNode], None]] = []
        #: Called with the node's name and the changed names after every applied change of
        #: any node (after the node's own :attr:`ParamNode.on_change`): a front end that shows
        #: every node's parameters (the builder adds it).
        self.on_change: list[Callable[[str, list[str]], None]] = []

    def add(self, node: ParamNode) -> None:
        """Register a node's parameters."""
        self.nodes[node.name] = node
        for callback in self.on_add:
            callback(node)

    def node(self, name: str) -> ParamNode:
        """Return a node by name (``virtual_robot`` or ``/virtual_robot``).

        Raises:
            ServiceError: no such node has parameters.
        """
        key = name if name.startswith("/") else "/" + name
        found = self.nodes.get(key)
        if found is None:
            msg = f"node {key} has no parameters (known: {', '.join(sorted(self.nodes))})"
            raise ServiceError(msg)
        return found

    def names(self, node: str) -> list[str]:
        """Return the parameter names of a node, sorted."""
        return sorted(self.node(node).read())

    def get(self, node: str, name: str) -> Any:
        """Return one value.

        Raises:
            ServiceError: unknown node or parameter.
        """
        values = self.node(node).read()
        if name not in values:
            msg = f"node {node} has no parameter '{name}'"
            raise ServiceError(msg)
        return values[name]

    def set(self, node: str, changes: dict[str, Any]) -> None:
        """Change several parameters of one node at once (all or nothing).

        Raises:
            ServiceError: an unknown or read-only name, a value of the wrong type, or an invalid
                combination; the message says which and why, and nothing was changed.
        """
        target = self.node(node)
        current = target.read()
        new = dict(current)
        for name, value in changes.items():
            if name not in current:
                msg = f"node {target.name} has no parameter '{name}'"
                raise ServiceError(msg)
            if name in target.read_only:
                why = target.descriptions.get(name, "")
                msg = f"parameter {name} of {target.name} is read-only at run time"
                raise ServiceError(f"{msg}: {why}" if why else msg)
            new[name] = _coerce(name, current[name], value)
        try:
            target.write(new)
        except ParameterRefused as err:  # it names each refused parameter itself
            raise ServiceError(f"invalid value: {err}") from None
        except ValueError as err:
            msg = f"invalid value for {', '.join(sorted(changes))}: {err}"
            raise ServiceError(msg) from None
        changed = [k for k in changes if current[k] != new[k]]
        for callback in target.on_change:
            callback(changed)
        for listener in self.on_change:
            listener(target.name, changed)
