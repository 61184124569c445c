"""rosapi services, answered by simbridge itself (no rosapi node needed).

Field names are rosbridge's (``rosapi_msgs/srv/*``, protocol reference section 4). Service names
are absolute (``/rosapi/topics``); roslibjs 2.1 sends them relative (``rosapi/topics``), which
name resolution turns into the same absolute name.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from simbridge.errors import ConversionError, ServiceError, TypeNotFoundError
from simbridge.graph.topics import BRIDGE_NODE
from simbridge.msgs import normalize_type, positional_args, typedefs


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = ["ROSAPI_NODE", "ROS_DISTRO", "install_rosapi", "request_fields", "visible"]

ROSAPI_NODE = "/rosapi"
#: The ROS 2 distribution simbridge answers to ``get_ros_version`` (its message set is rosbags'
#: latest store).
ROS_DISTRO = "jazzy"
#: rosapi's failure text for a definition it cannot give (``typedefs_full_text``).
_NO_TEXT = "# failed to get full definition text for {type}: {reason}"


def visible(name: str) -> bool:
    """Return whether a graph name is listed (hidden names have a component starting '_')."""
    return not any(part.startswith("_") for part in name.split("/"))


def request_fields(args: Any, fields: tuple[str, ...], service: str) -> dict[str, Any]:
    """Return the request of a call as a dict: ``args`` is an object, a list or absent.

    A list is zipped onto ``fields`` in declaration order (:func:`~simbridge.msgs.positional_args`).

    Raises:
        ServiceError: a key that is not a request field, or more values than fields.
    """
    if args is None:
        return {}
    if isinstance(args, list):
        try:
            return positional_args(args, fields, f"{service}: request")
        except ConversionError as err:
            raise ServiceError(str(err)) from None
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
    """Register the rosapi services on ``graph``.

    The parameter nodes' rcl_interfaces services are
    :func:`~simbridge.graph.paramservices.install_parameter_services`, which the builder calls.

    Every service of ``rosapi_msgs`` that rosbridge 2.x offers is answered (protocol reference
    section 4), plus the later ``interfaces``, ``action_type`` and ``action_*_details``.
    """
    graph.nodes[ROSAPI_NODE] = "rosapi, answered by simbridge"
    topics_of = graph.topics

    def absolute(name: str) -> str:
        return name if not name or name.startswith("/") else "/" + name

    def canonical(type_name: str, kind: Any = "msg") -> str:
        try:
            return normalize_type(type_name, kind)
        except TypeNotFoundError:
            return type_name

    def owner_node(owner: object) -> str:
        return owner if isinstance(owner, str) else BRIDGE_NODE

    def listed_topics() -> list[Any]:
        return [t for t in topics_of.listed() if visible(t.name)]

    def publishers_of(name: str) -> list[str]:
        topic = topics_of.topics.get(name)
        if topic is None:
            return []
        return sorted({owner_node(owner) for owner in topic.publishers})

    def subscribers_of(name: str) -> list[str]:
        topic = topics_of.topics.get(name)
        if topic is None:
            return []
        nodes = {node for node, _callback in topic.internal}
        if topic.sinks:
            nodes.add(BRIDGE_NODE)
        return sorted(nodes)

    def listed_services() -> list[Any]:
        return [s for n, s in sorted(graph.services.services.items()) if visible(n)]

    def action_servers() -> list[str]:
        return sorted(graph.actions.actions)

    def details(type_name: str, pick: Any) -> dict[str, Any]:
        try:
            name = pick(type_name)
            return {"typedefs": typedefs(graph.registry, name)}
        except TypeNotFoundError as err:
            raise ServiceError(str(err)) from None

    def full_text(type_name: str | None) -> str:
        if type_name is None:
            return _NO_TEXT.format(type="?", reason="the topic has no type yet")
        try:
            return graph.registry.definition_text(type_name)
        except TypeNotFoundError as err:
            return _NO_TEXT.format(type=type_name, reason=err)

    handlers: dict[str, tuple[str, Any]] = {
        "topics": (
            "Topics",
            lambda r: {
                "topics": [t.name for t in listed_topics()],
                "types": [t.type for t in listed_topics()],
            },
        ),
        "topics_for_type": (
            "TopicsForType",
            lambda r: {
                "topics": [t.name for t in listed_topics() if t.type == canonical(r["type"])]
            },
        ),
        "topics_and_raw_types": (
            "TopicsAndRawTypes",
            lambda r: {
                "topics": [t.name for t in listed_topics()],
                "types": [t.type for t in listed_topics()],
                "typedefs_full_text": [full_text(t.type) for t in listed_topics()],
            },
        ),
        "topic_type": (
            "TopicType",
            lambda r: {
                "type": (getattr(topics_of.topics.get(absolute(r["topic"])), "type", "") or "")
            },
        ),
        "publishers": ("Publishers", lambda r: {"publishers": publishers_of(absolute(r["topic"]))}),
        "subscribers": (
            "Subscribers",
            lambda r: {"subscribers": subscribers_of(absolute(r["topic"]))},
        ),
        "services": ("Services", lambda r: {"services": [s.name for s in listed_services()]}),
        "services_for_type": (
            "ServicesForType",
            lambda r: {
                "services": [
                    s.name for s in listed_services() if s.type == canonical(r["type"], "srv")
                ]
            },
        ),
        "service_type": (
            "ServiceType",
            lambda r: {
                "type": getattr(graph.services.services.get(absolute(r["service"])), "type", "")
            },
        ),
        "service_providers": (
            "ServiceProviders",
            lambda r: {
                "providers": sorted(
                    {
                        s.node
                        for s in graph.services.services.values()
                        if s.type == canonical(r["service"], "srv")
                    }
                )
            },
        ),
        "service_node": (
            "ServiceNode",
            lambda r: {
                "node": getattr(graph.services.services.get(absolute(r["service"])), "node", "")
            },
        ),
        "nodes": ("Nodes", lambda r: {"nodes": sorted(graph.nodes)}),
        "node_details": ("NodeDetails", lambda r: node_details(absolute(r["node"]))),
        "action_servers": ("GetActionServers", lambda r: {"action_servers": action_servers()}),
        "action_type": (
            "ActionType",
            lambda r: {
                "type": getattr(graph.actions.actions.get(absolute(r["action"])), "type", "")
            },
        ),
        "message_details": ("MessageDetails", lambda r: details(r["type"], lambda t: t)),
        "service_request_details": (
            "ServiceRequestDetails",
            lambda r: details(r["type"], lambda t: graph.registry.service(t)[0]),
        ),
        "service_response_details": (
            "ServiceResponseDetails",
            lambda r: details(r["type"], lambda t: graph.registry.service(t)[1]),
        ),
        "action_goal_details": (
            "ActionGoalDetails",
            lambda r: details(r["type"], lambda t: graph.registry.action(t)[0]),
        ),
        "action_result_details": (
            "ActionResultDetails",
            lambda r: details(r["type"], lambda t: graph.registry.action(t)[1]),
        ),
        "action_feedback_details": (
            "ActionFeedbackDetails",
            lambda r: details(r["type"], lambda t: graph.registry.action(t)[2]),
        ),
        "interfaces": (
            "Interfaces",
            lambda r: {"interfaces": graph.registry.interface_names()},
        ),
        "get_time": ("GetTime", lambda r: get_time()),
        "get_ros_version": ("GetROSVersion", lambda r: {"version": 2, "distro": ROS_DISTRO}),
    }

    def node_details(node: str) -> dict[str, Any]:
        if node not in graph.nodes:
            msg = f"node {node} does not exist (see /rosapi/nodes)"
            raise ServiceError(msg)
        subscribing, publishing = [], []
        for topic in topics_of.listed():
            if node in publishers_of(topic.name):
                publishing.append(topic.name)
            if node in subscribers_of(topic.name):
                subscribing.append(topic.name)
        services = [s.name for s in listed_services() if s.node == node]
        return {"subscribing": subscribing, "publishing": publishing, "services": services}

    def get_time() -> dict[str, Any]:
        sec, nanosec = graph.stamp()
        # ROS 2 spelling, plus roslibpy's ROS 1 spelling (its get_time reads secs/nsecs)
        return {"time": {"sec": sec, "nanosec": nanosec, "secs": sec, "nsecs": nanosec}}

    for name, (type_name, handler) in handlers.items():
        graph.add_service(f"/rosapi/{name}", f"rosapi_msgs/srv/{type_name}", ROSAPI_NODE, handler)
    _install_params(graph)


def _install_params(graph: Graph) -> None:
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
            "reason": (
                f"parameter '{name}' cannot be deleted: simbridge's nodes keep the parameters "
                "they declare"
            ),
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
