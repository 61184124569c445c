"""Fixtures of the ROS 2 over Zenoh tests.

A router from ``simbridge zenohd`` on a free port of 127.0.0.1, simbridge apps joined to it,
and zenoh-ros2-sdk (an independent rmw_zenoh implementation) as the ROS 2 side, reading message
definitions from a local directory.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import socket
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import pytest

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.msgs import TypeRegistry
from simbridge.ros2.zenoh.config import ZenohOptions
from tests.helpers import ROOT, TIMEOUT_FACTOR


#: Types the ROS 2 side of the tests uses (their .msg/.srv files are written for the SDK).
MESSAGES = [
    "nav_msgs/msg/Odometry",
    "sensor_msgs/msg/LaserScan",
    "tf2_msgs/msg/TFMessage",
    "geometry_msgs/msg/Twist",
    "std_msgs/msg/String",
    "visualization_msgs/msg/Marker",
    "action_msgs/msg/GoalStatusArray",
]
SERVICES = [
    "std_srvs/srv/Empty",
    "std_srvs/srv/SetBool",
    "std_srvs/srv/Trigger",
    "rcl_interfaces/srv/GetParameters",
    "rcl_interfaces/srv/SetParameters",
    "action_msgs/srv/CancelGoal",
]
#: Actions whose rcl_action wire types (``Foo_SendGoal``, ...) are written for the SDK.
ACTIONS = ["example_interfaces/action/Fibonacci"]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def write_definitions(root: Path) -> None:
    """Write ``<root>/<pkg>/msg/<Type>.msg`` (and ``srv``) as zenoh-ros2-sdk reads them first."""
    registry = TypeRegistry()
    done: set[str] = set()

    def add(name: str) -> None:
        if name in done:
            return
        done.add(name)
        pkg, kind, short = name.split("/")
        folder = root / pkg / kind
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{short}.msg").write_text(registry.message_text(name))
        for field in registry.spec(name).fields:
            if field.nested:
                add(field.base)

    for name in MESSAGES:
        add(name)
    wire = [registry.action_wire(name) for name in ACTIONS]
    for _, _, feedback in wire:
        add(feedback)
    for name in SERVICES + [s for w in wire for s in w[:2]]:
        request, response = registry.service(name)
        pkg, kind, short = name.split("/")
        folder = root / pkg / kind
        folder.mkdir(parents=True, exist_ok=True)
        text = _qualified(registry, request) + "\n---\n" + _qualified(registry, response)
        (folder / f"{short}.srv").write_text(text)
        if kind == "action":  # the SDK reads every service type from <pkg>/srv/
            (root / pkg / "srv").mkdir(parents=True, exist_ok=True)
            (root / pkg / "srv" / f"{short}.srv").write_text(text)
        for part in (request, response):
            for field in registry.spec(part).fields:
                if field.nested:
                    add(field.base)


def _qualified(registry: TypeRegistry, name: str) -> str:
    """Return the .msg text of a service part with nested types spelled ``pkg/Type``.

    The SDK would look a bare ``Type`` up in the service's own package.
    """
    text = registry.message_text(name)
    for field in registry.spec(name).fields:
        if field.nested:
            pkg, _, short = field.base.split("/")
            text = re.sub(rf"(?m)^{short}\b", f"{pkg}/{short}", text)
    return text


class Router:
    """A ``simbridge zenohd`` process on a free port of 127.0.0.1."""

    def __init__(self) -> None:
        self.port = free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.proc: subprocess.Popen[str] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "simbridge", "zenohd", "--listen", self.endpoint],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()  # printed once the router listens
        assert "listening on" in line, f"zenohd did not start: {line!r} {self.proc.stderr}"

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            self.proc.communicate(timeout=10)  # closes the pipes too
            self.proc = None


@pytest.fixture(scope="session")
def definitions(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The SDK's message directory (it never fetches definitions from the network then)."""
    root = tmp_path_factory.mktemp("ros2_msgs")
    write_definitions(root)
    from zenoh_ros2_sdk import message_registry

    message_registry.get_registry(str(root))  # the SDK's registry is global: set it first
    return root


@pytest.fixture(scope="session")
def router() -> Iterator[Router]:
    """The router of the Zenoh tests (one: the SDK keeps one session per process)."""
    r = Router()
    r.start()
    yield r
    r.stop()


@pytest.fixture(scope="session")
def ros2(router: Router, definitions: Path) -> Iterator[Any]:
    """zenoh-ros2-sdk's shared session, connected to the router."""
    from zenoh_ros2_sdk import ZenohSession

    if ZenohSession._instance is not None:
        ZenohSession._instance.close()
    session = ZenohSession.get_instance("127.0.0.1", router.port)
    yield session
    session.close()


def zenoh_options(router: Router, **changes: Any) -> ZenohOptions:
    values: dict[str, Any] = {"connect": (router.endpoint,), "listen": ("tcp/127.0.0.1:0",)}
    values.update(changes)
    return ZenohOptions(**values)


@pytest.fixture
async def zapp(router: Router, ros2: Any) -> AsyncIterator[App]:
    """A simbridge (default world) on the router's Zenoh network."""
    app = App(ServerSettings(host="127.0.0.1", port=0, http_port=0), zenoh=zenoh_options(router))
    await app.start()
    yield app
    await app.stop()


#: The world of the second process of the classroom tests: robot a1 in a room of its own.
ROOM_A = """\
name: room_a
walls:
  - [-3.0, -2.0, 3.0, -2.0]
  - [-3.0, 2.0, 3.0, 2.0]
robots:
  - {name: a1, pose: [-1.0, 0.0, 0.0]}
"""


@contextlib.asynccontextmanager
async def room_a_process(router: Router, tmp_path: Path) -> AsyncIterator[None]:
    """A second simbridge process simulating robot a1 (:data:`ROOM_A`) on ``router``.

    Entered once it serves (its first line names its rosbridge URL); stopped on exit.
    """
    world = tmp_path / "room_a.yaml"
    world.write_text(ROOM_A)
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "simbridge",
        "--zenoh",
        "--zenoh-connect",
        router.endpoint,
        "--zenoh-listen",
        "tcp/127.0.0.1:0",
        "--world",
        str(world),
        "--host",
        "127.0.0.1",
        "--port",
        "0",
        "--no-http",
        cwd=ROOT,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
    )
    try:
        assert proc.stdout is not None
        line = await asyncio.wait_for(proc.stdout.readline(), 20 * TIMEOUT_FACTOR)
        assert b"rosbridge ws://" in line, line
        yield
    finally:
        proc.terminate()
        await proc.communicate()


async def eventually(check: Any, timeout: float = 8.0, step: float = 0.05) -> Any:
    """Call ``check`` (in a thread: the SDK blocks) until it returns something true."""
    deadline = time.monotonic() + timeout * TIMEOUT_FACTOR
    while True:
        value = await asyncio.to_thread(check)
        if value:
            return value
        if time.monotonic() > deadline:
            msg = f"condition not met within {timeout} s: {check}"
            raise AssertionError(msg)
        await asyncio.sleep(step)
