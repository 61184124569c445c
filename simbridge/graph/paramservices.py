"""The standard ROS 2 parameter services (``rcl_interfaces``) of every in-process node.

For a node ``/virtual_robot`` simbridge serves, as any rclcpp/rclpy node does:
``/virtual_robot/get_parameters``, ``set_parameters``, ``set_parameters_atomically``,
``list_parameters``, ``describe_parameters`` and ``get_parameter_types``. Values travel as
``rcl_interfaces/msg/ParameterValue`` (``type`` selects the ``*_value`` field that counts).

``set_parameters`` applies each parameter on its own and reports one result per parameter (as
ROS 2 does); ``set_parameters_atomically`` applies all or none. A refused value changes nothing
and its result says why.

A request names at most ``max_parameter_names`` parameters (or prefixes): a longer one is
refused before its answer is built (``result: false`` naming the setting).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from simbridge.errors import ServiceError
from simbridge.graph.params import (
    PARAMETER_BOOL,
    PARAMETER_DOUBLE,
    PARAMETER_DOUBLE_ARRAY,
    PARAMETER_INTEGER,
    PARAMETER_NOT_SET,
    PARAMETER_STRING,
    ParamNode,
    param_type,
)


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph
    from simbridge.graph.params import Bounds

__all__ = ["from_parameter_value", "install_parameter_services", "to_parameter_value"]

#: ParameterValue field holding each ParameterType.
_VALUE_FIELDS = {
    PARAMETER_BOOL: "bool_value",
    PARAMETER_INTEGER: "integer_value",
    PARAMETER_DOUBLE: "double_value",
    PARAMETER_STRING: "string_value",
    5: "byte_array_value",
    6: "bool_array_value",
    7: "integer_array_value",
    PARAMETER_DOUBLE_ARRAY: "double_array_value",
    9: "string_array_value",
}


def to_parameter_value(graph: Graph, value: Any) -> dict[str, Any]:
    """Return the canonical ``rcl_interfaces/msg/ParameterValue`` of a Python value."""
    out = graph.converter.default("rcl_interfaces/msg/ParameterValue")
    kind = param_type(value)
    out["type"] = kind
    if kind == PARAMETER_DOUBLE_ARRAY:
        out["double_array_value"] = np.asarray(value, dtype=np.float64)
    elif kind != PARAMETER_NOT_SET:
        out[_VALUE_FIELDS[kind]] = value
    return out


def from_parameter_value(value: dict[str, Any]) -> Any:
    """Return the Python value of a canonical ParameterValue.

    Raises:
        ServiceError: the type is NOT_SET or unknown (parameters cannot be undeclared here).
    """
    field = _VALUE_FIELDS.get(value.get("type", 0))
    if field is None:
        msg = f"parameter value type {value.get('type')} is not a value (NOT_SET or unknown)"
        raise ServiceError(msg)
    found = value[field]
    if isinstance(found, np.ndarray):
        return found.tolist()
    if isinstance(found, bytes):
        return list(found)
    return found


def _describe_bounds(descriptor: dict[str, Any], bounds: Bounds | None) -> None:
    """Fill a ParameterDescriptor's constraints from a parameter's declared bounds.

    ``additional_constraints`` says them in words (``> 0 and <= 1000``); a range
    (``floating_point_range`` or ``integer_range``: inclusive at both ends, as rcl_interfaces
    defines it) only where both bounds are inclusive, so that it never admits a refused value.
    """
    if bounds is None or not bounds.text():
        return
    descriptor["additional_constraints"] = bounds.text()
    if bounds.ge is None or bounds.le is None:
        return
    if descriptor["type"] == PARAMETER_INTEGER:
        low, high = int(bounds.ge), int(bounds.le)
        descriptor["integer_range"] = [{"from_value": low, "to_value": high, "step": 0}]
    elif descriptor["type"] == PARAMETER_DOUBLE:
        low_f, high_f = float(bounds.ge), float(bounds.le)
        descriptor["floating_point_range"] = [
            {"from_value": low_f, "to_value": high_f, "step": 0.0}
        ]


def install_parameter_services(graph: Graph) -> None:
    """Serve the rcl_interfaces services of each parameter node (present and future)."""
    for node in list(graph.params.nodes.values()):
        _install(graph, node)
    graph.params.on_add.append(lambda node: _install(graph, node))


def _install(graph: Graph, node: ParamNode) -> None:
    store = graph.params
    limit = graph.max_parameter_names

    def bounded(req: dict[str, Any], field: str, service: str) -> Any:
        """Return ``req[field]`` if it names few enough parameters, before any work on it.

        Each name costs an entry of the answer (a descriptor is ~150 bytes of JSON, built in
        Python): 99,000 names in a 400 kB request built 20 MB and held the loop 1.2 s.
        """
        items = req[field]
        if len(items) > limit:
            msg = (
                f"{node.name}/{service}: {len(items)} {field} in one request, at most {limit} "
                "(the server's max_parameter_names); ask in several requests"
            )
            raise ServiceError(msg)
        return items

    def get_parameters(req: dict[str, Any]) -> dict[str, Any]:
        names = bounded(req, "names", "get_parameters")
        values = node.read()
        return {"values": [to_parameter_value(graph, values.get(n)) for n in names]}

    def set_one(param: dict[str, Any]) -> dict[str, Any]:
        try:
            store.set(node.name, {param["name"]: from_parameter_value(param["value"])})
        except ServiceError as err:
            return {"successful": False, "reason": str(err)}
        return {"successful": True, "reason": ""}

    def set_parameters(req: dict[str, Any]) -> dict[str, Any]:
        return {"results": [set_one(p) for p in bounded(req, "parameters", "set_parameters")]}

    def set_atomically(req: dict[str, Any]) -> dict[str, Any]:
        parameters = bounded(req, "parameters", "set_parameters_atomically")
        try:
            changes = {p["name"]: from_parameter_value(p["value"]) for p in parameters}
            store.set(node.name, changes)
        except ServiceError as err:
            return {"result": {"successful": False, "reason": str(err)}}
        return {"result": {"successful": True, "reason": ""}}

    def list_parameters(req: dict[str, Any]) -> dict[str, Any]:
        prefixes = [p.rstrip(".") for p in bounded(req, "prefixes", "list_parameters")]
        depth = int(req["depth"])
        names = []
        for name in sorted(node.read()):
            if prefixes and not any(name == p or name.startswith(p + ".") for p in prefixes):
                continue
            if depth:
                base = max((p for p in prefixes if name.startswith(p + ".")), key=len, default="")
                rest = name[len(base) + 1 :] if base else name
                if rest.count(".") >= depth:
                    continue
            names.append(name)
        groups = sorted({n.rsplit(".", 1)[0] for n in names if "." in n})
        return {"result": {"names": names, "prefixes": groups}}

    def describe_parameters(req: dict[str, Any]) -> dict[str, Any]:
        names = bounded(req, "names", "describe_parameters")
        values = node.read()
        out = []
        for name in names:
            d = graph.converter.default("rcl_interfaces/msg/ParameterDescriptor")
            d["name"] = name
            if name in values:
                d["type"] = param_type(values[name])
                d["description"] = node.descriptions.get(name, "")
                d["read_only"] = name in node.read_only
                _describe_bounds(d, node.bounds.get(name))
            out.append(d)
        return {"descriptors": out}

    def get_parameter_types(req: dict[str, Any]) -> dict[str, Any]:
        names = bounded(req, "names", "get_parameter_types")
        values = node.read()
        return {"types": bytes(param_type(values.get(n)) for n in names)}

    for suffix, type_name, handler in (
        ("get_parameters", "GetParameters", get_parameters),
        ("set_parameters", "SetParameters", set_parameters),
        ("set_parameters_atomically", "SetParametersAtomically", set_atomically),
        ("list_parameters", "ListParameters", list_parameters),
        ("describe_parameters", "DescribeParameters", describe_parameters),
        ("get_parameter_types", "GetParameterTypes", get_parameter_types),
    ):
        graph.add_service(
            f"{node.name}/{suffix}", f"rcl_interfaces/srv/{type_name}", node.name, handler
        )
