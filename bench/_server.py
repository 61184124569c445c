"""A real simbridge process for the reliability benchmarks, and raw-socket client helpers."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import psutil

from bench.procs import stop


@contextmanager
def server(*options: str) -> Iterator[tuple[int, psutil.Process]]:
    """Run ``simbridge --host 127.0.0.1 --port 0 --no-http OPTIONS``; yield its port and process."""
    with _run("--no-http", *options) as (port, _http, proc):
        yield port, proc


@contextmanager
def http_server(*options: str) -> Iterator[tuple[int, int, psutil.Process]]:
    """Run ``simbridge --host 127.0.0.1 --port 0 --http-port 0 OPTIONS``; yield both ports."""
    with _run("--http-port", "0", *options) as (port, http, proc):
        assert http is not None, "the server did not open its HTTP port"
        yield port, http, proc


@contextmanager
def _run(*options: str) -> Iterator[tuple[int, int | None, psutil.Process]]:
    cmd = [sys.executable, "-m", "simbridge", "--host", "127.0.0.1", "--port", "0"]
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
        page = re.search(r"http://[^:]+:(\d+)/", line)
        yield int(match.group(1)), int(page.group(1)) if page else None, psutil.Process(proc.pid)
    finally:
        stop(proc)


def health(port: int) -> dict[str, Any]:
    """Return the server's /healthz document."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=10) as r:
        result: dict[str, Any] = json.loads(r.read())
        return result


def memory(proc: psutil.Process) -> tuple[float, int]:
    """Return the RSS (MiB) and the number of open file descriptors of ``proc``."""
    return proc.memory_info().rss / 2**20, proc.num_fds()


def now() -> float:
    """Monotonic seconds."""
    return time.monotonic()
