"""A real simbridge process for the reliability benchmarks, and raw-socket client helpers."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import re
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import psutil


@contextmanager
def server(*options: str) -> Iterator[tuple[int, psutil.Process]]:
    """Run ``simbridge --host 127.0.0.1 --port 0 --no-http OPTIONS``; yield its port and process."""
    cmd = [sys.executable, "-m", "simbridge", "--host", "127.0.0.1", "--port", "0", "--no-http"]
    proc = subprocess.Popen(
        [*cmd, "--log-level", "warning", *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        match = re.search(r"ws://[^:]+:(\d+)/", line)
        if match is None:
            msg = f"simbridge did not start: {line!r}"
            raise RuntimeError(msg)
        yield int(match.group(1)), psutil.Process(proc.pid)
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def health(port: int) -> dict[str, Any]:
    """Return the server's /healthz document."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=10) as r:
        result: dict[str, Any] = json.loads(r.read())
        return result


def memory(proc: psutil.Process) -> tuple[float, int]:
    """Return the RSS (MiB) and the number of open file descriptors of ``proc``."""
    return proc.memory_info().rss / 2**20, proc.num_fds()


async def stalled_client(port: int, subscribe: dict[str, Any]) -> socket.socket:
    """Open a WebSocket by hand with a tiny receive buffer, subscribe, and never read again."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.setblocking(False)
    loop = asyncio.get_running_loop()
    await loop.sock_connect(sock, ("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    await loop.sock_sendall(
        sock,
        (
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n"
        ).encode(),
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += await loop.sock_recv(sock, 1)
    payload = json.dumps(subscribe).encode()
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    await loop.sock_sendall(sock, bytes([0x81, 0x80 | len(payload)]) + mask + masked)
    return sock


def percentile(values: list[float], q: float) -> float:
    """Return the ``q`` quantile (0..1) of ``values``."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def now() -> float:
    """Monotonic seconds."""
    return time.monotonic()
