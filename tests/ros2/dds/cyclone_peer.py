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
import json
import time
from typing import Any

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

    seen: dict[str, Any] = {"topics": {}, "nodes": [], "samples": {}}
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
        cmd.write(twist(linear=vector(args.drive, 0.0, 0.0), angular=vector(0.0, 0.0, 0.0)))
        chatter.write(string(data="hello from dds"))
        time.sleep(0.1)
    seen["info_matched"] = info_reader.get_subscription_matched_status().current_count
    print(json.dumps(seen), flush=True)


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
