from __future__ import annotations

import asyncio
import contextlib
import signal
import sys

import pytest
import yaml
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.tools.client import ClientError
from simbridge.tools.rostool import describe_value, hz_report, parse_yaml
from tests.helpers import (
    ROOT,
    finish_process,
    recv_until,
    send_json,
    wait_for,
    ws_url,
)


async def simbridge(*args: str, timeout: float = 15) -> tuple[int, str, str]:
    """Run the `simbridge` command line; return (exit code, stdout, stderr)."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "simbridge",
        *args,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    return await finish_process(proc, timeout)


async def test_topic_list_shows_types(app: App) -> None:
    code, out, err = await simbridge("topic", "list", "-t", "--url", ws_url(app))
    assert code == 0, err
    assert "/odom [nav_msgs/msg/Odometry]" in out.splitlines()
    assert "/clock [rosgraph_msgs/msg/Clock]" in out.splitlines()


async def test_topic_echo_once_prints_one_yaml_message(app: App) -> None:
    code, out, err = await simbridge("topic", "echo", "/odom", "--once", "--url", ws_url(app))
    assert code == 0, err
    docs = [d for d in yaml.safe_load_all(out) if d is not None]
    assert len(docs) == 1
    assert docs[0]["header"]["frame_id"] == "odom"
    assert len(docs[0]["pose"]["covariance"]) == 36
    code, out, err = await simbridge(
        "topic",
        "echo",
        "/odom",
        "--times",
        "2",
        "--field",
        "pose.pose.position",
        "--url",
        ws_url(app),
    )
    assert code == 0, err
    docs = [d for d in yaml.safe_load_all(out) if d is not None]
    assert len(docs) == 2
    assert set(docs[0]) == {"x", "y", "z"}


async def test_topic_pub_once_drives_the_robot(app: App) -> None:
    code, out, err = await simbridge(
        *("topic", "pub", "/cmd_vel", "geometry_msgs/msg/Twist"),
        *("{linear: {x: 0.2}, angular: {z: -0.5}}", "--once", "--url", ws_url(app)),
    )
    assert code == 0, err
    assert "publishing #1: {linear: {x: 0.2}, angular: {z: -0.5}}" in out
    robot = app.world.robots[""]
    assert (robot.cmd_v, robot.cmd_omega) == (0.2, -0.5)


async def test_topic_pub_at_a_rate_a_number_of_times(app: App) -> None:
    async with connect(ws_url(app)) as conn:
        await send_json(conn, {"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"})
        task = asyncio.create_task(
            simbridge(
                "topic",
                "pub",
                "/chatter",
                "std_msgs/msg/String",
                "data: hello",
                "-r",
                "20",
                "-t",
                "5",
                "--url",
                ws_url(app),
            )
        )
        got = [await recv_until(conn, lambda m: m.get("topic") == "/chatter") for _ in range(5)]
        code, _out, err = await task
    assert code == 0, err
    assert [m["msg"]["data"] for m in got] == ["hello"] * 5


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
async def test_topic_pub_ends_cleanly_on_a_signal_even_with_sigint_ignored(
    app: App, sig: signal.Signals
) -> None:
    """``topic pub`` ends on ``kill -INT`` and on ``kill``: exit 0, no trace.

    It is started as a script's background job is (``cmd &``: SIGINT and SIGQUIT ignored).
    """
    script = 'trap "" INT QUIT; exec "$@"'
    proc = await asyncio.create_subprocess_exec(
        *("sh", "-c", script, "sh", sys.executable, "-m", "simbridge", "topic", "pub"),
        *("/chatter", "std_msgs/msg/String", "data: hi", "-r", "20", "--url", ws_url(app)),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    assert proc.stdout is not None
    line = b""
    while not line.startswith(b"publishing #1"):
        line = await asyncio.wait_for(proc.stdout.readline(), 15)
        assert line, "topic pub ended before publishing"
    proc.send_signal(sig)
    code, _out, err = await finish_process(proc, 10)
    assert (code, err) == (0, "")


async def test_topic_pub_bad_message_exits_1_with_the_reason(app: App) -> None:
    code, _out, err = await simbridge(
        "topic",
        "pub",
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        "{linear: {x: fast}}",
        "--once",
        "--url",
        ws_url(app),
    )
    assert code == 1
    assert "linear.x must be a float64" in err
    code, _out, err = await simbridge(
        "topic",
        "pub",
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        "{linear: [",
        "--once",
        "--url",
        ws_url(app),
    )
    assert code == 1
    assert "not valid YAML" in err


async def test_topic_hz_reports_the_odom_rate(app: App) -> None:
    code, out, err = await simbridge(
        "topic", "hz", "/odom", "--window", "20", "--duration", "2.5", "--url", ws_url(app)
    )
    assert code == 0, err
    rates = [float(line.split(":")[1]) for line in out.splitlines() if "average rate" in line]
    assert rates, out
    assert 10 < rates[-1] < 30, out  # 20 Hz
    assert "window: 20" in out


async def test_service_call_pauses_the_simulation(app: App) -> None:
    code, out, err = await simbridge(
        "service",
        "call",
        "/sim/pause",
        "std_srvs/srv/SetBool",
        "{data: true}",
        "--url",
        ws_url(app),
    )
    assert code == 0, err
    assert app.simclock.paused
    response = yaml.safe_load(out.split("response:", 1)[1])
    assert response["success"] is True
    code, out, err = await simbridge("service", "call", "/sim/step", "--url", ws_url(app))
    assert code == 0, err
    assert "stepped to" in out
    code, out, err = await simbridge("service", "call", "/no_such", "--url", ws_url(app))
    assert code == 1
    assert "does not exist" in err


async def test_param_get_set_and_list(app: App) -> None:
    url = ws_url(app)
    name = ["/virtual_robot", "robot.max_linear_velocity"]
    code, out, err = await simbridge("param", "get", *name, "--url", url)
    assert (code, out.strip()) == (0, "Double value is: 0.5"), err
    code, out, err = await simbridge("param", "set", *name, "0.3", "--url", url)
    assert (code, out.strip()) == (0, "Set parameter successful"), err
    await wait_for(lambda: app.world.params.robot.max_linear_velocity == 0.3)
    code, out, err = await simbridge("param", "set", *name, "abc", "--url", url)
    assert code == 1
    assert "Setting parameter failed" in err
    code, out, err = await simbridge("param", "list", "/virtual_robot", "--url", url)
    assert code == 0, err
    assert "  robot.max_linear_velocity" in out.splitlines()


async def test_unreachable_server_is_a_clear_error() -> None:
    code, _out, err = await simbridge(
        "topic", "list", "--url", "ws://127.0.0.1:1", "--timeout", "2"
    )
    assert code == 1
    assert "cannot connect to rosbridge at ws://127.0.0.1:1" in err
    assert "Traceback" not in err


def test_parse_yaml_and_describe_value() -> None:
    assert parse_yaml("{linear: {x: 0.2}}", "message") == {"linear": {"x": 0.2}}
    assert parse_yaml("", "message") == {}
    with pytest.raises(ClientError, match="not valid YAML"):
        parse_yaml("{a: [", "message")
    assert describe_value(True) == "Boolean value is: True"
    assert describe_value(3) == "Integer value is: 3"
    assert describe_value(0.5) == "Double value is: 0.5"
    assert describe_value([0.0, 1.0]) == "Double array value is: [0.0, 1.0]"


def test_hz_report_of_regular_stamps() -> None:
    report = hz_report([0.0, 0.05, 0.10, 0.15])
    assert report is not None
    assert report.startswith("average rate: 20.000")
    assert "window: 4" in report
    assert hz_report([1.0]) is None


async def test_topic_echo_of_a_topic_not_published_yet_warns_then_waits_for_it(app: App) -> None:
    """As `ros2 topic echo`: one warning at once, then the first message once it appears."""
    proc = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "simbridge", "topic", "echo", "/later", "--once"),
        *("--url", ws_url(app)),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    assert proc.stderr is not None
    line = await asyncio.wait_for(proc.stderr.readline(), 15)
    assert line.decode() == "WARNING: topic [/later] does not appear to be published yet\n"
    assert proc.returncode is None  # still waiting
    async with connect(ws_url(app)) as conn:
        await send_json(conn, {"op": "advertise", "topic": "/later", "type": "std_msgs/String"})
        while proc.returncode is None:  # until echo has subscribed and printed one message
            await send_json(conn, {"op": "publish", "topic": "/later", "msg": {"data": "here"}})
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(proc.wait(), 0.2)
        code, out, err = await finish_process(proc)
    assert code == 0, err
    assert out == "data: here\n---\n"
