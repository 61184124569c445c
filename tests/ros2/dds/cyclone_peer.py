"""A ROS 2 node on DDS as rmw_cyclonedds makes one, in its own process, for the tests.

It uses Cyclone DDS's own typed Python (de)serialization (not simbridge's CDR code): it lists
the ROS topics and nodes it discovers, echoes the first sample of ``/odom``, ``/scan``,
``/tf`` and ``/tf_static`` (transient-local: a late joiner), publishes ``/cmd_vel`` and, as
node ``/talker``, ``/chatter`` (std_msgs/String), announced on ``ros_discovery_info`` with
24- or 16-byte GIDs. Runs until it saw everything asked for or ``--seconds`` passed, then
prints one JSON line: what it saw.

    python cyclone_peer.py --domain 7 --seconds 10 --drive 0.3
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from typing import Any

from cyclonedds._clayer import ddspy_write
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from simbridge.msgs.registry import TypeRegistry
from simbridge.ros2.dds.types import IdlTypes
from simbridge.ros2.dds.wire import (
    DISCOVERY_TOPIC,
    ENCLAVE_USER_DATA,
    NodeInfo,
    ParticipantInfo,
    encode_participant_info,
    gid_size,
)


ECHO = {
    "/odom": ("nav_msgs/msg/Odometry", False),
    "/scan": ("sensor_msgs/msg/LaserScan", False),
    "/tf": ("tf2_msgs/msg/TFMessage", False),
    "/tf_static": ("tf2_msgs/msg/TFMessage", True),
}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--drive", type=float, default=0.0, help="linear.x on /cmd_vel")
    parser.add_argument("--distro", default="jazzy")
    parser.add_argument(
        "--call",
        nargs=3,
        action="append",
        default=[],
        metavar=("SERVICE", "TYPE", "JSON"),
        help="call a service as rmw_cyclonedds does (the request header in the payload)",
    )
    parser.add_argument(
        "--unknown-type",
        action="store_true",
        help="also publish /mystery, of a type no registry knows (foo_msgs/msg/Mystery)",
    )
    args = parser.parse_args()

    types = IdlTypes(TypeRegistry())
    participant = DomainParticipant(args.domain, qos=Qos(Policy.Userdata(ENCLAVE_USER_DATA)))
    reliable = Policy.Reliability.Reliable(100_000_000)

    def qos(latched: bool) -> Qos:
        durability = Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile
        return Qos(reliable, durability, Policy.History.KeepLast(10))

    def topic(name: str, type_name: str) -> Topic:
        return Topic(participant, "rt/" + name.strip("/"), types.get(type_name))

    readers = {
        name: DataReader(participant, topic(name, t), qos=qos(latched))
        for name, (t, latched) in ECHO.items()
    }
    twist, vector = types.get("geometry_msgs/msg/Twist"), types.get("geometry_msgs/msg/Vector3")
    string = types.get("std_msgs/msg/String")
    cmd = DataWriter(participant, topic("/cmd_vel", "geometry_msgs/msg/Twist"), qos=qos(False))
    chatter = DataWriter(participant, topic("/chatter", "std_msgs/msg/String"), qos=qos(False))
    size = gid_size(args.distro)
    gid = types.named("rmw_dds_common::msg::dds_::Gid_", {"data": _t().array[_t().uint8, size]})
    node = types.named(
        "rmw_dds_common::msg::dds_::NodeEntitiesInfo_",
        {
            "node_namespace": _t().bounded_str[256],
            "node_name": _t().bounded_str[256],
            "reader_gid_seq": _t().sequence[gid],
            "writer_gid_seq": _t().sequence[gid],
        },
    )
    info_type = types.named(
        "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_",
        {"gid": gid, "node_entities_info_seq": _t().sequence[node]},
    )
    info_topic = Topic(participant, DISCOVERY_TOPIC, info_type)
    info_qos = Qos(reliable, Policy.Durability.TransientLocal, Policy.History.KeepLast(1))
    info_writer = DataWriter(participant, info_topic, qos=info_qos)
    info_reader = DataReader(participant, info_topic, qos=info_qos)
    ours = ParticipantInfo(
        participant.guid.bytes,
        (NodeInfo("/", "talker", (), (chatter.guid.bytes, cmd.guid.bytes)),),
    )
    data = encode_participant_info(ours, size)
    info_writer.write(info_type.deserialize(data))  # rmw's bytes, through Cyclone's types
    publications = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)

    # (bytes that are not CDR of their type come from ddspeer --raw: a Cyclone writer checks
    # what it writes against its type, and a Cyclone reader matches only a writer whose type
    # information is assignable to its own)
    raw = []
    if args.unknown_type:
        mystery = types.named("foo_msgs::msg::dds_::Mystery_", {"x": _t().int32})
        mystery_topic = Topic(participant, "rt/mystery", mystery)
        raw.append(
            (DataWriter(participant, mystery_topic, qos=qos(False)), b"\x00\x01\0\0\x07\0\0\0")
        )
    calls = [_Client(participant, types, qos(False), *call) for call in args.call]
    seen: dict[str, Any] = {"topics": {}, "nodes": [], "samples": {}, "replies": {}}
    deadline = time.monotonic() + args.seconds
    while time.monotonic() < deadline:
        for sample in publications.take(200):
            if sample.participant_key != participant.guid and sample.topic_name.startswith("rt/"):
                seen["topics"][sample.topic_name] = sample.type_name
        for sample in info_reader.take(20):
            if bytes(sample.gid.data[:16]) == participant.guid.bytes:
                continue
            for n in sample.node_entities_info_seq:
                fqn = NodeInfo(n.node_namespace, n.node_name).fqn
                if fqn not in seen["nodes"]:
                    seen["nodes"].append(fqn)
        for name, reader in readers.items():
            for sample in reader.take(5):
                if name not in seen["samples"]:
                    seen["samples"][name] = _summary(name, sample)
        for client in calls:
            reply = client.poll()
            if reply is not None:
                seen["replies"][client.service] = reply
        for writer, data in raw:
            ddspy_write(writer._ref, data)
        cmd.write(twist(linear=vector(args.drive, 0.0, 0.0), angular=vector(0.0, 0.0, 0.0)))
        chatter.write(string(data="hello from dds"))
        time.sleep(0.1)
    seen["info_matched"] = info_reader.get_subscription_matched_status().current_count
    print(json.dumps(seen), flush=True)


class _Client:
    """A service client on rmw_cyclonedds's wire: rq/<name>Request and rr/<name>Reply."""

    def __init__(
        self, participant: Any, types: IdlTypes, qos: Qos, service: str, type_name: str, text: str
    ) -> None:
        registry = types.registry
        request, response = registry.service(type_name)
        self.service = service
        self.request = types.wrapped(request)
        name = service.strip("/")
        self.writer = DataWriter(
            participant, Topic(participant, f"rq/{name}Request", self.request), qos=qos
        )
        self.reader = DataReader(
            participant, Topic(participant, f"rr/{name}Reply", types.wrapped(response)), qos=qos
        )
        self.args = json.loads(text) or {"structure_needs_at_least_one_member": 0}
        self.guid = int.from_bytes(self.writer.guid.bytes[8:], "little")
        self.sent = False

    def poll(self) -> Any:
        if not self.sent:
            matched = self.writer.get_publication_matched_status().current_count
            if matched and self.reader.get_subscription_matched_status().current_count:
                self.writer.write(
                    self.request(client_guid=self.guid, sequence_number=1, **self.args)
                )
                self.sent = True
            return None
        for sample in self.reader.take(5):
            if sample.client_guid == self.guid and sample.sequence_number == 1:
                out = dataclasses.asdict(sample)
                del out["client_guid"], out["sequence_number"]
                return out
        return None


def _t() -> Any:
    from cyclonedds.idl import types

    return types


def _summary(name: str, sample: Any) -> Any:
    if name == "/odom":
        return {"frame_id": sample.header.frame_id, "child_frame_id": sample.child_frame_id}
    if name == "/scan":
        return {"frame_id": sample.header.frame_id, "ranges": len(sample.ranges)}
    return sorted([t.header.frame_id, t.child_frame_id] for t in sample.transforms)


if __name__ == "__main__":
    main()
