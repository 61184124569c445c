"""rmw_zenoh's names on the wire: key expressions, liveliness tokens and QoS strings.

Pure functions and data; nothing here imports Zenoh. The formats are those of rmw_zenoh_cpp's
``liveliness_utils.cpp`` and ``qos.cpp`` (identical on the Humble, Jazzy and Kilted branches):

* data: ``<domain>/<name without its outer slashes>/<DDS type>/<type hash>``, the DDS type
  spelled ``pkg::msg::dds_::Type_`` (services: the service type, ``pkg::srv::dds_::Type_``);
* graph: one liveliness token per entity, ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/
  <kind>/<enclave>/<namespace>/<node>`` plus ``/<name>/<DDS type>/<hash>/<qos>`` for endpoints,
  every ``/`` inside a field written ``%`` (so an empty namespace ``/`` is ``%``);
* QoS: ``reliability:durability:history,depth:deadline s,ns:lifespan s,ns:liveliness,s,ns``
  with each field left empty when it equals rmw_zenoh's default (reliable, volatile, keep last
  42, infinite durations, automatic liveliness).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Literal


__all__ = [
    "ADMIN_SPACE",
    "DEFAULT_QOS",
    "LATCHED_QOS",
    "SENSOR_QOS",
    "Entity",
    "Kind",
    "Qos",
    "dds_type",
    "demangle",
    "entity_gid",
    "mangle",
    "ros_type",
    "split_node",
    "topic_keyexpr",
]

#: The key space of rmw_zenoh's graph tokens.
ADMIN_SPACE = "@ros2_lv"

#: Node, message publisher and subscription, service server and client.
Kind = Literal["NN", "MP", "MS", "SS", "SC"]
_KINDS = ("NN", "MP", "MS", "SS", "SC")

# rmw enums (rmw/types.h)
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
_DEFAULT_DEPTH = 42  # rmw_zenoh's choice for depth 0, elided from tokens


def mangle(name: str) -> str:
    """Write a name as one key-expression chunk: every ``/`` becomes ``%``."""
    return name.replace("/", "%")


def demangle(chunk: str) -> str:
    """Undo :func:`mangle`."""
    return chunk.replace("%", "/")


def _strip_outer(name: str) -> str:
    start = 1 if name.startswith("/") else 0
    end = len(name) - 1 if name.endswith("/") and len(name) > 1 else len(name)
    return name[start:end]


def dds_type(ros_name: str) -> str:
    """Return the DDS spelling of ``pkg/msg/Type`` (or ``pkg/srv/Type``): ``pkg::msg::dds_::Type_``.

    Raises:
        ValueError: the name is not ``pkg/kind/Type``.
    """
    parts = ros_name.split("/")
    if len(parts) != 3 or not all(parts):
        msg = f"'{ros_name}' is not a type name of the form pkg/msg/Type"
        raise ValueError(msg)
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_type(dds_name: str) -> str:
    """Return ``pkg/msg/Type`` for a DDS spelling ``pkg::msg::dds_::Type_``.

    Raises:
        ValueError: the name is not of that form.
    """
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_") or len(parts[3]) < 2:
        msg = f"'{dds_name}' is not a DDS type name of the form pkg::msg::dds_::Type_"
        raise ValueError(msg)
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def topic_keyexpr(domain: int, name: str, dds: str, type_hash: str) -> str:
    """Return the key expression a topic's samples (or a service's queries) travel on."""
    return f"{domain}/{_strip_outer(name)}/{dds}/{type_hash}"


def split_node(fqn: str) -> tuple[str, str]:
    """Split a fully qualified node name into (namespace, name): ``/a/b`` -> (``/a``, ``b``)."""
    fqn = "/" + fqn.strip("/")
    namespace, _, name = fqn.rpartition("/")
    return namespace or "/", name


@dataclass(frozen=True, slots=True)
class Qos:
    """The QoS an endpoint declares in its token (rmw enum values)."""

    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 10

    def encode(self) -> str:
        """Return the token's QoS field (defaults elided as rmw_zenoh writes them)."""
        rel = "" if self.reliability == RELIABLE else str(self.reliability)
        dur = "" if self.durability == VOLATILE else str(self.durability)
        hist = "" if self.history == KEEP_LAST else str(self.history)
        depth = "" if self.depth == _DEFAULT_DEPTH else str(self.depth)
        return f"{rel}:{dur}:{hist},{depth}:,:,:,,"

    @classmethod
    def decode(cls, text: str) -> Qos:
        """Read a token's QoS field (durations are not needed by simbridge and are ignored).

        Raises:
            ValueError: the field is malformed.
        """
        parts = text.split(":")
        if len(parts) < 3 or "," not in parts[2]:
            msg = f"malformed QoS field '{text}'"
            raise ValueError(msg)
        hist, _, depth = parts[2].partition(",")

        def num(value: str, default: int) -> int:
            return int(value) if value else default

        return cls(
            reliability=num(parts[0], RELIABLE),
            durability=num(parts[1], VOLATILE),
            history=num(hist, KEEP_LAST),
            depth=num(depth, _DEFAULT_DEPTH),
        )

    @property
    def transient_local(self) -> bool:
        """Whether late joiners get the last messages (a latched topic)."""
        return self.durability == TRANSIENT_LOCAL


#: rclcpp's default profile (reliable, volatile, keep last 10); services use it too.
DEFAULT_QOS = Qos()
#: A latched topic (rclcpp's ``transient_local()`` with depth 1, as /tf_static and /map use).
LATCHED_QOS = Qos(durability=TRANSIENT_LOCAL, depth=1)
#: rclcpp's sensor-data profile (best effort, keep last 5).
SENSOR_QOS = Qos(reliability=BEST_EFFORT, depth=5)


@dataclass(frozen=True, slots=True)
class Entity:
    """One graph entity as its liveliness token describes it.

    Attributes:
        domain: ROS domain id.
        zid: the Zenoh session id (hex) of the process that owns it.
        nid: node id within that session (as a decimal string).
        eid: entity id within that session (equal to ``nid`` for a node).
        kind: ``NN``, ``MP``, ``MS``, ``SS`` or ``SC``.
        namespace: the node's namespace (``/`` when none).
        node: the node's name.
        enclave: the security enclave (``/`` when none).
        name: the topic or service name (endpoints only).
        type: ``pkg/msg/Type`` or ``pkg/srv/Type`` (endpoints only).
        type_hash: ``RIHS01_...`` or ``TypeHashNotSupported`` (endpoints only).
        qos: the endpoint's QoS.
    """

    domain: int
    zid: str
    nid: str
    eid: str
    kind: Kind
    namespace: str
    node: str
    enclave: str = "/"
    name: str = ""
    type: str = ""
    type_hash: str = ""
    qos: Qos = DEFAULT_QOS

    @property
    def node_fqn(self) -> str:
        """The node's fully qualified name, ``/ns/name``."""
        if self.namespace in ("", "/"):
            return "/" + self.node
        return f"{self.namespace.rstrip('/')}/{self.node}"

    def token(self) -> str:
        """Return the liveliness key expression of this entity."""
        head = (
            f"{ADMIN_SPACE}/{self.domain}/{self.zid}/{self.nid}/{self.eid}/{self.kind}/"
            f"{mangle(self.enclave)}/{mangle(self.namespace)}/{mangle(self.node)}"
        )
        if self.kind == "NN":
            return head
        return (
            f"{head}/{mangle(self.name)}/{mangle(dds_type(self.type))}/"
            f"{mangle(self.type_hash)}/{self.qos.encode()}"
        )

    def keyexpr(self) -> str:
        """Return the data key expression of an endpoint."""
        return topic_keyexpr(self.domain, self.name, dds_type(self.type), self.type_hash)

    @classmethod
    def parse(cls, token: str) -> Entity:
        """Read a liveliness key expression.

        Raises:
            ValueError: it is not an rmw_zenoh graph token (the message says why).
        """
        parts = token.split("/")
        if len(parts) < 9 or parts[0] != ADMIN_SPACE:
            msg = f"not an rmw_zenoh graph token: '{token}'"
            raise ValueError(msg)
        if any(not p for p in parts):
            msg = f"graph token with an empty field: '{token}'"
            raise ValueError(msg)
        kind = parts[5]
        if kind not in _KINDS:
            msg = f"graph token of unknown kind '{kind}': '{token}'"
            raise ValueError(msg)
        common = {
            "domain": int(parts[1]),
            "zid": parts[2],
            "nid": parts[3],
            "eid": parts[4],
            "kind": kind,
            "enclave": demangle(parts[6]),
            "namespace": demangle(parts[7]),
            "node": demangle(parts[8]),
        }
        if kind == "NN":
            return cls(**common)  # type: ignore[arg-type]
        if len(parts) < 13:
            msg = f"endpoint token without name, type, hash and QoS: '{token}'"
            raise ValueError(msg)
        return cls(
            **common,  # type: ignore[arg-type]
            name=demangle(parts[9]),
            type=ros_type(demangle(parts[10])),
            type_hash=demangle(parts[11]),
            qos=Qos.decode(parts[12]),
        )


def entity_gid(token: str) -> bytes:
    """Return a 16-byte GID for an entity, derived from its token (unique as the token is).

    rmw_zenoh hashes the token with XXH3-128; any stable 16 bytes unique per entity serve, as
    peers only compare GIDs (service replies echo the caller's GID unchanged).
    """
    return hashlib.blake2b(token.encode(), digest_size=16).digest()
