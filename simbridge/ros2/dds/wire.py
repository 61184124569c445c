"""What the ROS 2 DDS middlewares put on the wire besides the messages themselves.

Pure functions and data; nothing here imports a DDS library. The formats are those of
rmw_fastrtps and rmw_cyclonedds (Humble, Jazzy and Kilted branches) and rmw_dds_common:

* topic ``/odom`` is the DDS topic ``rt/odom``; service ``/reset`` is the request topic
  ``rq/resetRequest`` and the reply topic ``rr/resetReply`` (``namespace_prefix``);
* the participant's USER_DATA is ``enclave=/;`` (rmw ``participant.cpp`` / ``rmw_node.cpp``);
  from Iron on an endpoint's USER_DATA is ``typehash=RIHS01_<64 hex>;`` (rmw_dds_common
  ``qos.cpp``);
* the nodes of a participant and their endpoints are announced on ``ros_discovery_info``
  as one ``rmw_dds_common/msg/ParticipantEntitiesInfo`` per participant, each GID 24 bytes in
  Humble and 16 from Iron on (``msg/Gid.msg``): the DDS GUID (prefix 12 + entity id 4),
  zero-filled.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field


__all__ = [
    "DISCOVERY_TOPIC",
    "DISCOVERY_TYPE",
    "ENCLAVE_USER_DATA",
    "NodeInfo",
    "ParticipantInfo",
    "decode_participant_info",
    "encode_participant_info",
    "gid_size",
    "parse_user_data",
    "reply_topic",
    "request_topic",
    "ros_name",
    "topic_name",
    "typehash_user_data",
]

#: The discovery topic of rmw_dds_common (no ``rt/`` prefix) and its DDS type name.
DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
#: A ROS 2 participant's USER_DATA: what makes ``ros2 node list`` count it (with the NUL
#: rmw_fastrtps and rmw_cyclonedds write after it).
ENCLAVE_USER_DATA = b"enclave=/;\x00"
_CDR_LE = b"\x00\x01\x00\x00"
#: ROS 2 topics' prefixes by kind: messages, service requests and replies.
_PREFIXES = ("rt/", "rq/", "rr/")


def gid_size(distro: str) -> int:
    """Return the bytes of an rmw GID on ``ros_discovery_info`` for a distribution."""
    return 24 if distro == "humble" else 16


def topic_name(name: str) -> str:
    """Return the DDS topic of ROS topic ``name``: ``/odom`` -> ``rt/odom``."""
    return "rt/" + name.strip("/")


def request_topic(service: str) -> str:
    """Return the DDS request topic of a service: ``/reset`` -> ``rq/resetRequest``."""
    return "rq/" + service.strip("/") + "Request"


def reply_topic(service: str) -> str:
    """Return the DDS reply topic of a service: ``/reset`` -> ``rr/resetReply``."""
    return "rr/" + service.strip("/") + "Reply"


def ros_name(dds_topic: str) -> tuple[str, str] | None:
    """Return (kind, ROS name) of a DDS topic, kind ``rt``, ``rq`` or ``rr``; None: not ROS's.

    ``rt/odom`` -> (``rt``, ``/odom``); ``rq/resetRequest`` -> (``rq``, ``/reset``).
    """
    prefix = dds_topic[:3]
    if prefix not in _PREFIXES or len(dds_topic) <= 3:
        return None
    rest = dds_topic[3:]
    if prefix == "rq/":
        if not rest.endswith("Request") or len(rest) == len("Request"):
            return None
        rest = rest[: -len("Request")]
    elif prefix == "rr/":
        if not rest.endswith("Reply") or len(rest) == len("Reply"):
            return None
        rest = rest[: -len("Reply")]
    return prefix[:2], "/" + rest


def typehash_user_data(type_hash: str) -> bytes:
    """Return an endpoint's USER_DATA for its RIHS01 type hash (Iron and later)."""
    return f"typehash={type_hash};".encode()


def parse_user_data(data: bytes) -> dict[str, str]:
    """Read ``key=value;`` pairs of a USER_DATA (an unreadable one reads as empty)."""
    text = data.split(b"\x00", 1)[0].decode("utf-8", "replace")
    out: dict[str, str] = {}
    for part in text.split(";"):
        key, sep, value = part.partition("=")
        if sep and key:
            out[key.strip()] = value
    return out


@dataclass(frozen=True, slots=True)
class NodeInfo:
    """One node of a participant: its namespace, name and endpoints' GIDs (16 bytes each)."""

    namespace: str
    name: str
    readers: tuple[bytes, ...] = ()
    writers: tuple[bytes, ...] = ()

    @property
    def fqn(self) -> str:
        """The fully qualified node name (``/ns/name``)."""
        return ("" if self.namespace == "/" else self.namespace.rstrip("/")) + "/" + self.name


@dataclass(frozen=True, slots=True)
class ParticipantInfo:
    """A ``ParticipantEntitiesInfo``: the participant's GID and its nodes."""

    gid: bytes
    nodes: tuple[NodeInfo, ...] = field(default_factory=tuple)


def encode_participant_info(info: ParticipantInfo, size: int) -> bytes:
    """Return the CDR bytes (XCDR1, little-endian, with header) of a ParticipantEntitiesInfo.

    GIDs are cut or zero-filled to ``size`` bytes (:func:`gid_size`).
    """
    out = bytearray(_CDR_LE)

    def align4() -> None:
        out.extend(b"\x00" * (-(len(out) - 4) % 4))

    def gid(value: bytes) -> None:
        out.extend(value[:size].ljust(size, b"\x00"))

    def string(value: str) -> None:
        raw = value.encode()
        align4()
        out.extend(struct.pack("<I", len(raw) + 1))
        out.extend(raw + b"\x00")

    def gids(values: Sequence[bytes]) -> None:
        align4()
        out.extend(struct.pack("<I", len(values)))
        for value in values:
            gid(value)

    gid(info.gid)
    align4()
    out.extend(struct.pack("<I", len(info.nodes)))
    for node in info.nodes:
        string(node.namespace)
        string(node.name)
        gids(node.readers)
        gids(node.writers)
    return bytes(out)


def decode_participant_info(data: bytes, size: int) -> ParticipantInfo:
    """Read a ParticipantEntitiesInfo written with GIDs of ``size`` bytes.

    Raises:
        ValueError: the bytes are not such a message (truncated, a bad count or string).
    """
    if len(data) < 4 or data[1] not in (0, 1):
        msg = "not CDR (bad encapsulation header)"
        raise ValueError(msg)
    order = "<" if data[1] == 1 else ">"
    body = memoryview(data)[4:]
    pos = 0

    def take(n: int) -> bytes:
        nonlocal pos
        if n < 0 or pos + n > len(body):
            msg = f"truncated at byte {pos + 4} (wanted {n} more)"
            raise ValueError(msg)
        chunk = bytes(body[pos : pos + n])
        pos += n
        return chunk

    def u32() -> int:
        nonlocal pos
        pos += -pos % 4
        value: int = struct.unpack(order + "I", take(4))[0]
        return value

    def count() -> int:
        n = u32()
        if n > len(body):
            msg = f"sequence of {n} elements in {len(body)} bytes"
            raise ValueError(msg)
        return n

    def string() -> str:
        n = count()
        raw = take(n)
        if not raw or raw[-1] != 0:
            msg = "string without its NUL"
            raise ValueError(msg)
        return raw[:-1].decode()

    gid = take(size)
    nodes = []
    for _ in range(count()):
        namespace = string()
        name = string()
        readers = tuple(take(size) for _ in range(count()))
        writers = tuple(take(size) for _ in range(count()))
        nodes.append(NodeInfo(namespace, name, readers, writers))
    if len(body) - pos > 3:
        msg = f"{len(body) - pos} bytes left over (GIDs of another size?)"
        raise ValueError(msg)
    return ParticipantInfo(gid, tuple(nodes))


def read_participant_info(data: bytes, preferred: int) -> ParticipantInfo:
    """Read a ParticipantEntitiesInfo of either GID size, ``preferred`` tried first.

    A Humble peer (24-byte GIDs) and a Jazzy one (16) may share a domain: each message is read
    with the size that accounts for all its bytes.

    Raises:
        ValueError: neither size reads it.
    """
    other = 40 - preferred
    try:
        return decode_participant_info(data, preferred)
    except ValueError as first:
        try:
            return decode_participant_info(data, other)
        except ValueError:
            raise first from None


def guid_gid(guid: bytes) -> bytes:
    """Return the 16-byte GID of a DDS GUID (its prefix and entity id), as rmw writes it."""
    return guid[:16].ljust(16, b"\x00")


def node_entities(nodes: Mapping[str, tuple[list[bytes], list[bytes]]]) -> tuple[NodeInfo, ...]:
    """Return the NodeInfo of ``{fqn: (reader gids, writer gids)}`` (sorted by name)."""
    out = []
    for fqn in sorted(nodes):
        readers, writers = nodes[fqn]
        path = "/" + fqn.strip("/")
        namespace, _, name = path.rpartition("/")
        out.append(NodeInfo(namespace or "/", name, tuple(readers), tuple(writers)))
    return tuple(out)
