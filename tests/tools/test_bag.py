from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader

from simbridge.msgs import Converter, TypeRegistry
from simbridge.tools.bag import BagError, BagWriter, read_messages


@pytest.fixture(scope="module")
def registry() -> TypeRegistry:
    return TypeRegistry()


def canonical(registry: TypeRegistry, type_name: str, msg: dict) -> dict:
    return Converter(registry, lambda: (1, 2)).from_json(type_name, msg)


def test_messages_round_trip_through_cdr(registry: TypeRegistry, tmp_path: Path) -> None:
    """Odometry, LaserScan (float32 arrays), Image (uint8[] as base64) and String survive."""
    odom = canonical(
        registry, "nav_msgs/msg/Odometry", {"pose": {"pose": {"position": {"x": 1.5}}}}
    )
    scan = canonical(registry, "sensor_msgs/msg/LaserScan", {"ranges": [0.5, 1.0, 3.5]})
    image = canonical(registry, "sensor_msgs/msg/Image", {"data": "AAEC", "height": 1})
    text = canonical(registry, "std_msgs/msg/String", {"data": "hello"})
    writer = BagWriter(tmp_path / "bag", registry)
    writer.write("/odom", "nav_msgs/msg/Odometry", odom, 1_000)
    writer.write("/scan", "sensor_msgs/msg/LaserScan", scan, 2_000)
    writer.write("/image", "sensor_msgs/msg/Image", image, 3_000)
    writer.write("/chatter", "std_msgs/msg/String", text, 4_000)
    writer.close()
    assert sorted(p.name for p in (tmp_path / "bag").iterdir()) == ["bag.mcap", "metadata.yaml"]
    got = {topic: (stamp, msg) for topic, _type, stamp, msg in read_messages(tmp_path / "bag")}
    assert got["/odom"][0] == 1_000
    assert got["/odom"][1]["pose"]["pose"]["position"]["x"] == 1.5
    assert got["/scan"][1]["ranges"] == [0.5, 1.0, 3.5]
    assert got["/image"][1]["data"] == [0, 1, 2]
    assert got["/chatter"][1] == {"data": "hello"}
    # the .mcap file itself works as the path too
    assert len(list(read_messages(tmp_path / "bag" / "bag.mcap"))) == 4


def test_foxglove_mcap_library_decodes_every_message(
    registry: TypeRegistry, tmp_path: Path
) -> None:
    """The official MCAP reader with its ROS 2 decoder parses the schemas simbridge writes."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    writer = BagWriter(tmp_path / "fox", registry, segment_seconds=0.0)
    scan = canonical(registry, "sensor_msgs/msg/LaserScan", {"ranges": [0.5, 1.0]})
    odom = canonical(registry, "nav_msgs/msg/Odometry", {"child_frame_id": "base_link"})
    for k in range(3):
        writer.write("/scan", "sensor_msgs/msg/LaserScan", scan, 10 + k)
        writer.write("/odom", "nav_msgs/msg/Odometry", odom, 20 + k)
        writer.tick()
    writer.close()
    with (tmp_path / "fox" / "fox.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [(ch.topic, msg) for _s, ch, _m, msg in reader.iter_decoded_messages()]
        summary = reader.get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count == 6
    assert [t for t, _ in decoded].count("/scan") == 3
    by_topic = dict(decoded)
    assert list(by_topic["/scan"].ranges) == [0.5, 1.0]
    assert by_topic["/odom"].child_frame_id == "base_link"


def test_closed_segments_read_without_close(registry: TypeRegistry, tmp_path: Path) -> None:
    """What a killed recorder leaves: closed segments listed in metadata.yaml, rosbags reads it."""
    writer = BagWriter(tmp_path / "cut", registry, segment_seconds=0.0)
    msg = canonical(registry, "std_msgs/msg/String", {"data": "x"})
    for k in range(3):
        writer.write("/chatter", "std_msgs/msg/String", msg, 1_000 + k)
        writer.tick()
    writer.write("/chatter", "std_msgs/msg/String", msg, 9_999)  # open segment: lost
    with Reader(tmp_path / "cut") as reader:
        assert reader.message_count == 3
        assert [stamp for _c, stamp, _raw in reader.messages()] == [1_000, 1_001, 1_002]
    assert len(list((tmp_path / "cut").glob("cut_*.mcap"))) == 3
    writer.abort()


def test_existing_output_is_refused(registry: TypeRegistry, tmp_path: Path) -> None:
    with pytest.raises(BagError, match="exists already"):
        BagWriter(tmp_path, registry)


def test_an_empty_recording_is_still_a_bag(registry: TypeRegistry, tmp_path: Path) -> None:
    BagWriter(tmp_path / "empty", registry).close()
    with Reader(tmp_path / "empty") as reader:
        assert reader.message_count == 0


def test_unreadable_bag_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="cannot read bag"):
        list(read_messages(tmp_path / "nope"))
