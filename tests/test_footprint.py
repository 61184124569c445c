"""The default server's idle footprint: what it imports, and its resident memory (issue 16).

A Raspberry Pi 4B runs simbridge all day next to other things; what an idle server holds is what
``simbridge`` with no options (the default world and parameters, the page on its HTTP port)
imports and builds. The server runs in a child process; a thread in it waits until the WebSocket
port answers and the resident set has settled, reports ``sys.modules`` and VmRSS, and stops the
server with SIGINT (the normal shutdown).

Where the memory goes (x86-64, CPython 3.11, measured with ``python -X importtime`` and RSS after
each import): the interpreter 8.7 MB; asyncio 10.7 MB (ssl and libcrypto included); numpy
17.8 MB plus numpy.random 2.4; pydantic 5.5 MB plus the settings models 3 MB; rosbags' ROS 2 type
store and simbridge's registry 7.4 MB (2.9 of it the service/action interfaces, now generated on
the first lookup that needs one); websockets 2 MB. The issue's 40 MB target is below what
numpy, asyncio and the interpreter take together (37 MB), so the ceiling here guards the level
reached (see docs/deploy.md) against regressions: a module that a run does not use, imported on
the default path, fails :func:`test_default_server_imports_nothing_it_does_not_use` by name.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from typing import Any

import pytest

from tests.helpers import ROOT, TIMEOUT_FACTOR


#: Idle RSS ceiling of the default server, MB. The same commit measures 55.8 MB in a long-used
#: development venv and 61.4-63.4 MB in a fresh clone's venv (CI's case; cause not found yet), so
#: the ceiling guards against gross regressions (62.2 MB was the level before issue 16, measured
#: in a development venv); the import test below guards the default path by name.
IDLE_RSS_CEILING_MB = 66.0

#: Modules a default run has no use for: tools, bag writing, optional transports, test libraries.
NOT_ON_THE_DEFAULT_PATH = (
    "urllib.request",
    "http.client",
    "zenoh",
    "mcap",
    "rosbags.rosbag2",
    "simbridge.tools",
    "simbridge.record",
    "simbridge.bag",
    "simbridge.compare",
    "simbridge.rostool",
    "psutil",
    "playwright",
)

PROBE = r"""
import json, os, signal, socket, sys, threading, time

port = int(sys.argv[1])


def rss_mb():
    with open("/proc/self/status") as status:
        return next(int(ln.split()[1]) for ln in status if ln.startswith("VmRSS")) / 1024


def watch():
    deadline = time.monotonic() + float(sys.argv[3])
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            if time.monotonic() > deadline:
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.05)
    # settled: two readings 0.5 s apart within 0.1 MB (the loop's first ticks allocate a little)
    last = rss_mb()
    while time.monotonic() < deadline:
        time.sleep(0.5)
        now = rss_mb()
        if abs(now - last) < 0.1:
            break
        last = now
    print(json.dumps({"rss_mb": rss_mb(), "modules": sorted(sys.modules)}), file=sys.stderr)
    os.kill(os.getpid(), signal.SIGINT)


threading.Thread(target=watch, daemon=True).start()
from simbridge.cli import main

sys.exit(main(["--host", "127.0.0.1", "--port", str(port), "--http-port", sys.argv[2]]))
"""


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="module")
def idle_server() -> dict[str, Any]:
    """Run the default server until it is idle; return its RSS (MB) and its modules."""
    timeout = 60 * TIMEOUT_FACTOR
    proc = subprocess.run(
        [sys.executable, "-c", PROBE, str(free_port()), str(free_port()), str(timeout)],
        capture_output=True,
        text=True,
        timeout=timeout + 30,
        cwd=ROOT,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = next(ln for ln in proc.stderr.splitlines() if ln.startswith('{"rss_mb"'))
    result: dict[str, Any] = json.loads(report)
    return result


def test_default_server_imports_nothing_it_does_not_use(idle_server: dict[str, Any]) -> None:
    """No tool, bag writer, optional transport or HTTP client module on the default path."""
    loaded = [m for m in idle_server["modules"] if m.startswith(NOT_ON_THE_DEFAULT_PATH)]
    assert loaded == []


def test_default_server_idle_rss_stays_under_the_ceiling(idle_server: dict[str, Any]) -> None:
    """The default server, idle (no client), holds at most IDLE_RSS_CEILING_MB resident."""
    rss = float(idle_server["rss_mb"])
    assert rss <= IDLE_RSS_CEILING_MB, f"idle RSS {rss:.1f} MB > {IDLE_RSS_CEILING_MB} MB"
