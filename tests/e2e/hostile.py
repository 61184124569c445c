"""Hypothesis strategies for hostile rosbridge input (shared by the test and bench/hostile.py).

Every frame drawn here is something the server must refuse or survive: malformed JSON, wrong
types, missing fields, huge strings, deep nesting, NaN and infinities, garbage binary frames,
absurd throttle, queue and fragment values. A /cmd_vel payload drawn here is never a command
that could move the robot: its numbers are non-finite, absurd (above 1000) or of the wrong type.
"""

from __future__ import annotations

import json
from typing import Any

from hypothesis import strategies as st


OPS = [
    "advertise",
    "unadvertise",
    "publish",
    "subscribe",
    "unsubscribe",
    "call_service",
    "advertise_service",
    "unadvertise_service",
    "service_response",
    "advertise_action",
    "unadvertise_action",
    "send_action_goal",
    "cancel_action_goal",
    "action_feedback",
    "action_result",
    "fragment",
    "set_level",
    "auth",
    "status",
    "png",
    "",
]
FIELDS = [
    "op", "id", "topic", "type", "msg", "service", "args", "values", "result", "action",
    "action_type", "throttle_rate", "queue_length", "fragment_size", "compression", "latch",
    "queue_size", "level", "data", "num", "total", "timeout", "feedback", "mac", "t", "end",
]  # fmt: skip
NAMES = [
    "/cmd_vel", "cmd_vel", "/odom", "/scan", "/tf", "/rosout", "/rosapi/topics", "/reset",
    "/rosapi/set_param", "", "/", "//", "~", "/a b", "/ünïcödé", "/" + "x" * 300, "/ok/../x",
    "/a/_b", "0abc", "/r1/cmd_vel", "\x00", "/x" * 200,
]  # fmt: skip
TYPES = [
    "geometry_msgs/Twist", "geometry_msgs/msg/Twist", "std_msgs/String", "nav_msgs/Odometry",
    "std_srvs/Trigger", "std_srvs/srv/Empty", "", "a/b/c/d", "../../etc/passwd", "x" * 500,
    "std_msgs/msg/NotAType", "/", "pkg//T",
]  # fmt: skip

#: Numbers no robot should ever act on.
hostile_numbers = st.sampled_from(
    [
        float("nan"), float("inf"), float("-inf"), 1e308, -1e308, 1e3 + 1, -5e5, 2**63, -(2**64),
        10**400, 2**31, -(2**31) - 1,
    ]
)  # fmt: skip
huge_text = st.integers(1_000, 300_000).map(lambda n: "x" * n)
leaf = st.one_of(
    st.none(),
    st.booleans(),
    hostile_numbers,
    st.text(max_size=30),
    huge_text,
    st.sampled_from(NAMES),
)
values = st.recursive(
    leaf,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(FIELDS), inner, max_size=4)
    ),
    max_leaves=12,
)
absurd_ints = st.sampled_from([-1, 0, 2**31, 2**63, 10**30, -(10**9), 1.5, 1e300, 0.0])


def _dumps(obj: Any) -> str:
    """JSON with NaN/Infinity tokens as Python writes them (what roslibpy sends)."""
    return json.dumps(obj, allow_nan=True)


@st.composite
def _random_op(draw: st.DrawFn) -> str:
    obj: dict[str, Any] = {"op": draw(st.sampled_from(OPS) | st.text(max_size=10))}
    for name in draw(st.lists(st.sampled_from(FIELDS), max_size=6, unique=True)):
        if name == "op":
            continue
        if name in ("topic", "service", "action"):
            obj[name] = draw(st.sampled_from(NAMES) | values)
        elif name in ("type", "action_type"):
            obj[name] = draw(st.sampled_from(TYPES) | values)
        elif name in ("throttle_rate", "queue_length", "fragment_size", "queue_size", "num",
                      "total", "timeout", "t", "end"):  # fmt: skip
            obj[name] = draw(absurd_ints | values)
        else:
            obj[name] = draw(values)
    return _dumps(obj)


@st.composite
def _cmd_vel(draw: st.DrawFn) -> str:
    bad = draw(hostile_numbers | st.text(max_size=5) | st.none() | st.lists(st.integers()))
    axis = draw(st.sampled_from(["linear", "angular"]))
    field = "x" if axis == "linear" else "z"
    msg: dict[str, Any] = {axis: {field: bad}}
    if draw(st.booleans()):
        msg["wings"] = draw(values)
    op = {"op": "publish", "topic": "/cmd_vel", "msg": msg}
    if draw(st.booleans()):
        op["type"] = draw(st.sampled_from(TYPES))
    return _dumps(op)


@st.composite
def _absurd_subscribe(draw: st.DrawFn) -> str:
    return _dumps(
        {
            "op": "subscribe",
            "topic": draw(st.sampled_from(NAMES)),
            "throttle_rate": draw(absurd_ints),
            "queue_length": draw(absurd_ints),
            "fragment_size": draw(absurd_ints),
            "compression": draw(st.sampled_from(["none", "png", "cbor", "cbor-raw", "zip", 5])),
        }
    )


@st.composite
def _fragment(draw: st.DrawFn) -> str:
    return _dumps(
        {
            "op": "fragment",
            "id": draw(st.text(max_size=5) | st.integers()),
            "data": draw(st.text(max_size=50) | huge_text),
            "num": draw(absurd_ints),
            "total": draw(absurd_ints),
        }
    )


@st.composite
def _echo(draw: st.DrawFn) -> str:
    """Subscribe and publish hostile content on one topic in one frame: it must be encoded."""
    topic = draw(st.sampled_from(["/echo", "/chatter", "/rosout", "/tf"]))
    sub = {
        "op": "subscribe",
        "topic": topic,
        "compression": draw(st.sampled_from(["none", "cbor"])),
    }
    pub = {"op": "publish", "topic": topic, "msg": draw(values)}
    if draw(st.booleans()):
        pub["type"] = draw(st.sampled_from(TYPES))
    return _dumps(sub) + _dumps(pub)


deep = st.tuples(st.integers(10, 200_000), st.sampled_from(["[", '{"a":'])).map(
    lambda p: p[1] * p[0] + ("]" * p[0] if p[1] == "[" else "1" + "}" * p[0])
)
truncated = _random_op().map(lambda text: text[: max(1, len(text) // 2)])
many = st.integers(2, 400).map(lambda n: '{"op":"set_level","level":"error"}' * n)

#: One hostile WebSocket message: text (str) or binary (bytes).
frames = st.one_of(
    _random_op(),
    _cmd_vel(),
    _absurd_subscribe(),
    _fragment(),
    _echo(),
    values.map(_dumps),
    deep,
    truncated,
    many,
    st.binary(min_size=0, max_size=200),
    st.text(max_size=100),
)
