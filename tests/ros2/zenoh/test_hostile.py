"""Hostile ROS 2 peers (issue 29), played by zenoh-ros2-sdk and its raw Zenoh session.

A ROS 2 peer passes the admission of a rosbridge client of the role the instructor chose: in
class mode by default a student without a robot (it reads; it cannot release stops, reset, set
parameters or drive). Zenoh samples are bounded by size and bytes held, remote tokens by count,
applied in callbacks of their own; an observer's /odom keeps its 20 Hz meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import os
import struct
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.ros2.names import Entity
from simbridge.ros2.typehash import TypeHasher
from simbridge.ros2.zenoh.config import ZenohOptions
from tests.helpers import ROOT, TIMEOUT_FACTOR, send_json, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router, eventually, free_port, zenoh_options


pytestmark = pytest.mark.e2e

ADMIN = "teacher-token-xyz"
TOKENS = {"student-token-r1": "r1", "student-token-r2": "r2"}
CLASSROOM = ROOT / "config" / "worlds" / "classroom.yaml"


def sdk_kw(router: Router) -> dict[str, Any]:
    return {"router_ip": "127.0.0.1", "router_port": router.port}


@contextlib.asynccontextmanager
async def zenoh_app(router: Router, **settings: Any) -> AsyncIterator[App]:
    """A simbridge on the router; ``classroom=True``: the classroom world in class mode."""
    world = None
    if settings.pop("classroom", False):
        world = CLASSROOM
        settings = {"client_tokens": TOKENS, "admin_token": ADMIN, **settings}
    app = App(
        ServerSettings(host="127.0.0.1", port=0, http_port=0, **settings),
        world=world,
        zenoh=zenoh_options(router),
    )
    await app.start()
    try:
        yield app
    finally:
        await app.stop()


@contextlib.asynccontextmanager
async def observed(app: App, topic: str = "/odom") -> AsyncIterator[Callable[[], Awaitable[None]]]:
    """Watch ``topic`` while the block runs; the yielded coroutine asserts it kept its 20 Hz.

    Rate and worst gap are read on the server's header stamps, as tests/e2e/test_state_budgets.
    """
    token = f"/?token={ADMIN}" if app.settings.admin_token else ""
    async with connect(ws_url(app) + token, max_size=None) as ws:
        stamps: list[float] = []

        async def read() -> None:
            with contextlib.suppress(ConnectionClosed):
                async for data in ws:
                    msg = json.loads(data)
                    if msg.get("topic") == topic:
                        s = msg["msg"]["header"]["stamp"]
                        stamps.append(s["sec"] + s["nanosec"] * 1e-9)

        task = asyncio.create_task(read())
        await send_json(ws, {"op": "subscribe", "topic": topic})
        await wait_for(lambda: len(stamps) >= 2, timeout=5)
        start = time.time()

        async def check() -> None:
            await asyncio.sleep(max(0.0, start + 1.0 - time.time()))
            end = time.time()
            await asyncio.sleep(0.1)
            seen = [s for s in stamps if start <= s <= end]
            gaps = [b - a for a, b in itertools.pairwise(seen)]
            rate = (len(seen) - 1) / (seen[-1] - seen[0])
            worst = max(*gaps, seen[0] - start, end - seen[-1])
            assert rate >= 18.0, (rate, worst)
            assert worst <= 0.25 * TIMEOUT_FACTOR, (rate, worst)

        try:
            yield check
        finally:
            task.cancel()


async def _publish_until(pub: Any, moved: Callable[[], bool], seconds: float) -> bool:
    """Publish a forward Twist every 0.1 s until ``moved()`` or ``seconds`` pass."""
    from zenoh_ros2_sdk import get_message_class

    vector = get_message_class("geometry_msgs/msg/Vector3")
    deadline = time.monotonic() + seconds * TIMEOUT_FACTOR
    while not moved() and time.monotonic() < deadline:
        await asyncio.to_thread(
            pub.publish, linear=vector(x=0.3, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0)
        )
        await asyncio.sleep(0.1)
    return moved()


def _parameter(name: str, value: float) -> Any:
    import numpy as np
    from zenoh_ros2_sdk import get_message_class

    value_class = get_message_class("rcl_interfaces/msg/ParameterValue")
    parameter_class = get_message_class("rcl_interfaces/msg/Parameter")
    assert value_class is not None and parameter_class is not None
    return parameter_class(
        name=name,
        value=value_class(
            type=3,
            bool_value=False,
            integer_value=0,
            double_value=value,
            string_value="",
            byte_array_value=np.zeros(0, dtype=np.uint8),
            bool_array_value=np.zeros(0, dtype=np.bool_),
            integer_array_value=np.zeros(0, dtype=np.int64),
            double_array_value=np.zeros(0, dtype=np.float64),
            string_array_value=[],
        ),
    )


async def test_in_class_mode_a_ros2_peer_reads_but_cannot_release_reset_set_or_drive(
    router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import ROS2Publisher, ROS2ServiceClient, ROS2Subscriber

    async with zenoh_app(router, classroom=True) as app:
        link = app.zenoh
        assert link is not None
        latch = app.estop.latch_global()  # the instructor's global stop
        kw = sdk_kw(router)

        def client(name: str, type_name: str, **extra: Any) -> Any:
            return ROS2ServiceClient(name, type_name, timeout=5.0, **kw, **extra)

        hasher = TypeHasher(app.graph.registry, "jazzy")
        # the SDK cannot hash an empty request itself; it takes the hash Jazzy's rosidl gives
        trigger = {
            "request_definition": "",
            "response_definition": "bool success\nstring message",
            "type_hash": hasher.service("std_srvs/srv/Trigger"),
        }
        empty = {
            "request_definition": "",
            "response_definition": "",
            "type_hash": hasher.service("std_srvs/srv/Empty"),
        }
        reset_all = await asyncio.to_thread(
            client, "/estop/reset", "std_srvs/srv/Trigger", **trigger
        )
        reset_r1 = await asyncio.to_thread(
            client, "/r1/estop/reset", "std_srvs/srv/Trigger", **trigger
        )
        set_params = await asyncio.to_thread(
            client, "/virtual_robot/set_parameters", "rcl_interfaces/srv/SetParameters"
        )
        reset = await asyncio.to_thread(client, "/reset", "std_srvs/srv/Empty", **empty)
        limit = app.world.params.robot.max_linear_velocity
        try:
            # the e-stop's own rule: releases this connection's latches only (it has none)
            answer = await asyncio.to_thread(reset_all.call)
            assert answer is not None and "nothing of this connection's" in answer.message
            # admission: another robot's namespace, an administrative service, a parameter
            # service ending: refused (the SDK's call gets the error reply, returns None)
            assert await asyncio.to_thread(reset_r1.call) is None
            too_fast = [_parameter("robot.max_linear_velocity", 20.0)]
            assert await asyncio.to_thread(set_params.call, parameters=too_fast) is None
            r1 = app.world.robots["r1"]
            r1.state.x += 0.5
            moved_x = r1.state.x
            assert await asyncio.to_thread(reset.call) is None
        finally:
            for c in (reset_all, reset_r1, set_params, reset):
                c.close()
        assert app.world.estopped and latch.id in app.estop.latches
        assert app.world.params.robot.max_linear_velocity == limit
        assert r1.state.x == moved_x  # not reset
        assert link.stats["calls_failed"] >= 3
        app.estop.release_latch(latch.id)
        # it may drive no robot: its /r2/cmd_vel is never even subscribed to
        pub = await asyncio.to_thread(ROS2Publisher, "/r2/cmd_vel", "geometry_msgs/msg/Twist", **kw)
        heard: list[Any] = []
        sub = await asyncio.to_thread(
            ROS2Subscriber, "/r1/odom", "nav_msgs/msg/Odometry", heard.append, **kw
        )
        try:
            await wait_for(lambda: "/r2/cmd_vel" in link._by_name, timeout=8)
            r2 = app.world.robots["r2"]
            x0 = r2.state.x
            assert not await _publish_until(pub, lambda: r2.state.x != x0, 1.0)
            assert "/r2/cmd_vel" not in link._subscribers
            await eventually(lambda: heard)  # it reads
        finally:
            pub.close()
            sub.close()


async def test_ros2_role_robot_gives_ros2_peers_that_robot_and_no_other(
    router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import ROS2Publisher

    async with zenoh_app(router, classroom=True, ros2_role="robot:r1") as app:
        link = app.zenoh
        assert link is not None
        kw = sdk_kw(router)
        mine = await asyncio.to_thread(
            ROS2Publisher, "/r1/cmd_vel", "geometry_msgs/msg/Twist", **kw
        )
        other = await asyncio.to_thread(
            ROS2Publisher, "/r2/cmd_vel", "geometry_msgs/msg/Twist", **kw
        )
        try:
            r1, r2 = app.world.robots["r1"], app.world.robots["r2"]
            x1, x2 = r1.state.x, r2.state.x
            assert await _publish_until(mine, lambda: r1.state.x > x1 + 0.05, 8.0)
            assert await _publish_until(other, lambda: r2.state.x != x2, 0.5) is False
            assert "/r2/cmd_vel" not in link._subscribers
        finally:
            mine.close()
            other.close()


async def test_oversized_samples_are_dropped_and_the_loop_and_a_good_command_go_on(
    zapp: App, router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import ROS2Publisher

    link = zapp.zenoh
    assert link is not None
    pub = await asyncio.to_thread(
        ROS2Publisher, "/cmd_vel", "geometry_msgs/msg/Twist", **sdk_kw(router)
    )
    try:
        await wait_for(lambda: pub.keyexpr in link._subscribers.get("/cmd_vel", {}), timeout=8)
        received = link.stats["received"]
        big = b"\x00\x01\x00\x00" + b"\x00" * 4_000_000  # 4 MB on the robot's /cmd_vel key
        async with observed(zapp) as steady:
            for _ in range(30):
                await asyncio.to_thread(ros2.session.put, pub.keyexpr, big)
                await asyncio.sleep(0.02)
            await steady()
        assert link.stats["received"] == received  # none reached the graph
        robot = next(iter(zapp.world.robots.values()))
        x0 = robot.state.x
        assert await _publish_until(pub, lambda: robot.state.x > x0 + 0.05, 8.0)
        assert link.inbox.bytes == 0 and link.state == "connected"
    finally:
        pub.close()


async def test_a_token_flood_is_capped_and_comes_and_goes_without_stalling_the_loop(
    router: Router, ros2: Any
) -> None:
    async with zenoh_app(router, zenoh_max_remote_tokens=600) as app:
        link = app.zenoh
        assert link is not None
        zid = ros2.session_id

        def token(n: int) -> str:
            return (
                f"@ros2_lv/0/{zid}/77/{1000 + n}/MP/%/%/flood/%flood_{n}/"
                "std_msgs::msg::dds_::String_/RIHS01_"
                "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
            )

        liveliness = ros2.session.liveliness()
        tokens: list[Any] = []
        try:
            async with observed(app) as steady:
                await asyncio.to_thread(
                    lambda: tokens.extend(liveliness.declare_token(token(n)) for n in range(2_000))
                )
                await wait_for(lambda: link.stats["tokens_refused"] > 0, timeout=10)
                await wait_for(lambda: not link._tokens, timeout=10)
                await steady()
            assert len(link._remote) <= 600
            flood = [n for n in app.graph.topics.topics if n.startswith("/flood_")]
            assert 0 < len(flood) <= 600
        finally:  # the session is the whole run's: a failure must not flood the later tests
            await asyncio.to_thread(lambda: [t.undeclare() for t in tokens])
        await wait_for(
            lambda: not any(n.startswith("/flood_") for n in app.graph.topics.topics), timeout=10
        )
        assert not link._by_name.keys() & set(flood)


ACL_EXAMPLE = ROOT / "config" / "zenoh_router_acl.example.json5"


def _twist_cdr(x: float) -> bytes:
    """geometry_msgs/msg/Twist as CDR (little endian), written by hand."""
    return b"\x00\x01\x00\x00" + struct.pack("<6d", x, 0.0, 0.0, 0.0, 0.0, 0.0)


def _client_config(endpoint: str, user: str, password: str) -> Any:
    import zenoh

    config = zenoh.Config()
    for key, value in {
        "mode": "client",
        "connect/endpoints": [endpoint],
        "scouting/multicast/enabled": False,
        "transport/auth/usrpwd/user": user,
        "transport/auth/usrpwd/password": password,
    }.items():
        config.insert_json5(key, json.dumps(value))
    return config


async def test_the_routers_acl_gives_each_students_ros2_node_its_own_robot(
    tmp_path: Path,
) -> None:
    """config/zenoh_router_acl.example.json5 on a real router, simbridge --ros2-role robots."""
    import zenoh

    users = tmp_path / "users.txt"
    users.write_text("router:router-pw\nsimbridge:server-pw\nalice:alice-pw\nbob:bob-pw\n")
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env = {
        **os.environ,
        "ZENOH_ROUTER_CONFIG_URI": str(ACL_EXAMPLE),
        "ZENOH_CONFIG_OVERRIDE": (
            f'transport/auth/usrpwd/dictionary_file="{users}";'
            'transport/auth/usrpwd/password="router-pw"'
        ),
    }
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "simbridge", "zenohd", "--listen", endpoint,
        cwd=ROOT, env=env, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL,
    )  # fmt: skip
    alice = None
    try:
        assert proc.stdout is not None
        line = await asyncio.wait_for(proc.stdout.readline(), 20 * TIMEOUT_FACTOR)
        assert b"listening on" in line, line
        server = ZenohOptions(
            connect=(endpoint,),
            override=(
                'mode="client";transport/auth/usrpwd/user="simbridge";'
                'transport/auth/usrpwd/password="server-pw"'
            ),
        )
        settings = ServerSettings(
            host="127.0.0.1",
            port=0,
            http_port=0,
            client_tokens=TOKENS,
            admin_token=ADMIN,
            ros2_role="robots",
        )
        app = App(settings, world=CLASSROOM, zenoh=server)
        await app.start()
        try:
            link = app.zenoh
            assert link is not None
            await wait_for(lambda: link.state == "connected", timeout=10)
            with pytest.raises(zenoh.ZError):  # a wrong password gets no session
                await asyncio.to_thread(
                    zenoh.open, _client_config(endpoint, "alice", "not-her-password")
                )
            alice = await asyncio.to_thread(
                zenoh.open, _client_config(endpoint, "alice", "alice-pw")
            )

            def cmd_vel_keys() -> dict[str, str]:
                keys = {}
                for reply in alice.liveliness().get("@ros2_lv/0/**", timeout=2):
                    if reply.ok is None:
                        continue
                    with contextlib.suppress(ValueError):
                        entity = Entity.parse(str(reply.ok.key_expr))
                        if entity.kind == "MS" and entity.name.endswith("/cmd_vel"):
                            keys[entity.name] = entity.keyexpr()
                return keys if {"/r1/cmd_vel", "/r2/cmd_vel"} <= keys.keys() else {}

            keys = await eventually(cmd_vel_keys)
            # she reads every robot's topics: an rmw_zenoh subscription (its token) of /r2/odom
            hasher = TypeHasher(app.graph.registry, "jazzy")
            subscription = Entity(
                0, str(alice.info.zid()), "1", "2", "MS", "/", "alice_node",
                name="/r2/odom", type="nav_msgs/msg/Odometry",
                type_hash=hasher.message("nav_msgs/msg/Odometry"),
            )  # fmt: skip
            heard: list[str] = []
            odom = alice.declare_subscriber(
                subscription.keyexpr(), lambda s: heard.append(str(s.key_expr))
            )
            token = alice.liveliness().declare_token(subscription.token())
            gid = bytes(range(16))

            def drive(name: str, robot: str, seconds: float) -> bool:
                r = app.world.robots[robot]
                x0 = r.state.x
                deadline = time.monotonic() + seconds * TIMEOUT_FACTOR
                for sequence in itertools.count(1):
                    if abs(r.state.x - x0) > 0.05 or time.monotonic() > deadline:
                        break
                    attachment = struct.pack("<qqB", sequence, time.time_ns(), 16) + gid
                    alice.put(keys[name], _twist_cdr(0.3), attachment=attachment)
                    time.sleep(0.1)
                return abs(r.state.x - x0) > 0.05

            # simbridge lets ROS 2 drive every robot; the router lets alice reach r1's only
            assert await asyncio.to_thread(drive, "/r1/cmd_vel", "r1", 8.0)
            assert not await asyncio.to_thread(drive, "/r2/cmd_vel", "r2", 1.0)
            await wait_for(lambda: bool(heard), timeout=5)
            token.undeclare()
            odom.undeclare()
        finally:
            if alice is not None:
                await asyncio.to_thread(alice.close)
            await app.stop()
    finally:
        proc.terminate()
        await proc.communicate()


async def test_a_call_flood_is_refused_past_the_call_inbox_with_an_error_reply(
    zapp: App, router: Router, ros2: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    from simbridge.ros2.zenoh import link as link_module
    from simbridge.ros2.zenoh.attachment import Attachment

    link = zapp.zenoh
    assert link is not None
    monkeypatch.setattr(link_module, "CALL_INBOX_LIMIT", 5)
    await wait_for(
        lambda: any(e.entity.name == "/sim/pause" for e in link._declared.values()), timeout=8
    )
    key = next(e.entity.keyexpr() for e in link._declared.values() if e.entity.name == "/sim/pause")
    attachment = Attachment(1, time.time_ns(), bytes(16)).pack()
    request = b"\x00\x01\x00\x00\x01"  # SetBool data=True as CDR
    # the loop is held (as under load) while 20 calls arrive: 5 wait, 15 are refused on
    # Zenoh's threads, none more is queued on the loop
    handlers = [
        ros2.session.get(key, payload=request, attachment=attachment, timeout=5) for _ in range(20)
    ]
    deadline = time.monotonic() + 5 * TIMEOUT_FACTOR
    while link.stats["calls_refused"] < 15 and time.monotonic() < deadline:
        time.sleep(0.01)  # the event loop held on purpose: Zenoh's threads go on
    assert len(link._call_inbox) == 5 and link.stats["calls_refused"] == 15

    def collect() -> tuple[int, list[str]]:
        ok, errors = 0, []
        for handler in handlers:
            for reply in handler:
                if reply.err is not None:
                    errors.append(bytes(reply.err.payload.to_bytes()).decode())
                else:
                    ok += 1
        return ok, errors

    ok, errors = await asyncio.to_thread(collect)
    assert ok == 5 and len(errors) == 15
    assert all("too many calls waiting" in e for e in errors)
    assert zapp.simclock.paused and not link._call_inbox and link._calls_bytes == 0
