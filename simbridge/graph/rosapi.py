"""rosapi services, answered by simbridge itself (no rosapi node needed).

Field names are rosbridge's (``rosapi_msgs/srv/*``, protocol reference section 4). Service names
are absolute (``/rosapi/topics``); roslibjs 2.1 sends them relative (``rosapi/topics``), which
name resolution turns into the same absolute name.
"""

from __future__ import annotations

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

    graph.add_service("/rosapi/topics", "rosapi_msgs/srv/Topics", ROSAPI_NODE, topics)
    graph.add_service("/rosapi/topic_type", "rosapi_msgs/srv/TopicType", ROSAPI_NODE, topic_type)
    graph.add_service("/rosapi/services", "rosapi_msgs/srv/Services", ROSAPI_NODE, services)
