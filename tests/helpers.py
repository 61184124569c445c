"""Helpers of the test suite and the benchmarks: URLs, JSON over WebSocket, waiting, raw sockets."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import signal
import socket
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection

from simbridge.app.runner import App
from simbridge.graph.access import Access


ROOT = Path(__file__).resolve().parent.parent
JS_DIR = ROOT / "tests" / "js"
ROSLIBPY_RUN = ROOT / "tests" / "clients" / "roslibpy_run.py"
#: Scales every timeout of the suite (slow CI machines: SIMBRIDGE_TEST_TIMEOUT_FACTOR=3).
TIMEOUT_FACTOR = float(os.environ.get("SIMBRIDGE_TEST_TIMEOUT_FACTOR", "1"))


async def finish_process(
    proc: asyncio.subprocess.Process, timeout: float = 20
) -> tuple[int, str, str]:
    """Wait for a process started with piped output; return (exit code, stdout, stderr).

    ``timeout`` is scaled by :data:`TIMEOUT_FACTOR`; past it the process is killed and
    ``TimeoutError`` raised.
    """
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout * TIMEOUT_FACTOR)
    except TimeoutError:
        signals = _signal_state(proc.pid)
        # a Python child started with faulthandler on (PYTHONFAULTHANDLER) prints where each of
        # its threads is; what it wrote from now on goes into the report
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGABRT)
        try:
            out, err = await asyncio.wait_for(proc.communicate(), 5)
        except TimeoutError:
            proc.kill()
            out, err = await proc.communicate()
        msg = f"the process did not end within {timeout * TIMEOUT_FACTOR:g} s ({signals}); "
        msg += "then it wrote:\n"
        msg += f"stdout: {out.decode()[-2000:]}\nstderr: {err.decode()[-6000:]}"
        raise TimeoutError(msg) from None
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


def _signal_state(pid: int) -> str:
    """A live process's signal masks and threads, from ``/proc`` (for a report)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        threads = {}
        for task in Path(f"/proc/{pid}/task").iterdir():
            lines = (task / "status").read_text().splitlines()
            threads[task.name] = " ".join(x for x in lines if x.startswith(("SigBlk", "SigPnd")))
    except OSError as err:
        return f"no /proc state: {err}"
    keep = ("Threads", "SigQ", "ShdPnd", "SigIgn", "SigCgt")
    lines = [x for x in status.splitlines() if x.startswith(keep)]
    return "; ".join([*lines, *(f"task {k}: {v}" for k, v in threads.items())])


def cmd_vel_bag(path: Path, commands: list[tuple[float, float, float]]) -> None:
    """Write a bag of /cmd_vel: (seconds, linear, angular) at 10 Hz, then one zero command."""
    from simbridge.msgs import Converter, TypeRegistry
    from simbridge.tools.bag import BagWriter  # rosbags: only the tests that write bags pay for it

    registry = TypeRegistry()
    conv = Converter(registry, lambda: (0, 0))
    writer = BagWriter(path, registry)
    t = 1_700_000_000 * 10**9
    for seconds, v, w in [*commands, (0.1, 0.0, 0.0)]:
        for _ in range(round(seconds * 10)):
            msg = conv.from_json(
                "geometry_msgs/msg/Twist", {"linear": {"x": v}, "angular": {"z": w}}
            )
            writer.write("/cmd_vel", "geometry_msgs/msg/Twist", msg, t)
            t += 100_000_000
    writer.close()


def ws_url(app: App) -> str:
    """Return the rosbridge URL of a running app."""
    return f"ws://127.0.0.1:{app.ws_port}"


def http_url(app: App) -> str:
    """Return the HTTP base URL of a running app."""
    return f"http://127.0.0.1:{app.http_port}"


async def recv_json(conn: ClientConnection, timeout: float = 2.0) -> Any:
    """Receive one message and parse it as JSON (text frames only)."""
    data = await asyncio.wait_for(conn.recv(), timeout * TIMEOUT_FACTOR)
    assert isinstance(data, str), f"expected a text frame, got {type(data).__name__}"
    return json.loads(data)


async def recv_until(
    conn: ClientConnection, predicate: Callable[[Any], bool], timeout: float = 3.0
) -> Any:
    """Receive JSON messages until one satisfies ``predicate``; return it."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout * TIMEOUT_FACTOR
    while True:
        remaining = deadline - loop.time()
        if remaining <= 0:
            msg = "no matching message before the timeout"
            raise TimeoutError(msg)
        data = await asyncio.wait_for(conn.recv(), remaining)
        value = json.loads(data)
        if predicate(value):
            return value


async def send_json(conn: ClientConnection, value: Any) -> None:
    """Send ``value`` as a JSON text frame."""
    await conn.send(json.dumps(value))


async def wait_for(predicate: Callable[[], bool], timeout: float = 3.0, step: float = 0.01) -> None:
    """Wait until ``predicate()`` is true, polling; raise TimeoutError after ``timeout``."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout * TIMEOUT_FACTOR
    while not predicate():
        if loop.time() > deadline:
            msg = "condition not met before the timeout"
            raise TimeoutError(msg)
        await asyncio.sleep(step)


#: The rosbridge front end of each graph a test made (the server's own for an App's graph).
_FRONTS: weakref.WeakKeyDictionary[Any, Any] = weakref.WeakKeyDictionary()
#: The server settings of each graph made by :func:`graph_for` (its rosbridge's budgets).
_SETTINGS: weakref.WeakKeyDictionary[Any, Any] = weakref.WeakKeyDictionary()


def graph_for(settings: Any, **kwargs: Any) -> Any:
    """A graph with what ``settings`` give a graph; :func:`rosbridge_of` takes their budgets."""
    from simbridge.graph import Graph

    graph = Graph(
        service_timeout=settings.service_timeout,
        max_parameter_names=settings.max_parameter_names,
        **kwargs,
    )
    _SETTINGS[graph] = settings
    return graph


def rosbridge_of(graph: Any, authenticator: Any = None) -> Any:
    """Return the rosbridge front end of ``graph`` (made once; ``authenticator``: a guard).

    Its budgets are those of the settings the graph was made for (:func:`graph_for`), or the
    defaults.
    """
    from simbridge.app.settings import ServerSettings, budgets
    from simbridge.rosbridge.front import Rosbridge

    front = _FRONTS.get(graph)
    if front is None:
        settings = _SETTINGS.get(graph) or ServerSettings()
        front = _FRONTS[graph] = Rosbridge(
            graph, *budgets(settings), default_queue_length=settings.default_queue_length
        )
    if authenticator is not None:
        front.authenticator = authenticator
    return front


def op(peer: RecordingPeer, graph: Any, now: float = 0.0, **fields: Any) -> None:
    """Deliver one op (its fields as keyword arguments) from ``peer`` to ``graph`` at ``now``."""
    rosbridge_of(graph).receive(peer, json.dumps(fields), now)


def clocked_graph() -> Any:
    """A graph with rosapi and a fixed wall clock (stamps 1700000000.5 s)."""
    from simbridge.graph import Graph
    from simbridge.graph.rosapi import install_rosapi

    graph = Graph(wall_clock_ns=lambda: 1_700_000_000_500_000_000)
    install_rosapi(graph)
    return graph


class RecordingPeer:
    """A graph peer that records what it is sent (the seam where a socket would be)."""

    def __init__(self, graph: Any, label: str = "peer", *, token: str | None = None) -> None:
        self.front = rosbridge_of(graph)
        self.session = self.front.new_session(token)
        self.label = label
        self.frames: list[Any] = []
        self.front.add_peer(self)

    @property
    def access(self) -> Access:
        return self.session.access

    def send(self, frame: Any, key: Any = None, limit: int = 0) -> None:
        self.frames.append(frame)

    def messages(self) -> list[Any]:
        """Every JSON message received so far, decoded."""
        return [json.loads(f.data) for f in self.frames if f.text]

    def take(self) -> list[Any]:
        """Return and forget the messages received so far."""
        out = self.messages()
        self.frames.clear()
        return out


async def unread_socket(host: str, port: int, path: str = "/") -> socket.socket:
    """Open a WebSocket by hand with a tiny receive buffer and return it, upgraded, unread.

    ``path`` is the request target (``/?token=T``); nothing is read after the upgrade's head.
    """
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.setblocking(False)
    loop = asyncio.get_running_loop()
    await loop.sock_connect(sock, (host, port))
    key = base64.b64encode(os.urandom(16)).decode()
    await loop.sock_sendall(
        sock,
        (
            f"GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n"
        ).encode(),
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += await loop.sock_recv(sock, 1)
    assert head.startswith(b"HTTP/1.1 101"), head
    return sock


async def stalled_client(port: int, subscribe: dict[str, object], path: str = "/") -> socket.socket:
    """Open a WebSocket by hand with a tiny receive buffer, subscribe, and never read again.

    ``subscribe`` is the one op sent (any op); ``path`` the request target (``/?token=T``).
    """
    sock = await unread_socket("127.0.0.1", port, path)
    loop = asyncio.get_running_loop()
    payload = json.dumps(subscribe).encode()
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    assert len(payload) < 126
    await loop.sock_sendall(sock, bytes([0x81, 0x80 | len(payload)]) + mask + masked)
    return sock
