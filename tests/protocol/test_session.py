from __future__ import annotations

import json

import pytest

from simbridge.errors import ProtocolError
from simbridge.protocol import ClientId, Session, Subscription, ops as o, resolve_name


def test_merged_options_use_min_throttle_min_queue_and_strongest_compression() -> None:
    """Several ids on one topic merge as rosbridge does."""
    sub = Subscription("/scan", "/scan")
    sub.add(o.Subscribe("/scan", id="a", throttle_rate=100, queue_length=5, compression="png"))
    sub.add(o.Subscribe("/scan", id="b", throttle_rate=50, queue_length=9, fragment_size=300))
    sub.add(o.Subscribe("/scan", id="c", throttle_rate=70, compression="cbor"))
    assert (sub.throttle_rate, sub.queue_length, sub.fragment_size) == (50, 0, 300)
    assert sub.compression == "cbor"
    assert sub.remove("c") is False
    assert sub.compression == "png"
    assert sub.remove(None) is True


def test_throttle_drops_messages_inside_the_window() -> None:
    """throttle_rate 100 ms: a message 60 ms after the last one sent is dropped."""
    sub = Subscription("/odom", "/odom")
    sub.add(o.Subscribe("/odom", throttle_rate=100))
    assert sub.admit(1.000)
    assert not sub.admit(1.060)
    assert sub.admit(1.0995)  # half a millisecond early: jitter, still admitted
    assert not sub.admit(1.150)
    assert not sub.admit(1.185)
    assert sub.admit(1.200)


def test_parse_reports_errors_in_place_and_keeps_going() -> None:
    """One bad op in a frame does not hide the good ones."""
    session = Session(ClientId(1))
    items = session.parse('{"op":"subscribe","topic":"/a"} {"op":"nope"}', 0.0)
    assert isinstance(items[0], o.Subscribe)
    assert isinstance(items[1], ProtocolError)
    assert isinstance(session.parse("garbage", 0.0)[0], ProtocolError)


def test_fragments_are_reassembled_into_ops() -> None:
    """Three fragments of a publish op come out as the op once complete."""
    session = Session(ClientId(1))
    text = '{"op":"publish","topic":"/chatter","msg":{"data":"hi"}}'
    pieces = [text[:10], text[10:30], text[30:]]
    frames = [
        json.dumps({"op": "fragment", "id": "m1", "data": p, "num": n, "total": 3})
        for n, p in enumerate(pieces)
    ]
    assert session.parse(frames[2], 0.0) == []
    assert session.parse(frames[0], 0.0) == []
    (op,) = session.parse(frames[1], 0.0)
    assert op == o.Publish("/chatter", {"data": "hi"})


def test_status_level_filters_what_is_sent() -> None:
    """Default level error: warnings are not sent; set_level none silences everything."""
    session = Session(ClientId(1))
    assert session.wants_status("error") and not session.wants_status("warning")
    session.set_level("info")
    assert session.wants_status("warning")
    session.set_level("none")
    assert not session.wants_status("error")
    with pytest.raises(ProtocolError, match="level"):
        session.set_level("loud")


@pytest.mark.parametrize(
    ("name", "resolved"),
    [("odom", "/odom"), ("/odom", "/odom"), ("rosapi/topics", "/rosapi/topics"), ("/a/b/", "/a/b")],
)
def test_names_resolve_against_the_root_namespace(name: str, resolved: str) -> None:
    """Relative names (roslibjs 2.1) become absolute."""
    assert resolve_name(name) == resolved


@pytest.mark.parametrize("name", ["", "/", "a b", "/a//b", "1abc", "/x-y", "a" * 300])
def test_invalid_names_are_refused(name: str) -> None:
    """Names that are not valid ROS names raise ProtocolError."""
    with pytest.raises(ProtocolError, match="not a valid ROS name"):
        resolve_name(name)
