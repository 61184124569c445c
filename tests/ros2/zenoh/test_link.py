"""simbridge --zenoh against zenoh-ros2-sdk, an independent rmw_zenoh implementation.

Everything goes through a router started by ``simbridge zenohd`` on 127.0.0.1.
"""

from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import Callable
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.ros2.names import Entity
from simbridge.ros2.typehash import TypeHasher
from simbridge.ros2.zenoh.link import TX_THREADS, calm_transmit_threads
from tests.helpers import TIMEOUT_FACTOR, recv_until, send_json, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router, eventually


pytestmark = pytest.mark.e2e

KW: dict[str, Any] = {"router_ip": "127.0.0.1"}


def sdk_kw(router: Router) -> dict[str, Any]:
    return {**KW, "router_port": router.port}


async def test_ros2_discovers_simbridge_nodes_topics_and_services(
    zapp: App, router: Router
) -> None:
    from zenoh_ros2_sdk import get_service_names_and_types, get_topic_names_and_types

    def topics() -> dict[str, list[str]]:
        return dict(get_topic_names_and_types(**sdk_kw(router)))

    expected = {"/odom", "/scan", "/tf", "/tf_static", "/cmd_vel"}
    found = await eventually(lambda: (t := topics()) and expected <= t.keys() and t)
    assert found["/odom"] == ["nav_msgs/msg/Odometry"]
    assert found["/scan"] == ["sensor_msgs/msg/LaserScan"]
    assert found["/tf"] == ["tf2_msgs/msg/TFMessage"]
    assert found["/tf_static"] == ["tf2_msgs/msg/TFMessage"]
    assert found["/cmd_vel"] == ["geometry_msgs/msg/Twist"]

    def services() -> dict[str, list[str]]:
        return dict(get_service_names_and_types(**sdk_kw(router)))

    found = await eventually(
        lambda: (s := services()) and "/reset" in s and "/virtual_robot/get_parameters" in s and s
    )
    assert found["/reset"] == ["std_srvs/srv/Empty"]
    assert found["/virtual_robot/get_parameters"] == ["rcl_interfaces/srv/GetParameters"]
    # the tokens are rmw_zenoh's: node tokens for each in-process node, latched /tf_static
    tokens = [e.token() for e in (d.entity for d in zapp.zenoh._declared.values())]  # type: ignore[union-attr]
    node = next(t for t in tokens if t.endswith("/NN/%/%/virtual_robot"))
    assert node.startswith(f"@ros2_lv/0/{zapp.zenoh.zid}/")  # type: ignore[union-attr]
    static = next(t for t in tokens if "/%tf_static/" in t)
    assert static.endswith(
        "/tf2_msgs::msg::dds_::TFMessage_/" + static.split("/")[11] + "/:1:,1:,:,:,,"
    )


#: The simulated robot's published topics a ROS 2 subscriber of these tests takes.
ROBOT_TOPICS = [
    ("odom", "nav_msgs/msg/Odometry"),
    ("scan", "sensor_msgs/msg/LaserScan"),
    ("tf", "tf2_msgs/msg/TFMessage"),
]


async def _sdk_subscribers(router: Router, callback: Callable[[str], Any]) -> list[Any]:
    """ROS 2 subscribers (zenoh-ros2-sdk) of /odom, /scan and /tf, ``callback(name)`` each."""
    from zenoh_ros2_sdk import ROS2Subscriber

    return [
        await asyncio.to_thread(
            ROS2Subscriber, f"/{name}", type_name, callback=callback(name), **sdk_kw(router)
        )
        for name, type_name in ROBOT_TOPICS
    ]


async def test_ros2_subscribers_get_odom_scan_and_tf(zapp: App, router: Router) -> None:
    got: dict[str, list[Any]] = {"odom": [], "scan": [], "tf": []}
    subs = await _sdk_subscribers(router, lambda name: got[name].append)
    try:
        await wait_for(lambda: all(len(v) >= 5 for v in got.values()), timeout=10)
    finally:
        for sub in subs:
            sub.close()
    odom = got["odom"][-1]
    assert odom.header.frame_id == "odom" and odom.child_frame_id == "base_link"
    scan = got["scan"][-1]
    assert len(scan.ranges) == zapp.world.params.lidar.rays
    assert got["tf"][-1].transforms[0].child_frame_id == "base_link"


async def test_samples_carry_rosbags_exact_cdr_and_rmw_zenoh_attachments(
    zapp: App, router: Router
) -> None:
    import zenoh

    from simbridge.ros2.zenoh.attachment import Attachment

    link = zapp.zenoh
    assert link is not None
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([router.endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    raw = await asyncio.to_thread(zenoh.open, conf)
    got: dict[str, list[tuple[bytes, bytes]]] = {"odom": [], "scan": [], "tf": []}

    def keep(name: str) -> Any:
        def on_sample(sample: Any) -> None:  # a Zenoh thread
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
            got[name].append((sample.payload.to_bytes(), attachment))

        return on_sample

    taps = [raw.declare_subscriber(f"0/{name}/**", keep(name)) for name in got]
    start = time.time_ns()
    # the SDK's subscriptions are what makes simbridge publish (rmw_zenoh tokens)
    subs = await _sdk_subscribers(router, lambda _name: lambda _msg: None)
    try:
        await wait_for(lambda: all(len(v) >= 5 for v in got.values()), timeout=10)
    finally:
        for sub in subs:
            sub.close()
        for tap in taps:
            tap.undeclare()
        await asyncio.to_thread(raw.close)
    store = zapp.graph.registry.store
    for name, type_name in [
        ("odom", "nav_msgs/msg/Odometry"),
        ("scan", "sensor_msgs/msg/LaserScan"),
        ("tf", "tf2_msgs/msg/TFMessage"),
    ]:
        samples = got[name][:5]
        attachments = [Attachment.unpack(a) for _, a in samples]
        assert all(len(a) == 33 for _, a in samples)
        assert {a.gid for a in attachments} == {link._publishers[f"/{name}"].gid}
        sequences = [a.sequence for a in attachments]
        assert sequences == list(range(sequences[0], sequences[0] + 5))
        assert all(start - 10**9 <= a.timestamp_ns <= time.time_ns() for a in attachments)
        for payload, _ in samples:  # rosbags reads them and writes the same bytes back
            obj = store.deserialize_cdr(payload, type_name)
            assert bytes(store.serialize_cdr(obj, type_name, little_endian=True)) == payload
    odom = store.deserialize_cdr(got["odom"][-1][0], "nav_msgs/msg/Odometry")
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    assert len(odom.pose.covariance) == 36


async def test_ros2_publisher_drives_the_robot_through_cmd_vel(zapp: App, router: Router) -> None:
    from zenoh_ros2_sdk import ROS2Publisher

    robot = next(iter(zapp.world.robots.values()))
    x0 = robot.state.x
    pub = await asyncio.to_thread(
        ROS2Publisher, "/cmd_vel", "geometry_msgs/msg/Twist", **sdk_kw(router)
    )
    from zenoh_ros2_sdk import get_message_class

    twist = get_message_class("geometry_msgs/msg/Twist")
    vector = get_message_class("geometry_msgs/msg/Vector3")
    try:
        deadline = time.monotonic() + 10
        while robot.state.x < x0 + 0.1 and time.monotonic() < deadline:
            await asyncio.to_thread(
                pub.publish,
                linear=vector(x=0.3, y=0.0, z=0.0),
                angular=vector(x=0.0, y=0.0, z=0.0),
            )
            await asyncio.sleep(0.1)
    finally:
        pub.close()
    assert robot.state.x >= x0 + 0.1
    assert twist is not None


async def test_ros2_calls_reset_and_a_service_with_fields(zapp: App, router: Router) -> None:
    from zenoh_ros2_sdk import ROS2ServiceClient

    # SetBool's hash is computed by the SDK from the .srv text: an independent check of ours
    pause = await asyncio.to_thread(
        ROS2ServiceClient, "/sim/pause", "std_srvs/srv/SetBool", **sdk_kw(router)
    )
    reply = await asyncio.to_thread(pause.call, data=True)
    assert reply.success and zapp.simclock.paused
    # the SDK cannot hash an empty request itself; it takes the hash Jazzy's rosidl gives
    empty_hash = TypeHasher(zapp.graph.registry, "jazzy").service("std_srvs/srv/Empty")
    reset = await asyncio.to_thread(
        ROS2ServiceClient,
        "/reset",
        "std_srvs/srv/Empty",
        request_definition="",
        response_definition="",
        type_hash=empty_hash,
        **sdk_kw(router),
    )
    from zenoh_ros2_sdk import ROS2Subscriber

    # a ROS 2 node's /rosout subscription gets the reset's line (an ordinary delivery)
    lines: list[str] = []
    rosout = await asyncio.to_thread(
        ROS2Subscriber,
        "/rosout",
        "rcl_interfaces/msg/Log",
        callback=lambda m: lines.append(m.msg),
        msg_definition=zapp.graph.registry.definition_text("rcl_interfaces/msg/Log"),
        type_hash=TypeHasher(zapp.graph.registry, "jazzy").message("rcl_interfaces/msg/Log"),
        **sdk_kw(router),
    )
    await wait_for(lambda: zapp.graph.topics.topics["/rosout"].internal, timeout=10)
    robot = next(iter(zapp.world.robots.values()))
    start = robot.state.x
    robot.state.x += 0.5
    await asyncio.to_thread(reset.call)
    assert robot.state.x == pytest.approx(start)
    await wait_for(lambda: any(s.startswith("world reset") for s in lines), timeout=10)
    rosout.close()
    pause.close()
    reset.close()


async def test_ros2_reads_a_parameter_of_the_virtual_robot(zapp: App, router: Router) -> None:
    from zenoh_ros2_sdk import ROS2ServiceClient

    # what `ros2 param get /virtual_robot robot.max_linear_velocity` calls
    client = await asyncio.to_thread(
        ROS2ServiceClient,
        "/virtual_robot/get_parameters",
        "rcl_interfaces/srv/GetParameters",
        **sdk_kw(router),
    )
    try:
        reply = await asyncio.to_thread(client.call, names=["robot.max_linear_velocity"])
    finally:
        client.close()
    value = reply.values[0]
    assert value.type == 3  # PARAMETER_DOUBLE
    assert value.double_value == zapp.world.params.robot.max_linear_velocity


async def test_ros2_sets_a_parameter_with_array_fields_in_the_request(
    zapp: App, router: Router
) -> None:
    import numpy as np
    from zenoh_ros2_sdk import ROS2ServiceClient, get_message_class

    client = await asyncio.to_thread(
        ROS2ServiceClient,
        "/virtual_robot/set_parameters",
        "rcl_interfaces/srv/SetParameters",
        **sdk_kw(router),
    )
    value_class = get_message_class("rcl_interfaces/msg/ParameterValue")
    parameter_class = get_message_class("rcl_interfaces/msg/Parameter")
    assert value_class is not None and parameter_class is not None
    value = value_class(
        type=3,
        bool_value=False,
        integer_value=0,
        double_value=0.3,
        string_value="",
        byte_array_value=np.zeros(0, dtype=np.uint8),
        bool_array_value=np.zeros(0, dtype=np.bool_),
        integer_array_value=np.zeros(0, dtype=np.int64),
        double_array_value=np.zeros(0, dtype=np.float64),
        string_array_value=[],
    )
    try:
        reply = await asyncio.to_thread(
            client.call,
            parameters=[parameter_class(name="robot.max_linear_velocity", value=value)],
        )
    finally:
        client.close()
    assert reply.results[0].successful, reply
    assert zapp.world.params.robot.max_linear_velocity == 0.3


async def test_ros2_topic_and_service_reach_rosbridge_clients(zapp: App, router: Router) -> None:
    from zenoh_ros2_sdk import ROS2Publisher, ROS2ServiceServer

    pub = await asyncio.to_thread(
        ROS2Publisher, "/chatter", "std_msgs/msg/String", node_name="talker", **sdk_kw(router)
    )
    made: dict[str, Any] = {}

    def serve(request: Any) -> Any:
        return made["server"].response_msg_class(success=request.data, message="hello from ROS 2")

    server = made["server"] = await asyncio.to_thread(
        ROS2ServiceServer, "/ros2_hello", "std_srvs/srv/SetBool", serve, **sdk_kw(router)
    )
    try:
        await wait_for(lambda: "/chatter" in zapp.graph.topics.topics, timeout=8)
        async with connect(ws_url(zapp)) as conn:
            await send_json(conn, {"op": "call_service", "service": "/rosapi/topics", "id": "t"})
            listed = await recv_until(conn, lambda m: m.get("id") == "t")
            values = listed["values"]
            assert values["types"][values["topics"].index("/chatter")] == "std_msgs/msg/String"
            await send_json(conn, {"op": "call_service", "service": "/rosapi/nodes", "id": "n"})
            nodes = (await recv_until(conn, lambda m: m.get("id") == "n"))["values"]["nodes"]
            assert "/talker" in nodes and "/virtual_robot" in nodes
            await send_json(conn, {"op": "subscribe", "topic": "/chatter"})
            await asyncio.sleep(0.3)  # the link subscribes within a reconcile pass

            async def talk() -> None:
                for _ in range(40):
                    await asyncio.to_thread(pub.publish, data="hi")
                    await asyncio.sleep(0.05)

            talking = asyncio.create_task(talk())
            msg = await recv_until(conn, lambda m: m.get("topic") == "/chatter", timeout=5)
            assert msg["msg"] == {"data": "hi"}
            talking.cancel()
            await wait_for(lambda: "/ros2_hello" in zapp.graph.services.services, timeout=8)
            call = {"op": "call_service", "service": "/ros2_hello", "id": "c", "args": [True]}
            await send_json(conn, call)
            answer = await recv_until(conn, lambda m: m.get("id") == "c", timeout=8)
            assert answer["result"] is True
            assert answer["values"] == {"success": True, "message": "hello from ROS 2"}
    finally:
        pub.close()
        server.close()
    # gone with its tokens
    await wait_for(lambda: "/ros2_hello" not in zapp.graph.services.services, timeout=8)


async def test_rosbridge_topic_and_service_reach_ros2(zapp: App, router: Router) -> None:
    from zenoh_ros2_sdk import ROS2ServiceClient, ROS2Subscriber

    async with connect(ws_url(zapp)) as conn:
        await send_json(
            conn,
            {"op": "advertise_service", "service": "/web_hello", "type": "std_srvs/srv/SetBool"},
        )
        await send_json(
            conn, {"op": "advertise", "topic": "/web_chatter", "type": "std_msgs/msg/String"}
        )
        got: list[Any] = []
        await wait_for(lambda: ("MP", "/rosbridge_websocket", "/web_chatter") in _keys(zapp), 5)
        sub = await asyncio.to_thread(
            ROS2Subscriber, "/web_chatter", "std_msgs/msg/String", got.append, **sdk_kw(router)
        )
        await wait_for(lambda: zapp.zenoh._remote_subs["/web_chatter"] > 0, 8)  # type: ignore[union-attr]
        # the subscription's token can arrive before its data route: publish until heard
        deadline = time.monotonic() + 5
        while len(got) < 5 and time.monotonic() < deadline:
            await send_json(conn, {"op": "publish", "topic": "/web_chatter", "msg": {"data": "yo"}})
            await asyncio.sleep(0.05)
        assert len(got) >= 5
        assert got[0].data == "yo"
        sub.close()
        await wait_for(lambda: ("SS", "/rosbridge_websocket", "/web_hello") in _keys(zapp), 5)
        client = await asyncio.to_thread(
            ROS2ServiceClient, "/web_hello", "std_srvs/srv/SetBool", **sdk_kw(router)
        )
        call = asyncio.create_task(asyncio.to_thread(client.call, data=True))
        request = await recv_until(conn, lambda m: m.get("op") == "call_service", timeout=5)
        assert request["args"] == {"data": True}
        await send_json(
            conn,
            {
                "op": "service_response",
                "service": "/web_hello",
                "id": request["id"],
                "values": {"success": True, "message": "hello from the web"},
                "result": True,
            },
        )
        reply = await asyncio.wait_for(call, 10)
        assert reply.success and reply.message == "hello from the web"
        # calls from ROS 2 waiting for a provider outside the process are budgeted: past the
        # limit a call is refused at once (an error reply), and an answer frees its place
        link = zapp.zenoh
        assert link is not None and link.calls_waiting == 0
        link.max_calls_waiting = 1
        first = asyncio.create_task(asyncio.to_thread(client.call, data=False))
        request = await recv_until(conn, lambda m: m.get("op") == "call_service", timeout=5)
        assert link.calls_waiting == 1
        failed = link.stats["calls_failed"]
        assert await asyncio.to_thread(client.call, data=True) is None
        assert link.stats["calls_failed"] == failed + 1 and link.calls_waiting == 1
        answer = {"op": "service_response", "service": "/web_hello", "id": request["id"]}
        await send_json(conn, {**answer, "values": {"success": False}, "result": True})
        reply = await asyncio.wait_for(first, 10)
        assert not reply.success and reply.message == "" and link.calls_waiting == 0
        client.close()


async def test_late_ros2_subscriber_gets_the_latched_walls(zapp: App, router: Router) -> None:
    from zenoh_ros2_sdk import ROS2Subscriber
    from zenoh_ros2_sdk.qos import QosDurability, QosProfile

    # the first walls went out before any ROS 2 subscriber existed
    await asyncio.sleep(0.5)
    got: list[Any] = []
    qos = QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1)
    sub = await asyncio.to_thread(
        ROS2Subscriber,
        "/walls",
        "visualization_msgs/msg/Marker",
        got.append,
        qos=qos,
        **sdk_kw(router),
    )
    try:
        await wait_for(lambda: len(got) >= 1, 8)
    finally:
        sub.close()
    assert len(got[0].points) == 2 * len(zapp.world.spec.segments())


def _keys(app: App) -> set[tuple[str, str, str]]:
    assert app.zenoh is not None
    return set(app.zenoh._declared)


async def test_health_reports_the_zenoh_session(zapp: App) -> None:
    assert zapp.zenoh is not None
    await wait_for(lambda: zapp.health()["zenoh"]["state"] == "connected", 8)
    health = zapp.health()["zenoh"]
    assert health["routers"] == 1 and health["domain"] == 0 and health["ros_distro"] == "jazzy"
    assert json.dumps(health)  # JSON-able for /healthz


async def test_zenohs_transmit_threads_are_batch_scheduled_once_linked(zapp: App) -> None:
    # so that a tick's puts are not preempted by the thread that sends them (see
    # calm_transmit_threads); the threads exist once the session has a link
    await wait_for(lambda: zapp.health()["zenoh"]["state"] == "connected", 8)
    tx = []
    for tid in os.listdir("/proc/self/task"):
        with open(f"/proc/self/task/{tid}/comm") as f:
            if f.read().startswith(TX_THREADS):
                tx.append(int(tid))
    assert tx
    assert all(os.sched_getscheduler(tid) == os.SCHED_BATCH for tid in tx)
    assert calm_transmit_threads() == len(tx)


def test_token_of_sdk_parses(router: Router) -> None:
    token = (
        "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/"
        "%add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/RIHS01_e118de6bf5eeb66a2491b5"
        "bda11202e7b68f198d6f67922cf30364858239c81a/::,10:,:,:,,"
    )
    assert Entity.parse(token).token() == token


async def test_a_flood_of_samples_is_handed_over_in_batches_and_bounded(
    zapp: App, router: Router
) -> None:
    from simbridge.ros2.link import DRAIN_BATCH, DRAIN_BYTES, INBOX_LIMIT

    link = zapp.zenoh
    assert link is not None
    inbox = link.inbox
    on_sample = link._sample_handler("/nobody_listens")

    class Payload:
        def __init__(self, size: int) -> None:
            self.data = b"\x00\x01\x00\x00".ljust(size, b"\x00")

        def __len__(self) -> int:
            return len(self.data)

        def to_bytes(self) -> bytes:
            return self.data

    class Sample:
        def __init__(self, size: int) -> None:
            self.payload = Payload(size)

    small = Sample(4)
    for _ in range(INBOX_LIMIT + 10):
        on_sample(small)
    assert len(inbox.samples) == INBOX_LIMIT and link.stats["samples_dropped"] == 10
    inbox.drain()  # one batch, then the loop's other work, then the next batch
    assert len(inbox.samples) == INBOX_LIMIT - DRAIN_BATCH
    await wait_for(lambda: not inbox.samples, timeout=10)
    # by size: one over zenoh_max_sample_bytes is dropped uncopied and reported (rate-limited)
    on_sample(Sample(link.max_sample + 1))
    assert not inbox.samples and link.stats["samples_oversized"] == 1
    await wait_for(lambda: "oversized" in link.logbook.logged, timeout=5)
    # by bytes held: the oldest go past zenoh_inbox_bytes; a batch hands over DRAIN_BYTES
    big = Sample(link.max_sample)
    dropped = link.stats["samples_dropped"]
    for _ in range(link.max_inbox // link.max_sample + 3):
        on_sample(big)
    assert inbox.bytes <= link.max_inbox
    assert link.stats["samples_dropped"] == dropped + 3
    held = len(inbox.samples)
    inbox.drain()
    assert held - len(inbox.samples) == max(1, DRAIN_BYTES // link.max_sample)
    await wait_for(lambda: not inbox.samples and inbox.bytes == 0, timeout=10)


async def _receive_from(zapp: App, conn: Any, pub: Any, name: str) -> dict[str, Any]:
    """Subscribe ``conn`` to ``name`` and wait until a sample ``pub`` publishes reaches it.

    The link declares its subscriber before the publisher's session may have heard of it (a put
    before that goes nowhere), so a probe is published every half second until one arrives;
    then a last sample, received after every probe still under way (one publisher's samples
    arrive in order), leaves nothing of the probes for what the test receives next.
    Returns the probe (``{"data": "probe"}``): the route is up end to end.
    """
    link = zapp.zenoh
    assert link is not None
    await wait_for(lambda: name in zapp.graph.topics.topics, timeout=8)
    await send_json(conn, {"op": "subscribe", "topic": name})
    await wait_for(lambda: name in link._subscribers, timeout=8)
    loop = asyncio.get_running_loop()
    deadline = loop.time() + 8 * TIMEOUT_FACTOR
    while True:
        await asyncio.to_thread(pub.publish, data="probe")
        try:
            msg = await recv_until(conn, lambda m: m.get("topic") == name, timeout=0.5)
            break
        except TimeoutError:
            if loop.time() > deadline:
                raise
    await asyncio.to_thread(pub.publish, data="probes done")
    await recv_until(conn, lambda m: m.get("msg") == {"data": "probes done"}, timeout=8)
    return dict(msg["msg"])


async def test_a_burst_on_a_polled_topic_reaches_the_client_whole_and_in_order(
    zapp: App, router: Router, monkeypatch: pytest.MonkeyPatch
) -> None:
    from zenoh_ros2_sdk import ROS2Publisher

    from simbridge.ros2.zenoh.link import RING

    monkeypatch.setattr("simbridge.ros2.zenoh.link.CALLBACK_KEYS", 0)  # every key polled
    monkeypatch.setattr("simbridge.ros2.zenoh.link.POLL_BATCH", 32)  # a burst in several callbacks

    link = zapp.zenoh
    assert link is not None
    pub = await asyncio.to_thread(
        ROS2Publisher, "/burst", "std_msgs/msg/String", node_name="burster", **sdk_kw(router)
    )
    try:
        async with connect(ws_url(zapp)) as conn:
            await _receive_from(zapp, conn, pub, "/burst")
            count = RING - 10
            assert count > 2 * 32  # several batches, each written out before the next

            def burst() -> None:
                for k in range(count):
                    pub.publish(data=str(k))

            await asyncio.to_thread(burst)  # faster than the loop polls: they wait in the ring
            got = [
                (await recv_until(conn, lambda m: m.get("topic") == "/burst", timeout=5))["msg"]
                for _ in range(count)
            ]
            assert got == [{"data": str(k)} for k in range(count)]
            await send_json(conn, {"op": "unsubscribe", "topic": "/burst"})
            await wait_for(lambda: "/burst" not in link._subscribers, timeout=8)
            assert all(name != "/burst" for name, _ in link._channel_list)
    finally:
        pub.close()


def test_the_poll_period_grows_with_the_channels(zapp: App) -> None:
    from simbridge.ros2.zenoh.link import POLL_MAX, POLL_MIN

    link = zapp.zenoh
    assert link is not None
    channels = link._channel_list
    periods = []
    for n in (1, 100, 600, 5000):
        link._channel_list = [(f"/t{k}", None) for k in range(n)]
        periods.append(link.poll_period(100.0))
    link._channel_list = channels
    assert periods[0] == POLL_MIN and periods[-1] == POLL_MAX
    assert periods == sorted(periods) and POLL_MIN < periods[1] < POLL_MAX


def test_the_tick_compares_the_graph_with_zenoh_only_when_something_changed(zapp: App) -> None:
    """While nothing changes the tick compares nothing; a change is declared at its tick.

    A full pass over every topic took 15-30 ms with 300 robots; one is made every FULL_PERIOD s
    as a safety net.
    """
    from simbridge.ros2.zenoh.link import FULL_PERIOD, RECONCILE_PERIOD

    link = zapp.zenoh
    assert link is not None
    start = max(link._next_full, link._next_reconcile) + 1.0
    link.tick(start)  # the safety pass is due: everything is compared once
    passes = link.stats["reconciles"]
    for k in range(1, 40):
        link.tick(start + k * RECONCILE_PERIOD)  # 20 s of ticks, nothing changed
    assert link.stats["reconciles"] == passes

    def listener(msg: Any, source: Any) -> None:
        """An in-process subscriber: a change the link mirrors."""

    zapp.graph.subscribe("/probe", "std_msgs/msg/String", "/probe_node", listener)
    link.tick(start + 40 * RECONCILE_PERIOD)
    assert link.stats["reconciles"] == passes + 1
    assert ("MS", "/probe_node", "/probe") in link._declared
    zapp.graph.topics.unsubscribe_internal("/probe", listener)
    link.tick(start + 41 * RECONCILE_PERIOD)
    assert ("MS", "/probe_node", "/probe") not in link._declared
    link.tick(start + 41 * RECONCILE_PERIOD + FULL_PERIOD)
    assert link.stats["reconciles"] == passes + 3


async def test_after_a_silence_the_tick_polls_and_the_next_sample_still_arrives(
    zapp: App, router: Router, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An idle link keeps no timer of its own (each wake-up costs CPU); its tick polls."""
    from zenoh_ros2_sdk import ROS2Publisher

    from simbridge.ros2.zenoh.link import IDLE_AFTER

    monkeypatch.setattr("simbridge.ros2.zenoh.link.CALLBACK_KEYS", 0)  # every key polled

    link = zapp.zenoh
    assert link is not None
    pub = await asyncio.to_thread(
        ROS2Publisher, "/quiet", "std_msgs/msg/String", node_name="quiet", **sdk_kw(router)
    )
    try:
        async with connect(ws_url(zapp)) as conn:
            await _receive_from(zapp, conn, pub, "/quiet")
            assert link._poll_handle is not None  # samples arrive: polled on a timer
            # a silence: the timer stops (the tick polls, see ZenohLink.tick)
            await wait_for(lambda: link._poll_handle is None, timeout=IDLE_AFTER + 5)
            await asyncio.to_thread(pub.publish, data="after the silence")
            msg = await recv_until(conn, lambda m: m.get("topic") == "/quiet", timeout=5)
            assert msg["msg"] == {"data": "after the silence"}
    finally:
        pub.close()


async def test_the_first_keys_come_by_callback_and_the_rest_are_polled(
    zapp: App, router: Router, monkeypatch: pytest.MonkeyPatch
) -> None:
    from zenoh_ros2_sdk import ROS2Publisher

    link = zapp.zenoh
    assert link is not None
    monkeypatch.setattr("simbridge.ros2.zenoh.link.CALLBACK_KEYS", len(link._callback_keys) + 1)
    pubs = [
        await asyncio.to_thread(
            ROS2Publisher, name, "std_msgs/msg/String", node_name=f"n{k}", **sdk_kw(router)
        )
        for k, name in enumerate(("/first", "/second"))
    ]
    try:
        async with connect(ws_url(zapp)) as conn:
            for name, pub in zip(("/first", "/second"), pubs, strict=True):
                assert await _receive_from(zapp, conn, pub, name) == {"data": "probe"}
        assert {n for n, _key in link._callback_keys} >= {"/first"}
        assert "/second" not in {n for n, _key in link._callback_keys}
        assert "/second" in {n for n, _ in link._channel_list}
    finally:
        for pub in pubs:
            pub.close()
