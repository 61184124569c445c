"""Cyclone DDS's warnings read back: which line says a sample was refused, and whose it was."""

from __future__ import annotations

from simbridge.ros2.dds.trace import RefusedSample, refused_sample


def test_a_refused_sample_names_its_writer_topic_type_and_reason() -> None:
    line = (
        "1796184206.530101 [48]       recv: data(application, vendor 1.15): "
        "10f7f01:1341f1cf:0:303 #1: deserialization rt/cmd_vel/geometry_msgs::msg::dds_::Twist_ "
        "failed (for reasons unknown)"
    )
    assert refused_sample(line) == RefusedSample(
        bytes.fromhex("010f7f011341f1cf0000000000000303"),
        "rt/cmd_vel",
        "geometry_msgs::msg::dds_::Twist_",
        "for reasons unknown",
    )


def test_other_lines_of_cyclones_log_are_no_refusals() -> None:
    assert refused_sample("1796184206.5 [48] recv: DATA(10f7f01:c641ce0b:0:100c2 #2)") is None
    assert refused_sample("") is None
