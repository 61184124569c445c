"""What the Foxglove WebSocket protocol's names and values are in simbridge's graph, and back.

Pure: no SDK, no event loop. Parameters are named as foxglove_bridge names ROS 2 parameters,
``NODE.PARAMETER`` (``/virtual_robot.robot.max_linear_velocity``), so that Foxglove's and
Lichtblick's Parameters panels group them by node as they do behind foxglove_bridge. Channels
carry ``ros2msg`` schemas: the full ``.msg`` text with its dependencies
(:meth:`TypeRegistry.definition_text <simbridge.msgs.TypeRegistry.definition_text>`), the text
Foxglove's ``@foxglove/rosmsg`` parses.
"""

from __future__ import annotations

from typing import Any

import orjson


__all__ = [
    "ADMIN_SCOPE",
    "CLIENT_ENCODINGS",
    "INSTALL_HINT",
    "MESSAGE_ENCODING",
    "SCHEMA_ENCODING",
    "param_name",
    "split_param",
    "status_of",
]

#: What a channel's messages and a service's requests are (ROS 2's wire format).
MESSAGE_ENCODING = "cdr"
#: What a channel's schema is: a ROS 2 ``.msg`` definition with its dependencies.
SCHEMA_ENCODING = "ros2msg"
#: Encodings a client may publish and call with (Foxglove's teleop panel sends either).
CLIENT_ENCODINGS = (MESSAGE_ENCODING, "json")
#: The command that installs the extra.
INSTALL_HINT = 'pip install "simbridge[foxglove]"'
#: The scope that gives a Foxglove port every topic and administrative rights.
ADMIN_SCOPE = "admin"


def param_name(node: str, name: str) -> str:
    """Return the Foxglove name of parameter ``name`` of ``node``: ``/node.name``."""
    return f"{node}.{name}"


def split_param(full: str, nodes: list[str]) -> tuple[str, str] | None:
    """Return ``(node, parameter)`` of a Foxglove parameter name, or None if no node has it.

    The longest matching node name wins (``/a/b.x`` is node ``/a/b``'s ``x`` when both ``/a``
    and ``/a/b`` exist).
    """
    for node in sorted(nodes, key=len, reverse=True):
        if full.startswith(node + ".") and len(full) > len(node) + 1:
            return node, full[len(node) + 1 :]
    return None


def status_of(data: bytes) -> tuple[str, str] | None:
    """Return ``(level, text)`` of a rosbridge ``status`` frame, None for any other frame."""
    try:
        body = orjson.loads(data)
    except orjson.JSONDecodeError:
        return None
    if not isinstance(body, dict) or body.get("op") != "status":
        return None
    return str(body.get("level", "error")), str(body.get("msg", ""))


def plain(value: Any) -> Any:
    """Return a canonical message as plain JSON values (numpy arrays as lists, bytes base64)."""
    from simbridge.msgs.message import encode_json

    return orjson.loads(encode_json(value))
