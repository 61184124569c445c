"""The harness's second DDS implementation: a ROS 2 node on Cyclone DDS (PyPI ``cyclonedds``).

The C++ peer (``peer/``) is Fast DDS, as rmw_fastrtps_cpp; this one is Cyclone DDS, as
rmw_cyclonedds_cpp (the other Tier-1 ROS 2 DDS middleware). It uses none of simbridge's code:
its types are its own ``@final`` IDL structs (XCDR1, as the ROS 2 middlewares write) under their
ROS 2 DDS names, so a check that passes between the two peers shows the harness and the wire
right before simbridge is in the picture. (dust-dds, the other candidate, cannot carry these
types: its 0.16 Python binding serializes no float32/float64 and no nested struct.)

It speaks ddspeer's language: the same options where it has them (``--domain``, ``--node``,
``--distro``, ``--no-announce``, ``--echo /odom|/scan|/tf|/tf_static|/cmd_vel|/peer_chatter``,
``--cmd-vel VX,WZ``, ``--rate``, ``--duration``), the same JSON events on stdout
(``participant_created``, ``ready``, ``participant``, ``endpoint``, ``nodes``, ``sample``,
``stopping``, ``stopped``) and stdin commands (``cmd_vel VX WZ``, ``quit``).
"""

import argparse
import json
import os
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic


# --- the ROS types, in their ROS 2 DDS names (rosidl_generator_dds_idl) ----------------------


@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@final
@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@final
@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str = ""


@final
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@final
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@final
@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@final
@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@final
@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose = field(default_factory=Pose)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@final
@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@final
@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist = field(default_factory=Twist)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@final
@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


@final
@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header = field(default_factory=Header)
    angle_min: float32 = 0.0
    angle_max: float32 = 0.0
    angle_increment: float32 = 0.0
    time_increment: float32 = 0.0
    scan_time: float32 = 0.0
    range_min: float32 = 0.0
    range_max: float32 = 0.0
    ranges: sequence[float32] = field(default_factory=list)
    intensities: sequence[float32] = field(default_factory=list)


@final
@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@final
@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@final
@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped] = field(default_factory=list)


def discovery_types(size: int) -> tuple[Any, Any, Any]:
    """rmw_dds_common's Gid, NodeEntitiesInfo, ParticipantEntitiesInfo with ``size``-byte Gids."""

    @final
    @dataclass
    class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
        data: array[uint8, size]

    @final
    @dataclass
    class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
        node_namespace: str
        node_name: str
        reader_gid_seq: sequence[Gid]
        writer_gid_seq: sequence[Gid]

    @final
    @dataclass
    class ParticipantEntitiesInfo(
        IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
    ):
        gid: Gid
        node_entities_info_seq: sequence[NodeEntitiesInfo]

    return Gid, NodeEntitiesInfo, ParticipantEntitiesInfo


#: ROS type, DDS struct and QoS kind of each topic this peer knows
TOPICS: dict[str, tuple[str, Any, bool]] = {
    "/odom": ("nav_msgs/msg/Odometry", Odometry, False),
    "/scan": ("sensor_msgs/msg/LaserScan", LaserScan, False),
    "/tf": ("tf2_msgs/msg/TFMessage", TFMessage, False),
    "/tf_static": ("tf2_msgs/msg/TFMessage", TFMessage, True),
    "/cmd_vel": ("geometry_msgs/msg/Twist", Twist, False),
    "/peer_chatter": ("std_msgs/msg/String", String, False),
}


def emit(event: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(event) + "\n")
    sys.stdout.flush()


def to_json(value: Any) -> Any:
    if isinstance(value, IdlStruct):
        return {name: to_json(getattr(value, name)) for name in value.__dataclass_fields__}
    if isinstance(value, list):
        return [to_json(item) for item in value]
    return value


def qos(latched: bool, depth: int) -> Qos:
    """ROS's default profile (reliable, volatile, keep last 10), or tf2's latched one."""
    return Qos(
        Policy.Reliability.Reliable(100_000_000),
        Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )


def user_data(policy_holder: Any) -> str:
    data = policy_holder.qos[Policy.Userdata] if policy_holder.qos else None
    raw = bytes(data.data) if data is not None else b""
    return raw.decode("latin-1").replace("\0", "\\0")


def kind_names(holder: Any) -> tuple[str, str]:
    q = holder.qos
    reliability = q[Policy.Reliability] if q else None
    durability = q[Policy.Durability] if q else None
    rel = "best_effort" if reliability == Policy.Reliability.BestEffort else "reliable"
    if durability == Policy.Durability.TransientLocal:
        dur = "transient_local"
    else:
        dur = "volatile" if durability == Policy.Durability.Volatile else "other"
    return rel, dur


class Peer:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.cmd = args.cmd_vel
        self.participant = DomainParticipant(args.domain, qos=Qos(Policy.Userdata(b"enclave=/;\0")))
        self.guid = self.participant.guid.bytes.hex()
        emit({"event": "participant_created", "guid": self.guid, "domain": args.domain})
        # as an rmw context: ros_discovery_info's writer and reader first (rmw_dds_common), the
        # participant's entry (no nodes yet) written at once, rewritten as nodes come
        self.size = 24 if args.distro == "humble" else 16
        self.gid, self.node_info, self.info = discovery_types(self.size)
        info_topic = Topic(self.participant, "ros_discovery_info", self.info)
        self.info_writer = DataWriter(self.participant, info_topic, qos=qos(True, 1))
        # readers keep all: the topic has no key, so keep-last 1 would keep one participant
        reader_qos = qos(True, 1)
        reader_qos += Qos(Policy.History.KeepAll)
        self.info_reader = DataReader(self.participant, info_topic, qos=reader_qos)
        own_gid = self.to_gid(self.participant.guid.bytes)
        if args.announce:
            self.info_writer.write(self.info(gid=own_gid, node_entities_info_seq=[]))
        self.readers: list[tuple[str, str, DataReader]] = []
        self.reader_guids: list[bytes] = []
        self.writer_guids: list[bytes] = []
        for name in args.echo:
            ros_type, struct, latched = TOPICS[name]
            topic = Topic(self.participant, "rt" + name, struct)
            reader = DataReader(self.participant, topic, qos=qos(latched, 100 if latched else 10))
            self.readers.append((name, ros_type, reader))
            self.reader_guids.append(reader.guid.bytes)
        self.cmd_writer: DataWriter | None = None
        if self.cmd is not None:
            topic = Topic(self.participant, "rt/cmd_vel", Twist)
            self.cmd_writer = DataWriter(self.participant, topic, qos=qos(False, 10))
            self.writer_guids.append(self.cmd_writer.guid.bytes)
        if args.announce:
            self.announce(args.namespace, args.node)
        self.builtin = [
            ("participant", BuiltinDataReader(self.participant, BuiltinTopicDcpsParticipant)),
            ("writer", BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)),
            ("reader", BuiltinDataReader(self.participant, BuiltinTopicDcpsSubscription)),
        ]
        emit({"event": "ready", "guid": self.guid, "node": args.node})

    def to_gid(self, raw: bytes) -> Any:
        return self.gid(data=list(raw.ljust(self.size, b"\0")))

    def announce(self, namespace: str, name: str) -> None:
        entry = self.node_info(
            node_namespace=namespace,
            node_name=name,
            reader_gid_seq=[self.to_gid(g) for g in self.reader_guids],
            writer_gid_seq=[self.to_gid(g) for g in self.writer_guids],
        )
        gid = self.to_gid(self.participant.guid.bytes)
        self.info_writer.write(self.info(gid=gid, node_entities_info_seq=[entry]))

    def poll(self) -> None:
        own = self.participant.guid
        for kind, reader in self.builtin:
            for s in reader.take(200):
                if kind == "participant":
                    if s.key != own:
                        ev = {"guid": s.key.bytes.hex(), "user_data": user_data(s)}
                        emit({"event": "participant", "name": "", "alive": True, **ev})
                    continue
                if s.participant_key == own:
                    continue
                rel, dur = kind_names(s)
                emit(
                    {
                        "event": "endpoint",
                        "kind": kind,
                        "guid": s.key.bytes.hex(),
                        "topic": s.topic_name,
                        "type": s.type_name,
                        "reliability": rel,
                        "durability": dur,
                        "user_data": user_data(s),
                        "alive": True,
                    }
                )
        for s in self.info_reader.take(20):
            emit(
                {
                    "event": "nodes",
                    "gid": bytes(s.gid.data[:16]).hex(),
                    "gid_size": self.size,
                    "nodes": [
                        {
                            "namespace": n.node_namespace,
                            "name": n.node_name,
                            "readers": [bytes(g.data[:16]).hex() for g in n.reader_gid_seq],
                            "writers": [bytes(g.data[:16]).hex() for g in n.writer_gid_seq],
                        }
                        for n in s.node_entities_info_seq
                    ],
                }
            )
        for name, ros_type, reader in self.readers:
            for s in reader.take(20):
                emit({"event": "sample", "topic": name, "type": ros_type, "data": to_json(s)})

    def read_commands(self) -> None:
        for line in sys.stdin:
            words = line.split()
            if words and words[0] == "quit":
                break
            if len(words) == 3 and words[0] == "cmd_vel":
                with self.lock:
                    self.cmd = (float(words[1]), float(words[2]))
            elif words:
                emit({"event": "error", "error": f"unknown command {line.strip()}"})
        self.stop.set()

    def run(self) -> None:
        threading.Thread(target=self.read_commands, daemon=True).start()
        start = next_pub = time.monotonic()
        while not self.stop.is_set():
            now = time.monotonic()
            if self.args.duration and now - start >= self.args.duration:
                break
            self.poll()
            if self.cmd_writer is not None and now >= next_pub:
                with self.lock:
                    vx, wz = self.cmd
                self.cmd_writer.write(Twist(linear=Vector3(x=vx), angular=Vector3(z=wz)))
                next_pub += 1.0 / self.args.rate
            time.sleep(0.01)
        emit({"event": "stopping"})


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID") or 0))
    parser.add_argument("--node", default="second_peer")
    parser.add_argument("--namespace", default="/")
    parser.add_argument("--distro", choices=["humble", "jazzy", "kilted"], default="humble")
    parser.add_argument("--no-announce", dest="announce", action="store_false")
    parser.add_argument("--echo", action="append", default=[], choices=sorted(TOPICS))
    parser.add_argument("--cmd-vel", type=lambda v: tuple(float(x) for x in v.split(",")))
    parser.add_argument("--rate", type=float, default=10.0)
    parser.add_argument("--duration", type=float, default=0.0)
    args = parser.parse_args(argv)
    if args.cmd_vel is not None and len(args.cmd_vel) != 2:
        parser.error("--cmd-vel wants VX,WZ")
    return args


def main(argv: list[str]) -> None:
    peer = Peer(parse(argv))
    peer.run()
    emit({"event": "stopped"})
    os._exit(0)  # the stdin thread may still block in a read


if __name__ == "__main__":
    main(sys.argv[1:])
