"""rosapi services, answered by simbridge itself (no rosapi node needed).

Field names are rosbridge's (``rosapi_msgs/srv/*``, protocol reference section 4). Service names
are absolute (``/rosapi/topics``); roslibjs 2.1 sends them relative (``rosapi/topics``), which
name resolution turns into the same absolute name.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from simbridge.errors import ServiceError


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = ["ROSAPI_NODE", "install_rosapi", "request_fields"]

ROSAPI_NODE = "/rosapi"


def request_fields(args: Any, fields: tuple[str, ...], service: str) -> dict[str, Any]:
    """Return the request of a call as a dict: ``args`` is an object, a list or absent.

    A list is zipped onto ``fields`` in declaration order (rosbridge section 3.5).

    Raises:
        ServiceError: a key that is not a request field.
    """
    if args is None:
        return {}
    if isinstance(args, list):
        return dict(zip(fields, args, strict=False))
    unknown = [k for k in args if k not in fields]
    if unknown:
        expected = ", ".join(fields) if fields else "no fields"
        msg = f"{service}: request has no field '{unknown[0]}' (expected {expected})"
        raise ServiceError(msg)
    return dict(args)


def _string(req: dict[str, Any], key: str, service: str) -> str:
    value = req.get(key, "")
    if not isinstance(value, str):
        msg = f"{service}: field '{key}' must be a string, got {value!r}"
        raise ServiceError(msg)
    return value


def install_rosapi(graph: Graph) -> None:
    """Register the rosapi services on ``graph``."""
    graph.nodes[ROSAPI_NODE] = "rosapi, answered by simbridge"

    def topics(args: Any) -> dict[str, Any]:
        request_fields(args, (), "/rosapi/topics")
        listed = graph.topics.listed()
        return {"topics": [t.name for t in listed], "types": [t.type for t in listed]}

    def topic_type(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("topic",), "/rosapi/topic_type")
        name = _string(req, "topic", "/rosapi/topic_type")
        if name and not name.startswith("/"):
            name = "/" + name
        topic = graph.topics.topics.get(name)
        return {"type": (topic.type or "") if topic is not None else ""}

    def services(args: Any) -> dict[str, Any]:
        request_fields(args, (), "/rosapi/services")
        return {"services": sorted(graph.services.services)}

    def split_name(name: str, service: str) -> tuple[str, str]:
        node, sep, param = name.partition(":")
        if not sep or not node or not param:
            msg = (
                f"{service}: parameter name '{name}' must be '<node>:<parameter>', "
                "e.g. '/virtual_robot:robot.max_linear_velocity'"
            )
            raise ServiceError(msg)
        return node if node.startswith("/") else "/" + node, param

    def get_param(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name", "default_value"), "/rosapi/get_param")
        default = _string(req, "default_value", "/rosapi/get_param")
        try:
            node, param = split_name(_string(req, "name", "/rosapi/get_param"), "get_param")
            value = graph.params.get(node, param)
        except ServiceError as err:
            # rosapi answers with the default (valid JSON text) and successful: false
            return {"value": default or '""', "successful": False, "reason": str(err)}
        return {"value": json.dumps(value), "successful": True, "reason": ""}

    def set_param(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name", "value"), "/rosapi/set_param")
        text = _string(req, "value", "/rosapi/set_param")
        try:
            value = json.loads(text)
        except ValueError:
            value = text  # rosapi reads a non-JSON value as a plain string
        try:
            node, param = split_name(_string(req, "name", "/rosapi/set_param"), "set_param")
            graph.params.set(node, {param: value})
        except ServiceError as err:
            return {"successful": False, "reason": str(err)}
        return {"successful": True, "reason": ""}

    def has_param(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name",), "/rosapi/has_param")
        try:
            node, param = split_name(_string(req, "name", "/rosapi/has_param"), "has_param")
            graph.params.get(node, param)
        except ServiceError:
            return {"exists": False}
        return {"exists": True}

    def delete_param(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name",), "/rosapi/delete_param")
        name = _string(req, "name", "/rosapi/delete_param")
        return {
            "successful": False,
            "reason": f"parameter '{name}' cannot be deleted: simulator parameters are fixed",
        }

    def get_param_names(args: Any) -> dict[str, Any]:
        request_fields(args, (), "/rosapi/get_param_names")
        return {
            "names": [
                f"{node}:{param}"
                for node in sorted(graph.params.nodes)
                for param in graph.params.names(node)
            ]
        }

    for name, type_name, handler in (
        ("get_param", "GetParam", get_param),
        ("set_param", "SetParam", set_param),
        ("has_param", "HasParam", has_param),
        ("delete_param", "DeleteParam", delete_param),
        ("get_param_names", "GetParamNames", get_param_names),
    ):
        graph.add_service(f"/rosapi/{name}", f"rosapi_msgs/srv/{type_name}", ROSAPI_NODE, handler)
    graph.add_service("/rosapi/topics", "rosapi_msgs/srv/Topics", ROSAPI_NODE, topics)
    graph.add_service("/rosapi/topic_type", "rosapi_msgs/srv/TopicType", ROSAPI_NODE, topic_type)
    graph.add_service("/rosapi/services", "rosapi_msgs/srv/Services", ROSAPI_NODE, services)
