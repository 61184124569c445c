"""The Foxglove port end to end, with a real Foxglove client.

@foxglove/ws-protocol's FoxgloveClient and @foxglove/rosmsg2-serialization under Node
(tests/js/foxglove.mjs); roslib 2.1.0 is the rosbridge client whose parameter change Foxglove sees.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus
from websockets.typing import Subprotocol

from simbridge.app.config import WorldSpec
from simbridge.errors import ConfigError
from tests.conftest import AppFactory, _run_client
from tests.helpers import JS_DIR, ROOT, TIMEOUT_FACTOR, ws_url


pytestmark = pytest.mark.e2e


async def _foxglove(url: str, args: dict[str, Any], timeout: float = 25) -> Any:
    t = timeout * TIMEOUT_FACTOR
    cmd = ["node", str(JS_DIR / "foxglove.mjs"), "--url", url, "--args", json.dumps(args)]
    return await _run_client([*cmd, "--timeout-ms", str(int(t * 1000))], t)


async def test_foxglove_client_reads_channels_drives_calls_and_sets_parameters(
    make_app: AppFactory, node_ready: None
) -> None:
    app = await make_app(foxglove_port=0)
    assert app.foxglove is not None
    args = {
        "refuse": {"topic": "/odom", "type": "geometry_msgs/msg/Twist"},
        "reset": True,
        "params": True,
        "rosbridge": ws_url(app),
        "graph": True,
    }
    got = await _foxglove(f"ws://127.0.0.1:{app.foxglove.port}", args)
    assert {"clientPublish", "services", "parameters", "parametersSubscribe"} <= set(
        got["capabilities"]
    )
    assert got["odomSchema"] == "nav_msgs/msg/Odometry"
    assert got["schemaEncoding"] == "ros2msg"
    assert got["tfStatic"] == ["base_link->laser"]  # latched, published before the client came
    assert 17 <= got["odomRate"] <= 23
    assert got["odomFrames"] == ["odom", "base_link"]
    assert got["scanRanges"] == 360
    assert got["moved"] > 0.05  # /cmd_vel from the client channel moved the robot
    # the type conflict is refused by the admission, as for a rosbridge client
    assert any("already established with type nav_msgs/msg/Odometry" in s for s in got["refusal"])
    assert got["reset"] is True
    # /rosout is an ordinary delivery: the reset's line reaches the Foxglove channel
    assert got["rosout"]["msg"].startswith("world reset") and got["rosout"]["level"] == 20
    assert {"/reset", "/spawn", "/kill", "/estop", "/estop/reset"} <= set(got["services"])
    assert got["paramRead"] == 0.5
    assert got["paramFromRosbridge"] == 0.45
    assert got["clientServiceSum"] == 42  # a service a rosbridge client provides, over CDR
    assert app.world.params.robot.max_linear_velocity == 0.45
    assert got["graph"] == {
        "odomPublishers": ["/virtual_robot"],
        "odomSubscribers": ["/foxglove_bridge"],  # this client, through the marker
        "cmdVelPublishers": ["/foxglove_bridge"],
        "resetProviders": ["/virtual_robot"],
    }
    # the old name, which @foxglove/ws-protocol and older Lichtblick ask for, is refused by the
    # SDK's handshake (simbridge serves foxglove.sdk.v1 only: no protocol code of its own)
    old = [Subprotocol("foxglove.websocket.v1")]
    with pytest.raises(InvalidStatus) as refused:
        async with connect(f"ws://127.0.0.1:{app.foxglove.port}", subprotocols=old):
            pass
    assert refused.value.response.status_code == 400
    health = app.health()["foxglove"]
    assert health["port"] == app.foxglove.port and health["calls"] >= 1
    assert health["parameter_updates"] is True


CLASS_WORLD = {
    "name": "class",
    "walls": [[-3, -2, 3, -2], [3, -2, 3, 2], [3, 2, -3, 2], [-3, 2, -3, -2]],
    "robots": [{"name": "r1", "pose": [-1, 0, 0]}, {"name": "r2", "pose": [1, 1, 3.14159]}],
}


async def test_in_a_class_the_foxglove_port_drives_only_the_robot_it_was_opened_for(
    make_app: AppFactory, node_ready: None
) -> None:
    tokens = {"student-one-token": "r1", "student-two-token": "r2"}
    with pytest.raises(ConfigError, match="carries no token"):
        from simbridge.app.settings import server_settings

        server_settings(foxglove_port=0, client_tokens=tokens)
    app = await make_app(
        world=WorldSpec.parse(CLASS_WORLD),
        client_tokens=tokens,
        foxglove_port=0,
        foxglove_scope="r1",
        use_sim_time=True,
        max_advertisements=4,
    )
    assert app.foxglove is not None
    args = {"robot": "r1", "refuse": {"topic": "/r2/cmd_vel", "type": "geometry_msgs/msg/Twist"}}
    got = await _foxglove(f"ws://127.0.0.1:{app.foxglove.port}", {**args, "time": True, "flood": 4})
    assert got["moved"] > 0.05
    assert any("/r2/cmd_vel" in s and "r1" in s for s in got["refusal"])
    assert any("at most 4: max_advertisements" in s for s in got["flood"])  # its budget
    assert "time" in got["capabilities"] and got["times"] >= 2  # the sim clock, from /clock
    assert app.world.robots["r2"].state.x == pytest.approx(1.0, abs=1e-6)  # r2 never moved


async def test_a_connection_past_foxglove_max_clients_is_closed_by_name_and_its_slot_freed(
    make_app: AppFactory, node_ready: None
) -> None:
    app = await make_app(foxglove_port=0, foxglove_max_clients=2)
    assert app.foxglove is not None
    url = f"ws://127.0.0.1:{app.foxglove.port}"
    protocols = [Subprotocol("foxglove.sdk.v1")]
    async with connect(url, subprotocols=protocols) as first:
        async with connect(url, subprotocols=protocols) as second:
            await second.recv()  # serverInfo: both are clients of the SDK
            got = await _foxglove(url, {"closed": True}, timeout=10)  # the third: the real client
            assert got["code"] == 1008
            assert got["reason"] == "too many Foxglove clients (at most 2: foxglove_max_clients)"
            health = app.health()["foxglove"]
            assert health["clients_refused"] == 1 and health["clients"] == 2
            await second.ping()  # the two within the budget are untouched
        await first.ping()
        async with connect(url, subprotocols=protocols) as again:  # the slot left is free
            await again.recv()
            # a scan counted it (one of the two) and did not close it
            watch, peer = app.foxglove.watch, again.local_address[:2]
            assert watch is not None
            async with asyncio.timeout(5 * TIMEOUT_FACTOR):
                while tuple(peer) not in watch.order.values():
                    await asyncio.sleep(0.02)
            assert app.foxglove.connections == 2
            await again.ping()
    assert app.foxglove.stats["clients_refused"] == 1


def test_without_the_option_nothing_of_foxglove_is_imported() -> None:
    code = (
        "import sys; from simbridge.app.runner import App; App(); "
        "print(sorted(m for m in sys.modules if 'foxglove' in m))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def test_the_option_without_the_extra_exits_with_the_install_command() -> None:
    code = (
        "import sys; sys.modules['foxglove'] = None; from simbridge.cli import main; "
        "sys.exit(main(['--foxglove-port', '0', '--port', '0', '--no-http']))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 2
    assert 'pip install "simbridge[foxglove]"' in out.stderr


def test_set_nodelay_turns_nagle_off_on_this_process_s_sockets_of_the_port_once() -> None:
    import socket

    from simbridge.foxglove.front import set_nodelay

    with socket.create_server(("127.0.0.1", 0)) as listener:
        port = listener.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)) as _client:
            accepted, _ = listener.accept()
            with accepted:
                assert accepted.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 0
                done: set[tuple[int, int]] = set()
                assert set_nodelay(port, done) == 1  # the accepted socket, not the listener
                assert accepted.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
                assert set_nodelay(port, done) == 0


async def test_a_clients_messages_waiting_for_the_loop_are_bounded_per_client(
    make_app: AppFactory,
) -> None:
    import threading
    import time
    from types import SimpleNamespace

    from simbridge.foxglove.front import INBOX_BYTES, INBOX_MESSAGES

    app = await make_app(foxglove_port=0)
    front = app.foxglove
    assert front is not None
    flooder, other = SimpleNamespace(id=901), SimpleNamespace(id=902)  # as the SDK's Client

    def flood() -> None:  # the SDK's thread: the listener's callback
        for _ in range(INBOX_MESSAGES + 100):
            front.listener.on_message_data(flooder, 1, b"{}")
        front.listener.on_message_data(other, 1, b"{}")  # another client is not affected
        big = b" " * (INBOX_BYTES // 2 - 1)  # two fit beside the small one, not three
        for _ in range(3):
            front.listener.on_message_data(other, 2, big)

    # the event loop held (as under load) while the SDK's thread hands messages over
    thread = threading.Thread(target=flood)
    thread.start()
    thread.join(10 * TIMEOUT_FACTOR)
    assert not thread.is_alive()
    assert front._waiting[901] == [INBOX_MESSAGES, 2 * INBOX_MESSAGES]
    assert front._waiting[902] == [3, 2 + 2 * (INBOX_BYTES // 2 - 1)]
    assert front.stats["messages_dropped"] == 100 + 1  # by count, then by bytes
    deadline = time.monotonic() + 5 * TIMEOUT_FACTOR
    while front._waiting and time.monotonic() < deadline:
        await asyncio.sleep(0.01)  # the loop takes them (unknown clients: nothing published)
    assert not front._waiting and front.health()["messages_dropped"] == 101
