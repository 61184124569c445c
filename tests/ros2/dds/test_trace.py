"""Cyclone DDS's log read back: which line says a sample was refused, whose it was, and the rest."""

from __future__ import annotations

from simbridge.ros2.dds.trace import CycloneLine, RefusedSample, cyclone_line, refused_sample


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


def test_another_line_loses_its_header_and_is_of_one_kind_whatever_its_numbers() -> None:
    first = cyclone_line(
        "1796193722.490436 [57]       recv: malformed packet received from vendor 1.15 length 32"
        " state parse:DATA <52545053 0203010f> smid 0x15 flags 0x1 otnh 256"
    )
    second = cyclone_line(
        "1796193723.5 [57]       recv: malformed packet received from vendor 1.16 length 48"
        " state parse:DATA <52545053 0203010e> smid 0x15 flags 0x1 otnh 28"
    )
    assert first is not None and second is not None
    assert first.text.startswith("malformed packet received from vendor 1.15 length 32")
    assert first.kind == second.kind != second.text
    line = cyclone_line("1796193906.44 [57]       tev: nosuch0: does not match an interface.")
    assert line == CycloneLine(
        "nosuch# does not match an interface.", "nosuch0: does not match an interface."
    )
    assert cyclone_line("  ") is None
