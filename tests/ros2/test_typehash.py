"""Type hashes per distribution, checked against values rmw_zenoh's docs show."""

from __future__ import annotations

from simbridge.msgs import TypeRegistry
from simbridge.ros2.typehash import NO_HASH, TypeHasher


def test_jazzy_hashes_messages_as_rosidl_does() -> None:
    hasher = TypeHasher(TypeRegistry(), "jazzy")
    assert hasher.message("std_msgs/msg/String") == (
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )


def test_service_hash_covers_request_response_and_event_with_uint8_gid() -> None:
    hasher = TypeHasher(TypeRegistry(), "kilted")
    # rosbags' own ServiceEventInfo (char[16] client_gid) would give RIHS01_baab5d...
    assert hasher.service("example_interfaces/srv/AddTwoInts") == (
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
    )


def test_humble_has_no_type_hashes() -> None:
    hasher = TypeHasher(TypeRegistry(), "humble")
    assert hasher.message("nav_msgs/msg/Odometry") == NO_HASH == "TypeHashNotSupported"
    assert hasher.service("std_srvs/srv/Empty") == NO_HASH


def test_hashes_come_from_the_registry_definitions_without_rosbags_store() -> None:
    """The shipped definitions hash as rosbags' store does, and hashing does not build it."""
    registry = TypeRegistry()
    hasher = TypeHasher(registry, "jazzy")
    names = ["nav_msgs/msg/Odometry", "sensor_msgs/msg/LaserScan", "tf2_msgs/msg/TFMessage"]
    hashes = [hasher.message(name) for name in names]
    service = hasher.service("std_srvs/srv/SetBool")
    assert registry._store is None
    assert hashes == [str(registry.store.hash_rihs01(name)) for name in names]
    assert service.startswith("RIHS01_") and len(service) == len("RIHS01_") + 64
