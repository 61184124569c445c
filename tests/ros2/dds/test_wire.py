"""What the ROS 2 DDS middlewares put on the wire: names, USER_DATA, ros_discovery_info."""

from __future__ import annotations

import struct

import pytest

from simbridge.ros2.dds.wire import (
    ENCLAVE_USER_DATA,
    NodeInfo,
    ParticipantInfo,
    decode_participant_info,
    encode_participant_info,
    gid_size,
    node_entities,
    parse_user_data,
    read_participant_info,
    reply_topic,
    request_topic,
    ros_name,
    topic_name,
    typehash_user_data,
)


def test_topic_and_service_names_are_prefixed_as_rmw_writes_them() -> None:
    assert topic_name("/odom") == "rt/odom"
    assert topic_name("/robot1/scan") == "rt/robot1/scan"
    assert request_topic("/reset") == "rq/resetRequest"
    assert reply_topic("/virtual_robot/get_parameters") == "rr/virtual_robot/get_parametersReply"
    assert ros_name("rt/robot1/odom") == ("rt", "/robot1/odom")
    assert ros_name("rq/resetRequest") == ("rq", "/reset")
    assert ros_name("rr/resetReply") == ("rr", "/reset")
    for not_ros in ("ros_discovery_info", "rt/", "rq/reset", "rr/Reply", "DCPSParticipant"):
        assert ros_name(not_ros) is None


def test_user_data_reads_back_with_or_without_its_nul() -> None:
    assert ENCLAVE_USER_DATA == b"enclave=/;\x00"
    assert parse_user_data(ENCLAVE_USER_DATA) == {"enclave": "/"}
    hashed = typehash_user_data("RIHS01_" + "ab" * 32)
    assert hashed == b"typehash=RIHS01_" + b"ab" * 32 + b";"
    assert parse_user_data(hashed) == {"typehash": "RIHS01_" + "ab" * 32}
    assert parse_user_data(b"\xff\xfe garbage") == {}


def test_gid_is_24_bytes_in_humble_and_16_from_iron_on() -> None:
    assert gid_size("humble") == 24
    assert gid_size("jazzy") == gid_size("kilted") == 16


def _info() -> ParticipantInfo:
    guid = bytes(range(12)) + b"\x00\x00\x01\xc1"
    writer = bytes(range(12)) + b"\x00\x00\x02\x03"
    reader = bytes(range(12)) + b"\x00\x00\x03\x04"
    nodes = node_entities({"/virtual_robot": ([reader], [writer]), "/robot1/sim": ([], [])})
    return ParticipantInfo(guid, nodes)


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_participant_info_round_trips_with_the_distros_gid_size(distro: str) -> None:
    size = gid_size(distro)
    info = _info()
    data = encode_participant_info(info, size)
    assert data[:4] == b"\x00\x01\x00\x00"
    back = decode_participant_info(data, size)
    assert back.gid == info.gid.ljust(size, b"\x00")
    assert [n.fqn for n in back.nodes] == ["/robot1/sim", "/virtual_robot"]
    robot = back.nodes[1]
    assert (robot.namespace, robot.name) == ("/", "virtual_robot")
    assert robot.writers == (info.nodes[1].writers[0].ljust(size, b"\x00"),)
    # a reader of the other distribution still reads it (a Humble and a Jazzy peer in a domain)
    assert read_participant_info(data, 40 - size).nodes[1].fqn == "/virtual_robot"


def test_participant_info_layout_is_plain_little_endian_cdr() -> None:
    info = ParticipantInfo(b"\x01" * 16, (NodeInfo("/", "n", (), (b"\x02" * 16,)),))
    data = encode_participant_info(info, 16)
    body = data[4:]
    assert body[:16] == b"\x01" * 16
    assert struct.unpack_from("<I", body, 16) == (1,)  # one node
    assert struct.unpack_from("<I", body, 20) == (2,) and body[24:26] == b"/\x00"
    assert struct.unpack_from("<I", body, 28) == (2,) and body[32:34] == b"n\x00"
    assert struct.unpack_from("<II", body, 36) == (0, 1)  # no reader, one writer
    assert body[44:60] == b"\x02" * 16 and len(body) == 60


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"\x00\x01\x00\x00" + b"\x01" * 10,  # a truncated GID
        b"\x00\x01\x00\x00" + b"\x00" * 16 + b"\xff\xff\xff\x7f",  # a huge node count
        b"\x00\x01\x00\x00" + b"\x00" * 16 + struct.pack("<II", 1, 3) + b"abc",  # no NUL
    ],
)
def test_a_bad_participant_info_is_a_value_error_not_a_crash(data: bytes) -> None:
    with pytest.raises(ValueError):
        read_participant_info(data, 16)
