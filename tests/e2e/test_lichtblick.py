"""Foxglove / Lichtblick "Rosbridge" data source, replayed: its call sequence, its decoding.

Lichtblick (RosbridgePlayer.ts) polls ``/rosapi/topics_and_raw_types``, takes ROS 2 when the
types include ``rcl_interfaces/msg/Log``, parses each ``typedefs_full_text`` and subscribes to
every topic without a type and with ``compression: cbor-raw``, then decodes ``msg.bytes`` as
ROS 2 CDR with the parsed definitions. This test does the same, decoding with a rosbags type
store that holds nothing but what the server sent, so the text alone must be complete.
"""

from __future__ import annotations

import asyncio
import itertools
import json
from typing import Any

import cbor2
import pytest
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.msg import get_types_from_msg
from websockets.asyncio.client import ClientConnection, connect

from simbridge.app.runner import App
from tests.helpers import TIMEOUT_FACTOR, ws_url


pytestmark = pytest.mark.e2e
_SEPARATOR = "\n" + "=" * 80 + "\n"
_ids = itertools.count(1)


def full_name(short: str) -> str:
    pkg, name = short.split("/")[0], short.split("/")[-1]
    return f"{pkg}/msg/{name}"


def store_from_text(type_name: str, text: str) -> Any:
    """A rosbags type store holding only the definitions in one typedefs_full_text."""
    store = get_typestore(Stores.EMPTY)
    sections = text.split(_SEPARATOR)
    types: dict[str, Any] = {}
    types.update(get_types_from_msg(sections[0], type_name))
    for section in sections[1:]:
        header, _, body = section.partition("\n")
        assert header.startswith("MSG: "), header
        types.update(get_types_from_msg(body, full_name(header[5:])))
    store.register(types)
    return store


async def call(
    ws: ClientConnection, service: str, args: Any, type_name: str, binary: list[bytes] | None = None
) -> Any:
    """call_service as roslibjs sends it (with a type key) and wait for the matching reply.

    Binary frames arriving meanwhile are kept in ``binary``.
    """
    op_id = f"call_service:{service}:{next(_ids)}"
    body = {"op": "call_service", "id": op_id, "service": service, "type": type_name, "args": args}
    await ws.send(json.dumps(body))
    while True:
        frame = await asyncio.wait_for(ws.recv(), 5 * TIMEOUT_FACTOR)
        if isinstance(frame, bytes):
            if binary is not None:
                binary.append(frame)
        else:
            reply = json.loads(frame)
            if reply.get("op") == "service_response" and reply.get("id") == op_id:
                assert reply["result"] is True, reply
                return reply["values"]


async def test_lichtblick_sees_every_topic_with_live_cdr_data(app: App) -> None:
    """Every listed topic decodes from cbor-raw with only the sent definitions; graph view works."""
    async with connect(ws_url(app), max_size=None) as ws, connect(ws_url(app)) as other:
        raw = await call(ws, "/rosapi/topics_and_raw_types", {}, "rosapi/TopicsAndRawTypes")
        assert "rcl_interfaces/msg/Log" in raw["types"]  # ROS 2 detection
        topics = dict(zip(raw["topics"], raw["types"], strict=True))
        texts = dict(zip(raw["topics"], raw["typedefs_full_text"], strict=True))
        assert not [t for t, text in texts.items() if text.startswith("# failed")]
        stores = {t: store_from_text(topics[t], texts[t]) for t in topics}
        for topic in topics:
            await ws.send(
                json.dumps({"op": "subscribe", "topic": topic, "compression": "cbor-raw"})
            )
        early: list[bytes] = []
        await call(ws, "/rosapi/get_time", {}, "rosapi/GetTime", early)  # subscribed by now
        # traffic on the topics only clients or events feed: /cmd_vel, /rosout
        await other.send(
            json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.1}}})
        )
        await call(other, "/reset", {}, "std_srvs/Empty")
        seen: dict[str, Any] = {}
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 5 * TIMEOUT_FACTOR
        # the simulator's streams, plus the client-fed /cmd_vel and the event-fed /rosout
        # (event topics such as /contact only carry data when something happens)
        required = {"/odom", "/scan", "/tf", "/tf_static", "/cmd_vel", "/rosout"}
        assert required <= set(topics)
        while not required <= set(seen):
            assert loop.time() < deadline, (
                f"no data on {set(topics) - set(seen)}"
            )  # pragma: no cover
            if early:
                frame = early.pop(0)
            else:
                try:
                    frame = await asyncio.wait_for(ws.recv(), deadline - loop.time())
                except TimeoutError:
                    raise AssertionError(f"no data on {required - set(seen)}") from None
            assert isinstance(frame, bytes), frame
            message = cbor2.loads(frame)
            assert message["op"] == "publish"
            name = message["topic"]
            body = message["msg"]
            assert (
                set(body) == {"secs", "nsecs", "bytes"} and body["bytes"][:4] == b"\x00\x01\x00\x00"
            )
            seen.setdefault(name, stores[name].deserialize_cdr(body["bytes"], topics[name]))
        assert seen["/odom"].child_frame_id == "base_link"
        assert len(seen["/scan"].ranges) == 360
        assert seen["/tf_static"].transforms[0].child_frame_id == "laser"
        assert seen["/cmd_vel"].linear.x == pytest.approx(0.1)
        assert isinstance(seen["/rosout"].msg, str)
        # the next poll and the graph view (nodes, node_details per node)
        again = await call(ws, "rosapi/topics_and_raw_types", {}, "rosapi/TopicsAndRawTypes")
        assert again["topics"] == raw["topics"]
        nodes = (await call(ws, "/rosapi/nodes", {}, "rosapi/Nodes"))["nodes"]
        for node in nodes:
            details = await call(ws, "/rosapi/node_details", {"node": node}, "rosapi/NodeDetails")
            assert set(details) == {"subscribing", "publishing", "services"}
        # a service call the way Lichtblick makes it: service_type first, then the call
        service_type = await call(
            ws, "/rosapi/service_type", {"service": "/reset"}, "rosapi/ServiceType"
        )
        assert service_type == {"type": "std_srvs/srv/Empty"}
        assert await call(ws, "/reset", {}, service_type["type"]) == {}
