"""rmw_zenoh's key expressions, tokens and QoS strings (examples from rmw_zenoh's docs)."""

from __future__ import annotations

import pytest

from simbridge.ros2.names import (
    LATCHED_QOS,
    SENSOR_QOS,
    Entity,
    Qos,
    dds_type,
    demangle,
    entity_gid,
    mangle,
    ros_type,
    split_node,
    topic_keyexpr,
)


def test_topic_keyexpr_drops_the_outer_slashes_and_spells_the_dds_type() -> None:
    key = topic_keyexpr(2, "/add_two_ints", dds_type("example_interfaces/srv/AddTwoInts"), "H")
    assert key == "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/H"
    assert topic_keyexpr(0, "/r1/odom/", "T", "H") == "0/r1/odom/T/H"


def test_dds_type_round_trips_and_refuses_other_spellings() -> None:
    assert ros_type(dds_type("nav_msgs/msg/Odometry")) == "nav_msgs/msg/Odometry"
    with pytest.raises(ValueError, match="pkg::msg::dds_::Type_"):
        ros_type("nav_msgs/msg/Odometry")
    with pytest.raises(ValueError, match="pkg/msg/Type"):
        dds_type("Odometry")


def test_mangling_writes_every_slash_as_percent() -> None:
    assert mangle("/r1/odom") == "%r1%odom"
    assert demangle("%r1%odom") == "/r1/odom"


def test_node_token_is_rmw_zenohs() -> None:
    ns, name = split_node("/virtual_robot")
    node = Entity(0, "abc", "3", "3", "NN", ns, name)
    assert node.token() == "@ros2_lv/0/abc/3/3/NN/%/%/virtual_robot"
    assert Entity.parse(node.token()) == node
    assert split_node("/r1/driver") == ("/r1", "driver")


def test_endpoint_token_round_trips_with_qos() -> None:
    token = (
        "@ros2_lv/0/abc/0/11/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,"
    )
    entity = Entity.parse(token)
    assert (entity.kind, entity.name, entity.type) == ("MP", "/chatter", "std_msgs/msg/String")
    assert entity.qos == Qos(depth=7)
    assert entity.node_fqn == "/talker"
    assert entity.token() == token


def test_qos_fields_equal_to_rmw_zenohs_defaults_are_left_empty() -> None:
    assert Qos().encode() == "::,10:,:,:,,"
    assert LATCHED_QOS.encode() == ":1:,1:,:,:,,"
    assert SENSOR_QOS.encode() == "2::,5:,:,:,,"
    assert Qos(depth=42).encode() == "::,:,:,:,,"
    assert Qos.decode("::,:,:,:,,").depth == 42
    assert Qos.decode(":1:,1:,:,:,,").transient_local


@pytest.mark.parametrize(
    "token",
    [
        "@ros2_lv/0/abc/0/1/XX/%/%/n",  # unknown kind
        "@ros2_lv/0/abc/0/1/MP/%/%/n",  # endpoint without name and type
        "@other/0/abc/0/1/NN/%/%/n",
        "@ros2_lv/0/abc//1/NN/%/%/n",
        "@ros2_lv/0/abc/0/1/MP/%/%/n/%t/NotDds/H/::,1:,:,:,,",
        "@ros2_lv/0/abc/0/1/MP/%/%/n/%t/a::msg::dds_::B_/H/nonsense",
    ],
)
def test_malformed_tokens_are_refused_with_the_reason(token: str) -> None:
    with pytest.raises(ValueError):
        Entity.parse(token)


def test_gids_are_16_bytes_and_differ_per_entity() -> None:
    assert len(entity_gid("a")) == 16
    assert entity_gid("a") != entity_gid("b")
