from __future__ import annotations

import hashlib
import json
from typing import Any

import pytest

from simbridge.app.build import guard_graph
from simbridge.app.guard import (
    NO_ROBOT,
    Guard,
    rosauth_mac,
    token_access,
)
from simbridge.app.settings import ServerSettings
from simbridge.graph import Graph
from simbridge.graph.access import Access
from simbridge.graph.rosapi import install_rosapi
from simbridge.ros2.role import ros2_access
from simbridge.rosbridge import TokenBucket
from tests.helpers import RecordingPeer, graph_for, rosbridge_of


WALL = 1_700_000_000.0
TOKENS = {"token-for-r1-aaaa": "r1", "token-for-all-bbb": "*", "teacher-token-ccc": "admin"}


def make(**settings: Any) -> tuple[Graph, Guard]:
    s = ServerSettings(**settings)
    graph = graph_for(s, wall_clock_ns=lambda: int(WALL * 1e9))
    install_rosapi(graph)
    graph.add_service("/reset", "std_srvs/srv/Empty", "/virtual_robot", lambda args: {})
    guard = Guard(graph, s, robots=lambda: ["r1", "r2"])
    guard_graph(graph, guard)
    rosbridge_of(graph, guard)
    return graph, guard


def peer(graph: Graph, guard: Guard, token: str | None = None) -> RecordingPeer:
    p = RecordingPeer(graph, token=token)
    guard.peer_connected(p)
    return p


def op(p: RecordingPeer, graph: Graph, now: float = 0.0, **fields: Any) -> list[Any]:
    rosbridge_of(graph).receive(p, json.dumps(fields), now)
    return p.take()


def errors(messages: list[Any]) -> list[str]:
    return [m["msg"] for m in messages if m.get("op") == "status" and m["level"] == "error"]


def test_rosauth_mac_is_the_hex_sha512_of_the_fields_concatenated() -> None:
    """rosauth: secret + client + dest + rand + t + level + end, decimal seconds, hex digest."""
    text = "0123456789abcdef" + "10.0.0.2" + "10.0.0.1" + "r4nd" + "1700000000" + "admin" + "1700"
    expected = hashlib.sha512(text.encode()).hexdigest()
    mac = rosauth_mac("0123456789abcdef", "10.0.0.2", "10.0.0.1", "r4nd", 1700000000, "admin", 1700)
    assert mac == expected and len(mac) == 128


def test_token_access_maps_admin_and_client_tokens_and_rejects_others() -> None:
    s = ServerSettings(admin_token="the-admin-token", client_tokens=TOKENS)
    assert token_access(s, "the-admin-token") == ("*", True)
    assert token_access(s, "token-for-r1-aaaa") == ("r1", False)
    assert token_access(s, "teacher-token-ccc") == ("*", True)
    assert token_access(s, "wrong") is None
    assert token_access(s, None) is None


def test_ros2_peers_get_the_role_chosen_and_in_class_mode_by_default_no_robot() -> None:
    assert ros2_access(ServerSettings()) == ("*", True)  # a laptop on its own: open
    assert ros2_access(ServerSettings(admin_token="the-admin-token")) == ("*", False)
    assert ros2_access(ServerSettings(client_tokens=TOKENS)) == (NO_ROBOT, False)
    assert ros2_access(ServerSettings(auth_secret="s" * 16)) == (NO_ROBOT, False)
    classroom = {"client_tokens": TOKENS, "admin_token": "the-admin-token"}
    for role, access in [
        ("none", (NO_ROBOT, False)),
        ("robot:r2", ("r2", False)),
        ("robots", ("*", False)),
        ("admin", ("*", True)),
    ]:
        assert ros2_access(ServerSettings(ros2_role=role, **classroom)) == access


def test_a_peer_outside_the_protocol_is_asked_the_same_rules_by_name() -> None:
    graph, _guard = make(client_tokens=TOKENS, admin_token="the-admin-token")
    admission = graph.access
    nobody = Access(NO_ROBOT, False, guarded=True)
    student = Access("r1", False, guarded=True)
    for name in ("/cmd_vel", "/r1/cmd_vel", "/chatter", "/tf"):
        assert admission.publish_refusal(nobody, name) is not None
    assert admission.publish_refusal(student, "/r1/cmd_vel") is None
    assert admission.publish_refusal(student, "/r2/cmd_vel") is not None
    for name in ("/reset", "/virtual_robot/set_parameters", "/any/set_parameters_atomically"):
        assert "administrative" in str(admission.reach_refusal(student, name))
    assert "another robot" in str(admission.reach_refusal(nobody, "/r1/estop/reset"))
    assert admission.reach_refusal(student, "/r1/estop/reset") is None
    assert admission.reach_refusal(nobody, "/rosapi/topics") is None


def test_token_bucket_allows_the_burst_then_the_rate() -> None:
    bucket = TokenBucket(rate=10.0, burst=3)
    assert [bucket.take(0.0) for _ in range(4)] == [True, True, True, False]
    assert not bucket.take(0.05)
    assert bucket.take(0.1)


def test_without_authentication_configured_every_client_may_do_everything() -> None:
    graph, guard = make()
    p = peer(graph, guard)
    out = op(p, graph, op="call_service", service="/reset", id="r")
    assert out[-1]["result"] is True


def test_unauthenticated_client_can_do_nothing_but_auth() -> None:
    """With client tokens configured, a client without one gets a status error for any op.

    The same refusal is told once a second (the status budget), the rest counted.
    """
    graph, guard = make(client_tokens=TOKENS)
    p = peer(graph, guard)
    assert "not authenticated" in errors(op(p, graph, op="subscribe", topic="/odom"))[0]
    assert not errors(op(p, graph, op="subscribe", topic="/odom"))
    assert p.session.refusals_untold == 1
    refused = op(p, graph, now=1.0, op="advertise", topic="/x", type="a/B")
    assert "not authenticated" in errors(refused)[0]
    reply = op(p, graph, op="call_service", service="/rosapi/topics", id="c")
    assert reply[0]["op"] == "service_response" and reply[0]["result"] is False
    assert "not authenticated" in reply[0]["values"]
    assert not p.session.subscriptions and not p.session.advertisements


def test_student_token_publishes_only_under_its_robot_namespace() -> None:
    graph, guard = make(client_tokens=TOKENS)
    p = peer(graph, guard, "token-for-r1-aaaa")
    twist = {"linear": {"x": 0.1}}
    assert not errors(op(p, graph, op="advertise", topic="/r1/cmd_vel", type="geometry_msgs/Twist"))
    assert not errors(op(p, graph, op="publish", topic="/r1/cmd_vel", msg=twist))
    refused = errors(op(p, graph, op="publish", topic="/r2/cmd_vel", msg=twist))
    assert "only use names under /r1/" in refused[0]
    assert errors(op(p, graph, op="advertise", topic="/cmd_vel", type="geometry_msgs/Twist"))
    assert errors(op(p, graph, op="advertise_service", service="/r2/x", type="std_srvs/Trigger"))
    assert "/r2/cmd_vel" not in p.session.advertisements
    # reading is not restricted
    assert not errors(op(p, graph, op="subscribe", topic="/r2/odom"))


def test_student_may_not_call_another_robots_services_nor_admin_services() -> None:
    graph, guard = make(client_tokens=TOKENS, admin_token="the-admin-token")
    graph.add_service("/r2/teleport", "std_srvs/srv/Empty", "/sim", lambda args: {})
    graph.add_service("/r1/teleport", "std_srvs/srv/Empty", "/sim", lambda args: {})
    p = peer(graph, guard, "token-for-r1-aaaa")
    assert op(p, graph, op="call_service", service="/r1/teleport")[0]["result"] is True
    other = op(p, graph, op="call_service", service="/r2/teleport")[0]
    assert other["result"] is False and "another robot" in other["values"]
    reset = op(p, graph, op="call_service", service="/reset", id=7)[0]
    assert reset == {
        "op": "service_response",
        "service": "/reset",
        "values": reset["values"],
        "result": False,
        "id": 7,
    }
    assert "administrative" in reset["values"]
    assert op(p, graph, op="call_service", service="/rosapi/topics")[0]["result"] is True


def test_admin_token_unlocks_administrative_services() -> None:
    graph, guard = make(admin_token="the-admin-token")
    anyone = peer(graph, guard)
    refused = op(anyone, graph, op="call_service", service="/rosapi/set_param", args={})[0]
    assert refused["result"] is False and "administrative" in refused["values"]
    admin = peer(graph, guard, "the-admin-token")
    assert op(admin, graph, op="call_service", service="/reset")[0]["result"] is True


def test_a_client_cannot_hijack_a_service_the_server_provides() -> None:
    graph, guard = make()
    p = peer(graph, guard)
    out = errors(op(p, graph, op="advertise_service", service="/rosapi/topics", type="a/B"))
    assert "provides this service itself" in out[0]
    assert graph.services.services["/rosapi/topics"].handler is not None


def test_subscription_and_advertisement_limits_are_refused_clearly() -> None:
    graph, guard = make(max_subscriptions=3, max_advertisements=2)
    p = peer(graph, guard)
    for k in range(3):
        assert not errors(op(p, graph, op="subscribe", topic=f"/t{k}"))
    assert not errors(op(p, graph, op="subscribe", topic="/t0", id="again"))  # same topic: ok
    assert "max_subscriptions" in errors(op(p, graph, op="subscribe", topic="/t3"))[0]
    assert not errors(op(p, graph, op="advertise", topic="/a0", type="std_msgs/String"))
    assert not errors(op(p, graph, op="advertise_service", service="/s0", type="std_srvs/Trigger"))
    refused = errors(op(p, graph, op="advertise", topic="/a1", type="std_msgs/String"))
    assert "max_advertisements" in refused[0]
    # the same cause again within a second is counted, not told; a second later it is told
    assert not errors(op(p, graph, op="advertise", topic="/a1", type="std_msgs/String"))
    refused = errors(
        op(p, graph, now=1.0, op="publish", topic="/a2", type="std_msgs/String", msg={})
    )
    assert "max_advertisements" in refused[0]
    assert len(p.session.subscriptions) == 3 and "/a1" not in graph.topics.topics


def test_publish_flood_is_dropped_above_the_rate_and_told_once_a_second() -> None:
    graph, guard = make(publish_rate=10.0, publish_burst=5)
    seen: list[Any] = []
    graph.subscribe("/flood", "std_msgs/msg/String", "/n", lambda msg, src: seen.append(msg))
    p = peer(graph, guard)
    told = []
    for k in range(100):
        told += errors(op(p, graph, now=k * 0.001, op="publish", topic="/flood", msg={}))
    assert len(seen) == 5
    assert len(told) == 1 and "publish_rate" in told[0]
    op(p, graph, now=1.0, op="publish", topic="/flood", msg={})
    assert len(seen) == 6


def _auth(graph: Graph, p: RecordingPeer, secret: str, **over: Any) -> list[Any]:
    fields: dict[str, Any] = {
        "client": "192.168.1.5",
        "dest": "192.168.1.1",
        "rand": "xyz",
        "t": int(WALL),
        "level": "admin",
        "end": int(WALL) + 60,
    }
    fields.update(over)
    mac = rosauth_mac(
        secret, **{k: fields[k] for k in ("client", "dest", "rand", "t", "level", "end")}
    )
    fields.setdefault("mac", mac)
    return op(p, graph, **{"op": "auth", **fields, "mac": over.get("mac", mac)})


@pytest.mark.parametrize(
    ("over", "why"),
    [
        ({"mac": "0" * 128}, "wrong MAC"),
        ({"t": int(WALL) - 60}, "expired"),
        ({"end": int(WALL) - 1}, "expired"),
    ],
)
def test_auth_op_with_a_bad_or_stale_mac_is_refused(over: dict[str, Any], why: str) -> None:
    secret = "0123456789abcdef"
    graph, guard = make(auth_secret=secret)
    p = peer(graph, guard)
    out = _auth(graph, p, secret, **over)
    assert why in errors(out)[0]
    assert errors(op(p, graph, op="subscribe", topic="/odom"))


def test_auth_op_with_a_valid_rosauth_mac_authenticates_with_its_level_as_scope() -> None:
    secret = "0123456789abcdef"
    graph, guard = make(auth_secret=secret, admin_token="the-admin-token")
    admin = peer(graph, guard)
    assert not errors(_auth(graph, admin, secret))
    assert op(admin, graph, op="call_service", service="/reset")[0]["result"] is True
    student = peer(graph, guard)
    assert not errors(_auth(graph, student, secret, level="r2"))
    assert errors(op(student, graph, op="advertise", topic="/r1/cmd_vel", type="std_msgs/String"))
    assert not errors(op(student, graph, op="advertise", topic="/r2/x", type="std_msgs/String"))


def test_auth_op_is_refused_when_no_secret_is_configured() -> None:
    graph, guard = make(client_tokens=TOKENS)
    p = peer(graph, guard)
    out = errors(_auth(graph, p, "0123456789abcdef"))
    assert "takes no rosauth MAC" in out[0]


def test_tiny_fragment_sizes_are_refused() -> None:
    graph, guard = make()
    p = peer(graph, guard)
    assert "too small" in errors(op(p, graph, op="subscribe", topic="/scan", fragment_size=1))[0]
    assert not p.session.subscriptions
    assert not errors(op(p, graph, op="subscribe", topic="/scan", fragment_size=256))
