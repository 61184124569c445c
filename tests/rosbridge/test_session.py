from __future__ import annotations

import gc
import json
from typing import Any

import pytest

from simbridge.errors import ProtocolError
from simbridge.rosbridge import (
    Advertised,
    ClientId,
    Limits,
    Pool,
    Provided,
    Refusal,
    Reply,
    Session,
    Subscribed,
    Subscription,
    Unadvertised,
    Unlatched,
    Unsubscribed,
    Withdrawn,
    ops as o,
    resolve_name,
)


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


def test_refused_frames_are_freed_at_once_not_by_the_garbage_collector() -> None:
    """A refused frame leaves no reference cycle: its text goes when its answer is made.

    Errors kept with their tracebacks held Session.parse's frame (the frame's text, the list
    of results): five clients' refused 3 MB fragments held 400 MB until a full collection.
    """
    session = Session(ClientId(1), limits=Limits(fragment_bytes=10_000, fragment_sets=1))
    frames = [
        json.dumps({"op": "fragment", "id": f"f{n}", "data": "x" * 20_000, "num": 0, "total": 2})
        for n in range(3)
    ]
    frames += ["garbage", '{"op":"nope"}', '{"op":"subscribe","topic":"/a\\u0000"}']
    gc.collect()
    gc.disable()
    try:
        for frame in frames:
            (refused,) = session.parse(frame, 0.0)
            assert isinstance(refused, ProtocolError)
        del refused
        assert gc.collect() == 0
    finally:
        gc.enable()


def test_frames_of_more_json_values_than_the_budget_are_refused_unparsed() -> None:
    """frame_values counts a big frame's values before parsing; admins are not limited."""
    session = Session(ClientId(1), limits=Limits(frame_values=1_000))
    many = json.dumps({"op": "publish", "topic": "/a", "msg": {"data": [1] * 1_000}})
    (refused,) = session.parse(many, 0.0)
    assert isinstance(refused, Refusal) and refused.cause == "max_frame_values"
    # 1002 values, two objects and an array
    assert "about 1070 JSON values" in str(refused) and "max_frame_values" in str(refused)
    (refused,) = session.parse(many.encode(), 0.0)  # binary frames too
    assert isinstance(refused, Refusal)
    fits = json.dumps({"op": "publish", "topic": "/a", "msg": {"data": [1] * 900}})
    assert isinstance(session.parse(fits, 0.0)[0], o.Publish)
    # objects become messages field by field in Python: 30 of them count as ~1,000 numbers
    poses = json.dumps({"op": "publish", "topic": "/a", "msg": {"poses": [{"x": 1}] * 30}})
    (refused,) = session.parse(poses, 0.0)
    assert isinstance(refused, Refusal) and refused.cause == "max_frame_values"
    text = json.dumps({"op": "publish", "topic": "/a", "msg": {"data": "x" * 100_000}})
    assert isinstance(session.parse(text, 0.0)[0], o.Publish)  # big, but few values
    session.admit("*", admin=True)
    assert isinstance(session.parse(many, 0.0)[0], o.Publish)


def test_frames_longer_than_the_budget_are_refused_unparsed() -> None:
    """frame_bytes: a student's 1 MB frame is handled in one go (a 9 MB string took 58 ms)."""
    session = Session(ClientId(1), limits=Limits(frame_bytes=1_000))
    long = json.dumps({"op": "publish", "topic": "/a", "msg": {"data": "x" * 1_000}})
    (refused,) = session.parse(long, 0.0)
    assert isinstance(refused, Refusal) and refused.cause == "max_frame_bytes"
    assert f"a frame of {len(long)} characters" in str(refused)
    (refused,) = session.parse(long.encode(), 0.0)
    assert isinstance(refused, Refusal) and "bytes was refused" in str(refused)
    short = json.dumps({"op": "publish", "topic": "/a", "msg": {"data": "x" * 900}})
    assert isinstance(session.parse(short, 0.0)[0], o.Publish)
    session.admit("*", admin=True)
    assert isinstance(session.parse(long, 0.0)[0], o.Publish)


def test_a_reassembled_message_of_too_many_values_is_refused() -> None:
    """Fragments are no way around frame_values: the reassembled text is counted too."""
    session = Session(ClientId(1), limits=Limits(frame_values=1_000))
    text = json.dumps({"op": "publish", "topic": "/a", "msg": {"data": [1] * 2_000}})
    size = len(text) // 4 + 1
    pieces = [text[i : i + size] for i in range(0, len(text), size)]
    for n, piece in enumerate(pieces):
        frame = {"op": "fragment", "id": "m", "data": piece, "num": n, "total": len(pieces)}
        items = session.parse(json.dumps(frame), 0.0)
        assert n == len(pieces) - 1 or items == []
    (refused,) = items
    assert isinstance(refused, Refusal) and refused.cause == "max_frame_values"


def test_status_level_filters_what_is_sent() -> None:
    """Default level error: warnings are not sent; set_level none silences everything."""
    session = Session(ClientId(1))
    assert session.wants_status("error") and not session.wants_status("warning")
    assert session.set_level(o.SetLevel("info")) == ()
    assert session.wants_status("warning")
    session.set_level(o.SetLevel("none"))
    assert not session.wants_status("error")
    assert session.status("error", "x") == ()
    with pytest.raises(ProtocolError, match="level"):
        session.set_level(o.SetLevel("loud"))


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


def budgeted(**limits: Any) -> tuple[Session, Pool]:
    pool = Pool({"subscribe_ids": 5, "advertise_ids": 5, "pending_calls": 3, "latched_bytes": 50})
    return Session(ClientId(1), limits=Limits(**limits), pool=pool), pool


def test_subscribe_ids_are_budgeted_per_topic_per_client_and_globally() -> None:
    """Ids, not topics, are counted; a spent budget is refused by its name; leaving frees."""
    session, pool = budgeted(subscribe_ids=4, ids_per_subscription=2)
    session.subscribe(o.Subscribe("/a", id=1))
    session.subscribe(o.Subscribe("/a", id=1))  # the same id again: replaced, not counted
    session.subscribe(o.Subscribe("/a", id=2))
    with pytest.raises(Refusal, match="max_ids_per_subscription"):
        session.subscribe(o.Subscribe("/a", id=3))
    session.subscribe(o.Subscribe("/b", id=1))
    session.subscribe(o.Subscribe("/c", id=1))
    with pytest.raises(Refusal, match="max_subscribe_ids"):
        session.subscribe(o.Subscribe("/d", id=1))
    other = Session(ClientId(2), pool=pool)
    other.subscribe(o.Subscribe("/x", id=1))
    with pytest.raises(Refusal, match="global_subscribe_ids"):
        other.subscribe(o.Subscribe("/y", id=1))
    assert session.subscribe_ids == 4 and pool.used["subscribe_ids"] == 5
    (effect,) = session.unsubscribe(o.Unsubscribe("/a", id=1))
    assert isinstance(effect, Unsubscribed) and not effect.gone and session.subscribe_ids == 3
    session.close()
    assert pool.used["subscribe_ids"] == 1 and not session.subscriptions


def test_advertise_ids_and_names_are_budgeted() -> None:
    session, pool = budgeted(advertise_ids=3, advertisements=2)
    string = "std_msgs/msg/String"
    session.advertise(o.Advertise("/a", string, id=1), string)
    session.advertise(o.Advertise("/a", string, id=1), string)  # the same id: not counted
    session.advertise(o.Advertise("/a", string, id=2), string)
    session.publish("/b", string)
    with pytest.raises(Refusal, match="max_advertise_ids"):
        session.advertise(o.Advertise("/a", string, id=3), string)
    with pytest.raises(Refusal, match="max_advertisements"):
        session.publish("/c", string)
    assert session.unadvertise(o.Unadvertise("/a", id=1)) == (Unadvertised("/a", 1),)
    assert session.advertises("/a")  # id 2 remains
    assert session.unadvertise(o.Unadvertise("/a")) == (Unadvertised("/a", None),)
    assert not session.advertises("/a") and pool.used["advertise_ids"] == 1


def test_calls_wait_at_most_the_call_timeout_and_are_budgeted() -> None:
    """No timeout: the default; 0 (rosbridge: forever) or too long: the maximum."""
    session, pool = budgeted(pending_calls=2, call_timeout=60.0)
    assert session.call_timeout(None, 5.0) == 5.0
    assert session.call_timeout(0.0, 5.0) == 60.0 == session.call_timeout(1e9, 5.0)
    assert session.call_timeout(2.0, 5.0) == 2.0
    assert session.call_service(o.CallService("/s", id=1), 10.0, waits=False, default=5.0) is None
    assert session.pending_calls == 0  # an in-process service answers at once
    assert session.call_service(o.CallService("/s", id=1), 10.0, waits=True, default=5.0) == 15.0
    session.call_service(o.CallService("/s", id=2, timeout=0), 10.0, waits=True, default=5.0)
    with pytest.raises(Refusal, match="max_pending_calls") as refused:
        session.call_service(o.CallService("/s", id=3), 10.0, waits=True, default=5.0)
    assert refused.value.op == "call_service" and refused.value.op_id == 3
    session.end_call()
    session.close()
    assert pool.used["pending_calls"] == 0


def test_latched_bytes_replace_per_topic_and_are_budgeted() -> None:
    session, pool = budgeted(latched_bytes=40)
    session.latch("/a", 30)
    session.latch("/a", 20)  # replaces its previous message on /a
    session.latch("/b", 20)
    with pytest.raises(Refusal, match="max_latched_bytes"):
        session.latch("/c", 1)
    assert session.latched_bytes == 40 == pool.used["latched_bytes"]
    session.unlatch("/a")
    assert pool.used["latched_bytes"] == 20
    session.close()
    assert pool.used["latched_bytes"] == 0


def test_before_admission_only_a_small_auth_op_is_read() -> None:
    """A client that owes a token: fragments are not reassembled, big frames not decoded."""
    session = Session(ClientId(1), limits=Limits(unauthenticated_frame_bytes=200))
    session.connect("*", False, authenticated=False)
    assert session.guarded and not session.authenticated
    frag = json.dumps({"op": "fragment", "id": "f", "data": "x", "num": 0, "total": 2})
    (refused,) = session.parse(frag, 0.0)
    assert isinstance(refused, Refusal) and "not authenticated" in str(refused)
    assert len(session.defrag) == 0
    (big,) = session.parse("[" * 300, 0.0)
    assert isinstance(big, Refusal) and "limited to 200 bytes" in str(big)
    (call,) = session.parse('{"op":"call_service","service":"/s","id":7}', 0.0)
    assert isinstance(call, Refusal) and (call.op, call.target, call.op_id) == (
        "call_service",
        "/s",
        7,
    )
    auth = {"op": "auth", "mac": "m", "client": "", "dest": "", "rand": "", "t": 0, "level": ""}
    (op,) = session.parse(json.dumps(auth | {"end": 0}), 0.0)
    assert isinstance(op, o.Auth)


def test_refusals_are_told_once_per_cause_per_second_and_counted() -> None:
    session = Session(ClientId(1), limits=Limits(statuses_per_second=3))
    assert session.may_tell("a", 0.0) and not session.may_tell("a", 0.0)
    assert session.may_tell("b", 0.0) and session.may_tell("c", 0.0)
    assert not session.may_tell("d", 0.0)  # three a second in all
    assert session.may_tell("a", 1.0)
    assert session.refusals_untold == 2


def test_ops_resolve_their_names_once_when_made() -> None:
    assert o.Subscribe("odom").name == "/odom"
    assert o.CallService("rosapi/topics").name == "/rosapi/topics"
    with pytest.raises(ProtocolError, match="not a valid ROS name"):
        o.Publish("/a\x00", {})


# -- ops in, effects out ---------------------------------------------------------------------


def test_a_subscribe_says_what_the_graph_delivers_and_an_unsubscribe_what_it_stops() -> None:
    """Subscribed carries the merged subscription (new once); Unsubscribed says when it is gone."""
    session = Session(ClientId(1))
    (first,) = session.subscribe(o.Subscribe("odom", id="a"), None)
    assert isinstance(first, Subscribed) and first.new and first.type is None
    assert (first.sub.topic, first.sub.resolved) == ("odom", "/odom")
    (again,) = session.subscribe(
        o.Subscribe("odom", id="b", type="nav_msgs/Odometry", throttle_rate=50),
        "nav_msgs/msg/Odometry",
    )
    assert isinstance(again, Subscribed) and not again.new and again.sub is first.sub
    assert again.type == "nav_msgs/msg/Odometry" and again.sub.throttle_rate == 0
    assert session.unsubscribe(o.Unsubscribe("odom", id="a")) == (Unsubscribed(first.sub, False),)
    assert session.unsubscribe(o.Unsubscribe("odom", id="b")) == (Unsubscribed(first.sub, True),)
    assert session.unsubscribe(o.Unsubscribe("odom")) == ()  # nothing left: no effect
    assert session.subscriptions == {} and session.subscribe_ids == 0


def test_a_subscribe_with_a_fragment_size_sets_the_clients_fragment_size() -> None:
    session = Session(ClientId(1))
    session.subscribe(o.Subscribe("/scan", fragment_size=1000))
    assert session.fragment_size == 1000
    session.call_service(o.CallService("/s", fragment_size=500), 0.0, waits=False, default=1.0)
    assert session.fragment_size == 500


def test_the_first_publish_advertises_the_topic_and_later_ones_have_no_effect() -> None:
    """The implicit publisher of rosbridge: one Advertised, then nothing on the hot path."""
    session = Session(ClientId(1))
    twist = "geometry_msgs/msg/Twist"
    assert session.publish("/cmd_vel", twist) == (Advertised("/cmd_vel", twist, None),)
    assert session.publish("/cmd_vel", twist) == ()
    assert session.advertisements == {"/cmd_vel": {None: twist}}
    # an advertise op records the canonical type the graph decided, and its latch
    op = o.Advertise("/map", "nav_msgs/OccupancyGrid", id="m", latch=True)
    grid = "nav_msgs/msg/OccupancyGrid"
    assert session.advertise(op, grid) == (Advertised("/map", grid, "m", True),)
    assert session.advertisements["/map"] == {"m": grid}


def test_services_and_actions_provided_are_recorded_and_withdrawn() -> None:
    session = Session(ClientId(1))
    (provided,) = session.provide("service", "/add", "example_interfaces/srv/AddTwoInts", "add")
    add = "example_interfaces/srv/AddTwoInts"
    assert provided == Provided("service", "/add", add, "add", add)
    fib = "example_interfaces/action/Fibonacci"
    (action,) = session.provide("action", "/fib", fib, "fib", "example_interfaces/Fibonacci")
    assert (action.written, action.written_type) == ("fib", "example_interfaces/Fibonacci")
    assert session.provides("service", "/add") and session.provides("action", "/fib")
    assert session.withdraw("service", "/add") == (Withdrawn("service", "/add"),)
    with pytest.raises(ProtocolError, match="unadvertise_service: service /add is not advertised"):
        session.withdraw("service", "/add")
    session.disown("action", "/fib")  # the graph gave it to another provider
    assert not session.provides("action", "/fib") and session.owned() == 0


def test_closing_gives_everything_back_and_says_what_the_graph_withdraws() -> None:
    session, pool = budgeted()
    (subscribed,) = session.subscribe(o.Subscribe("/odom"))
    assert isinstance(subscribed, Subscribed)
    session.publish("/chatter", "std_msgs/msg/String")
    session.latch("/chatter", 10)
    session.provide("service", "/s", "std_srvs/srv/Trigger")
    session.provide("action", "/a", "example_interfaces/action/Fibonacci")
    session.call_service(o.CallService("/s"), 0.0, waits=True, default=1.0)
    effects = session.close()
    assert effects == [
        Unsubscribed(subscribed.sub, True),
        Unadvertised("/chatter", None),
        Unlatched("/chatter"),
        Withdrawn("service", "/s"),
        Withdrawn("action", "/a"),
    ]
    assert all(used == 0 for used in pool.used.values())
    assert session.close() == []  # once


def test_refusals_become_replies_within_the_status_budget() -> None:
    session = Session(ClientId(1), limits=Limits(statuses_per_second=1))
    (reply,) = session.refused("publish /x: refused", "cause", 0.0, op_id="p1")
    assert isinstance(reply, Reply)
    assert json.loads(reply.frame.data) == {
        "op": "status",
        "level": "error",
        "msg": "publish /x: refused",
        "id": "p1",
    }
    assert session.refused("again", "cause", 0.1) == ()
    assert session.refusals_untold == 1


def test_the_publish_rate_is_the_clients_token_bucket() -> None:
    session = Session(ClientId(1), limits=Limits(publish_rate=1.0, publish_burst=2))
    assert session.take_publish(0.0) and session.take_publish(0.0)
    assert not session.take_publish(0.0)
    assert session.take_publish(1.0)


def test_ids_longer_than_the_budget_are_refused_before_anything_keeps_them() -> None:
    """A long id is refused for every op (a call gets its failed answer, without the id)."""
    session, _pool = budgeted(id_length=10)
    ok, sub, call, big = session.parse(
        '{"op":"subscribe","topic":"/a","id":"0123456789"}'
        '{"op":"subscribe","topic":"/a","id":"0123456789x"}'
        '{"op":"call_service","service":"/s","id":"\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e96"}'
        '{"op":"advertise","topic":"/a","type":"std_msgs/String","id":12345678901234567890123}',
        0.0,
    )
    assert isinstance(ok, o.Subscribe) and ok.id == "0123456789"
    assert isinstance(sub, Refusal) and sub.cause == "max_id_length"
    assert "subscribe: refused, its id is 11 characters long: more than 10" in str(sub)
    assert isinstance(call, Refusal) and (call.op, call.target, call.op_id) == (
        "call_service",
        "/s",
        None,
    )
    assert "13 characters" in str(call)  # UTF-8 bytes: 6 x 2 + 1
    assert isinstance(big, Refusal) and "23 digits" in str(big)


def test_goals_in_flight_are_budgeted_per_client_and_globally() -> None:
    """start_goal past either budget refuses by name; end_goal and close give back."""
    session, pool = budgeted(pending_goals=2)
    session.start_goal("/a", "g1")
    session.start_goal("/a", "g2")
    with pytest.raises(Refusal, match="max_pending_goals") as refused:
        session.start_goal("/a", "g3")
    assert refused.value.op == "send_action_goal" and refused.value.op_id == "g3"
    session.end_goal()
    assert session.pending_goals == 1 == pool.used["pending_goals"]
    shared = Pool({"pending_goals": 2})
    Session(ClientId(9), pool=shared).start_goal("/a", 1)
    Session(ClientId(10), pool=shared).start_goal("/a", 1)
    with pytest.raises(Refusal, match="global_pending_goals"):
        Session(ClientId(11), pool=shared).start_goal("/a", 1)
    session.close()
    assert pool.used["pending_goals"] == 0
