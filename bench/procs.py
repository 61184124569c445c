"""Processes of the network benchmarks: servers, load generators, CPU and memory readings.

Servers and load generators are separate processes (the clients never share the server's
interpreter or core time). CPU is read from the server process's own counters (user + system
seconds, ``psutil``), so other programs on a shared machine do not inflate it; latency, which
they can inflate, is reported with the load average seen during the run.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
from websockets.asyncio.client import connect


ROOT = Path(__file__).resolve().parent.parent


def tree_env(tree: Path) -> tuple[Path, dict[str, str]]:
    """The working directory and environment that run ``tree``'s simbridge with this Python.

    ``tree`` is a source checkout (e.g. a ``git worktree`` of an older commit, without a
    virtualenv of its own): first on ``PYTHONPATH`` and the working directory, so that its
    ``simbridge`` (and its ``bench``) shadow the one installed in this interpreter's venv.
    """
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [env.get("PYTHONPATH")])])
    return tree, env


def free_port() -> int:
    """Return a TCP port that is free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_listening(port: int, timeout: float = 20.0) -> None:
    """Wait until a WebSocket server accepts connections on ``port``."""

    async def probe() -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                async with connect(f"ws://127.0.0.1:{port}", open_timeout=2):
                    return
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.1)

    asyncio.run(probe())


@contextlib.contextmanager
def server(
    kind: str,
    *,
    world: Path | None = None,
    checkout: Path | None = None,
    tree: Path | None = None,
) -> Iterator[tuple[psutil.Process, int]]:
    """Run a server process: ``simbridge`` or ``broadcaster``; yield (process, port).

    ``checkout``: run simbridge as that checkout has it (its code and ``.venv``), e.g. the
    baseline of a before/after comparison. ``tree``: that source tree's simbridge with this
    interpreter (:func:`tree_env`).
    """
    port = free_port()
    python, cwd, env = sys.executable, ROOT, None
    if checkout is not None:
        python, cwd = str(checkout / ".venv" / "bin" / "python"), checkout
    if tree is not None and kind == "simbridge":
        cwd, env = tree_env(tree)
    if kind == "simbridge":
        cmd = [python, "-m", "simbridge", "--host", "127.0.0.1", "--port", str(port)]
        # 500-client runs: above the default --max-clients (200) of a classroom server
        cmd += ["--no-http", "--log-level", "warning", "--max-clients", "2000"]
        if world is not None:
            cmd += ["--world", str(world)]
    else:
        cmd = [sys.executable, "-m", "bench.broadcaster", str(port)]
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL)
    try:
        wait_listening(port)
        yield psutil.Process(proc.pid), port
    finally:
        stop(proc)


def stop(proc: subprocess.Popen[Any]) -> None:
    """Terminate a server process; kill it if it has not exited within 10 s."""
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def cpu_seconds(proc: psutil.Process) -> float:
    """User + system CPU seconds the process has used so far."""
    t = proc.cpu_times()
    return float(t.user + t.system)


def start_loadgens(
    url: str, clients: list[dict[str, Any]], processes: int, start: float, end: float
) -> list[subprocess.Popen[str]]:
    """Start the load-generator processes, the clients dealt round-robin among them."""
    procs = []
    for k in range(processes):
        spec = {"url": url, "clients": clients[k::processes], "start": start, "end": end}
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "bench.loadgen", json.dumps(spec)],
                cwd=ROOT,
                stdout=subprocess.PIPE,
                text=True,
            )
        )
    return procs


def collect(procs: list[subprocess.Popen[str]], timeout: float) -> list[dict[str, Any]]:
    """Wait for the load generators; return every client's result."""
    results: list[dict[str, Any]] = []
    for p in procs:
        out, _ = p.communicate(timeout=timeout)
        results.extend(json.loads(out))
    return results


def load_average() -> str:
    """The 1-minute load average and the core count, for the record."""
    return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values`` (nearest rank); nan when empty."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def losses(results: list[dict[str, Any]], topics: list[str]) -> tuple[int, int, int]:
    """Return (messages expected, messages missing, clients with errors).

    A message was published if any client received it (its stamp); every client subscribed
    to the topic should have it.
    """
    expected = missing = 0
    for topic in topics:
        have = [set(r["stamps"].get(topic, [])) for r in results if topic in r.get("stamps", {})]
        union = set().union(*have) if have else set()
        for s in have:
            expected += len(union)
            missing += len(union - s)
    errors = sum(1 for r in results if r.get("error"))
    return expected, missing, errors
