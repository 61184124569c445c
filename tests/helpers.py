"""Helpers of the test suite: URLs, JSON over WebSocket, waiting for conditions."""

from __future__ import annotations

import asyncio
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection

from simbridge.runner import App


ROOT = Path(__file__).resolve().parent.parent
JS_DIR = ROOT / "tests" / "js"
ROSLIBPY_RUN = ROOT / "tests" / "clients" / "roslibpy_run.py"
#: Scales every timeout of the suite (slow CI machines: SIMBRIDGE_TEST_TIMEOUT_FACTOR=3).
TIMEOUT_FACTOR = float(os.environ.get("SIMBRIDGE_TEST_TIMEOUT_FACTOR", "1"))


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


class RecordingPeer:
    """A graph peer that records what it is sent (the seam where a socket would be)."""

    def __init__(self, graph: Any, label: str = "peer") -> None:
        self.session = graph.new_session()
        self.label = label
        self.frames: list[Any] = []
        graph.add_peer(self)

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
