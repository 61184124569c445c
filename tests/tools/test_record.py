from __future__ import annotations

import asyncio
import signal
import sys
from collections import Counter
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from websockets.asyncio.client import connect

from simbridge.app.config import Params, RobotParams
from simbridge.app.runner import App
from simbridge.tools.bag import read_messages
from simbridge.tools.compare import load_run
from simbridge.tools.record import replay_headless
from tests.conftest import AppFactory
from tests.helpers import (
    ROOT,
    TIMEOUT_FACTOR,
    cmd_vel_bag,
    finish_process,
    recv_until,
    send_json,
    wait_for,
    ws_url,
)


async def start(*args: str) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "simbridge",
        *args,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )


async def test_record_until_sigint_writes_one_mcap(app: App, tmp_path: Path) -> None:
    """Ctrl-C finalises the bag: one .mcap with /odom and the /cmd_vel a client sent."""
    proc = await start(
        "record", "--url", ws_url(app), "-o", str(tmp_path / "run"), "/odom", "/cmd_vel"
    )
    assert proc.stderr is not None
    line = await asyncio.wait_for(proc.stderr.readline(), 10 * TIMEOUT_FACTOR)
    assert b"recording to" in line
    async with connect(ws_url(app)) as conn:
        await send_json(
            conn, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"}
        )
        for _ in range(3):
            await send_json(
                conn, {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.1}}}
            )
        await send_json(conn, {"op": "subscribe", "topic": "/odom"})
        for _ in range(10):  # half a second of /odom
            await recv_until(conn, lambda m: m.get("topic") == "/odom")
    proc.send_signal(signal.SIGINT)
    code, out, err = await finish_process(proc)
    assert code == 0, err
    assert "recorded" in out
    bag = tmp_path / "run"
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "run.mcap"]
    counts = Counter(topic for topic, *_ in read_messages(bag))
    assert counts["/cmd_vel"] == 3
    assert counts["/odom"] >= 5
    odom = next(m for t, _ty, _s, m in read_messages(bag) if t == "/odom")
    assert odom["header"]["frame_id"] == "odom"


async def test_sigkill_mid_recording_leaves_a_readable_bag(app: App, tmp_path: Path) -> None:
    """SIGKILL loses at most the open segment; rosbags' Reader reads the rest."""
    bag = tmp_path / "killed"
    proc = await start("record", "--url", ws_url(app), "-o", str(bag), "-a", "--segment", "0.3")
    await wait_for(lambda: len(list(bag.glob("killed_*.mcap"))) >= 3, timeout=10)
    proc.kill()
    await finish_process(proc)
    with Reader(bag) as reader:
        assert reader.message_count > 10
        store = get_typestore(Stores.LATEST)
        topics = Counter()
        for conn, _stamp, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            topics[conn.topic] += 1
        assert topics["/odom"] > 5
        assert msg is not None


async def test_record_needs_topics_or_all() -> None:
    code, _out, err = await finish_process(await start("record", "--url", "ws://127.0.0.1:1"))
    assert code == 2
    assert "-a" in err


async def test_replay_publishes_the_recorded_commands(app: App, tmp_path: Path) -> None:
    cmd_vel_bag(tmp_path / "cmds", [(0.5, 0.2, 0.0), (0.5, 0.0, 0.4)])
    async with connect(ws_url(app)) as conn:
        await send_json(conn, {"op": "subscribe", "topic": "/cmd_vel"})
        proc = await start("replay", str(tmp_path / "cmds"), "--url", ws_url(app))
        got = [
            (await recv_until(conn, lambda m: m.get("topic") == "/cmd_vel", timeout=5))["msg"]
            for _ in range(11)
        ]
        code, out, err = await finish_process(proc)
    assert code == 0, err
    assert "replayed 11 messages" in out
    assert [m["linear"]["x"] for m in got] == [0.2] * 5 + [0.0] * 6
    assert [m["angular"]["z"] for m in got] == [0.0] * 5 + [0.4] * 5 + [0.0]


def test_headless_replay_simulates_the_commands(tmp_path: Path) -> None:
    """0.2 m/s for 2 s, then stop: the simulated /odom ends 0.4 m ahead."""
    cmd_vel_bag(tmp_path / "real", [(2.0, 0.2, 0.0)])
    writer = replay_headless(str(tmp_path / "real"), tmp_path / "sim")
    assert writer.count > 0
    odom = [(s, m) for t, _ty, s, m in read_messages(tmp_path / "sim") if t == "/odom"]
    first_cmd = next(s for t, _ty, s, _m in read_messages(tmp_path / "real") if t == "/cmd_vel")
    assert odom[0][0] > first_cmd  # on the source bag's time line
    stamps = [m["header"]["stamp"] for _s, m in odom]
    assert [s["sec"] * 10**9 + s["nanosec"] for s in stamps] == [s for s, _m in odom]
    assert odom[-1][1]["pose"]["pose"]["position"]["x"] == pytest.approx(0.4, abs=0.011)


def test_headless_replay_of_a_twist_bag_drives_a_stamped_robot(tmp_path: Path) -> None:
    """robot.cmd_vel_stamped: the bag's Twists become TwistStamped; compare still aligns."""
    cmd_vel_bag(tmp_path / "real", [(1.0, 0.2, 0.0)])
    params = tmp_path / "stamped.yaml"
    params.write_text("robot:\n  cmd_vel_stamped: true\n")
    replay_headless(str(tmp_path / "real"), tmp_path / "sim", params=str(params))
    cmds = [(ty, m) for t, ty, _s, m in read_messages(tmp_path / "sim") if t == "/cmd_vel"]
    assert cmds[0][0] == "geometry_msgs/msg/TwistStamped"
    assert cmds[0][1]["twist"]["linear"]["x"] == 0.2
    assert cmds[0][1]["header"]["stamp"]["sec"] == 1_700_000_000
    assert load_run(tmp_path / "sim").distance() == pytest.approx(0.2, abs=0.011)


async def test_replay_converts_twist_to_the_servers_twist_stamped(
    make_app: AppFactory, tmp_path: Path
) -> None:
    app = await make_app(params=Params(robot=RobotParams(cmd_vel_stamped=True)))
    cmd_vel_bag(tmp_path / "cmds", [(0.1, 0.2, 0.0)])
    async with connect(ws_url(app)) as conn:
        await send_json(conn, {"op": "subscribe", "topic": "/cmd_vel"})
        proc = await start("replay", str(tmp_path / "cmds"), "--url", ws_url(app))
        got = (await recv_until(conn, lambda m: m.get("topic") == "/cmd_vel", timeout=5))["msg"]
        code, _out, err = await finish_process(proc)
    assert code == 0, err
    assert got["twist"]["linear"]["x"] == 0.2
    assert got["header"]["frame_id"] == "base_link"


async def test_server_records_itself_with_the_record_flag(tmp_path: Path) -> None:
    """`simbridge --record DIR` records in process; /cmd_vel from a client lands in the bag."""
    bag = tmp_path / "served"
    proc = await start(
        *("--host", "127.0.0.1", "--port", "0", "--no-http", "--log-level", "warning"),
        *("--record", str(bag), "--record-topics", "/odom", "/cmd_vel", "/tf_static"),
    )
    assert proc.stdout is not None
    line = (await asyncio.wait_for(proc.stdout.readline(), 10 * TIMEOUT_FACTOR)).decode()
    url = line.split()[2].rstrip("/")
    assert url.startswith("ws://127.0.0.1:"), line
    async with connect(url) as conn:
        await send_json(conn, {"op": "publish", "topic": "/cmd_vel", "type": "geometry_msgs/Twist",
                               "msg": {"linear": {"x": 0.3}}})  # fmt: skip
        await send_json(conn, {"op": "subscribe", "topic": "/odom"})
        for _ in range(6):
            await recv_until(conn, lambda m: m.get("topic") == "/odom")
    proc.send_signal(signal.SIGINT)
    code, out, err = await finish_process(proc)
    assert code == 0, err
    assert "recorded" in out
    counts = Counter(topic for topic, *_ in read_messages(bag))
    assert counts["/cmd_vel"] == 1
    assert counts["/tf_static"] == 1  # latched before the recorder started
    assert counts["/odom"] >= 6
