"""The Foxglove port against rosbridge: N clients on /odom (20 Hz) + /scan (10 Hz) each way.

One simbridge process per row, started with ``--foxglove-port`` for both kinds of row (the same
server; only the clients change): N rosbridge clients (JSON, ``bench/loadgen.py``) or N Foxglove
WebSocket clients (``foxglove.sdk.v1``, CDR; the same load generator's
``_FoxgloveClient``), two load-generator processes, the two kinds alternated. For each: server
CPU (its own user + system seconds per second: the SDK's Rust threads count too), latency
(arrival minus the header stamp), bytes per second all clients read, and losses (a message one
client got must reach every client). Then one more Foxglove row with 5 more Foxglove clients
that subscribe and stop reading (their receive buffers made small): the others' p99 and losses.
Then the idle server's RSS without and with ``--foxglove-port`` (the extra installed both
times: without the option nothing of it loads).

``python -m bench.foxglove [SECONDS [N [ROUNDS]]]`` (default 10 s, 100 clients, 2 rounds).
Target (issue 30): Foxglove clients cost no more server CPU than rosbridge clients.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import psutil
from websockets.asyncio.client import connect
from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.typing import Subprotocol
from websockets.uri import parse_uri

from bench.procs import (
    ROOT,
    collect,
    cpu_seconds,
    free_port,
    load_average,
    losses,
    percentile,
    stop,
    wait_listening,
)


TOPICS = ["/odom", "/scan"]


def _wait_foxglove(port: int, timeout: float = 20.0) -> None:
    """Wait until the Foxglove port completes a handshake (``foxglove.sdk.v1``)."""

    async def probe() -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                protocols = [Subprotocol("foxglove.sdk.v1")]
                async with connect(f"ws://127.0.0.1:{port}", subprotocols=protocols):
                    return
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.1)

    asyncio.run(probe())


@contextlib.contextmanager
def server(*, foxglove: bool = True) -> Iterator[tuple[psutil.Process, int, int]]:
    """Run simbridge (with ``--foxglove-port`` unless told not to); yield (process, ports)."""
    port, fox = free_port(), free_port()
    cmd = [sys.executable, "-m", "simbridge", "--host", "127.0.0.1", "--port", str(port)]
    cmd += ["--no-http", "--log-level", "warning", "--max-clients", "2000"]
    if foxglove:
        cmd += ["--foxglove-port", str(fox)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL)
    try:
        wait_listening(port)
        if foxglove:
            _wait_foxglove(fox)
        yield psutil.Process(proc.pid), port, fox
    finally:
        stop(proc)


def _loadgens(
    url: str, protocol: str, n: int, start: float, end: float
) -> list[subprocess.Popen[str]]:
    clients = [{"subscribe": TOPICS} for _ in range(n)]
    procs = []
    for k in range(2):
        spec = {"url": url, "clients": clients[k::2], "start": start, "end": end}
        if protocol == "foxglove":
            spec["protocol"] = "foxglove"
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "bench.loadgen", json.dumps(spec)],
                cwd=ROOT,
                stdout=subprocess.PIPE,
                text=True,
            )
        )
    return procs


def stalled_client(port: int) -> socket.socket:
    """Open a Foxglove client that subscribes to /odom and /scan, then never reads again.

    Its receive buffer is made small, so that the server's side of it fills within seconds.
    """
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    ws = ClientProtocol(
        parse_uri(f"ws://127.0.0.1:{port}"),
        subprotocols=[Subprotocol("foxglove.sdk.v1")],
        max_size=None,
    )
    ws.send_request(ws.connect())
    for chunk in ws.data_to_send():
        sock.sendall(chunk)
    channels: list[dict[str, Any]] = []
    while not channels:
        ws.receive_data(sock.recv(65536))
        for event in ws.events_received():
            if isinstance(event, Frame) and event.opcode is Opcode.TEXT:
                body = json.loads(event.data)
                if body.get("op") == "advertise":
                    channels = [c for c in body["channels"] if c["topic"] in TOPICS]
    subs = [{"id": k + 1, "channelId": c["id"]} for k, c in enumerate(channels)]
    ws.send_text(json.dumps({"op": "subscribe", "subscriptions": subs}).encode())
    for chunk in ws.data_to_send():
        sock.sendall(chunk)
    return sock  # never read from again


def phase(kind: str, n: int, seconds: float, stalled: int = 0) -> dict[str, Any]:
    """Run ``n`` clients of ``kind`` (``rosbridge`` or ``foxglove``) for ``seconds``.

    ``stalled``: Foxglove clients that subscribe and then stop reading, opened first.
    """
    with server() as (proc, port, fox), contextlib.ExitStack() as stack:
        for _ in range(stalled):
            stack.enter_context(stalled_client(fox))
        url = f"ws://127.0.0.1:{fox if kind == 'foxglove' else port}"
        start = time.time() + 3.0 + n / 60.0
        end = start + seconds
        procs = _loadgens(url, kind, n, start, end)
        time.sleep(max(0.0, start - time.time()))
        cpu0 = cpu_seconds(proc)
        time.sleep(max(0.0, end - time.time()))
        cpu1 = cpu_seconds(proc)
        rss = proc.memory_info().rss
        load = load_average()
        results = collect(procs, timeout=seconds + 60)
    latencies = [x for r in results for x in r.get("latencies", [])]
    expected, missing, errors = losses(results, TOPICS)
    return {
        "kind": kind + (f"+{stalled} stalled" if stalled else ""),
        "n": n,
        "cpu": (cpu1 - cpu0) / seconds,
        "p50": percentile(latencies, 0.5) * 1e3,
        "p99": percentile(latencies, 0.99) * 1e3,
        "bytes": sum(r.get("bytes", 0) for r in results) / seconds,
        "received": len(latencies),
        "expected": expected,
        "missing": missing,
        "errors": errors,
        "rss_mb": rss / 1e6,
        "load": load,
    }


def idle_rss(*, foxglove: bool, settle: float = 4.0) -> float:
    """Return the RSS (MB) of an idle server ``settle`` seconds after it listens."""
    with server(foxglove=foxglove) as (proc, _port, _fox):
        time.sleep(settle)
        return float(proc.memory_info().rss) / 1e6


HEADER = (
    f"{'clients':<20} {'N':>4} {'CPU':>7} {'p50 ms':>7} {'p99 ms':>7} {'kB/s':>8} "
    f"{'received':>8} {'missing':>7} {'errors':>6} {'RSS MB':>6}"
)


def row(r: dict[str, Any]) -> str:
    return (
        f"{r['kind']:<20} {r['n']:>4} {r['cpu'] * 100:>6.1f}% {r['p50']:>7.2f} {r['p99']:>7.2f} "
        f"{r['bytes'] / 1e3:>8.0f} {r['received']:>8} {r['missing']:>7} {r['errors']:>6} "
        f"{r['rss_mb']:>6.0f}  {r['load']}"
    )


def main(argv: list[str] | None = None) -> int:
    args = list(argv or [])
    seconds = float(args[0]) if args else 10.0
    n = int(args[1]) if len(args) > 1 else 100
    rounds = int(args[2]) if len(args) > 2 else 2
    print(f"foxglove: {n} clients on /odom + /scan, {seconds:g} s measured per row")
    print(HEADER)
    runs: dict[str, list[dict[str, Any]]] = {"rosbridge": [], "foxglove": []}
    for k in range(rounds):
        order = ["rosbridge", "foxglove"] if k % 2 == 0 else ["foxglove", "rosbridge"]
        for kind in order:
            r = phase(kind, n, seconds)
            runs[kind].append(r)
            print(row(r), flush=True)
    print("medians of the rounds; ratio = Foxglove / rosbridge (below 1: Foxglove costs less)")
    for key, unit, scale in (
        ("cpu", "% CPU", 100.0),
        ("p50", "ms p50", 1.0),
        ("p99", "ms p99", 1.0),
        ("bytes", "kB/s", 1e-3),
    ):
        ros = statistics.median(r[key] for r in runs["rosbridge"]) * scale
        fox = statistics.median(r[key] for r in runs["foxglove"]) * scale
        print(f"  {unit:<7} rosbridge {ros:>9.2f}  foxglove {fox:>9.2f}  ratio {fox / ros:.2f}x")
    stall = phase("foxglove", n, seconds, stalled=5)
    print(row(stall), flush=True)
    healthy = statistics.median(r["p99"] for r in runs["foxglove"])
    print(
        f"  with 5 Foxglove clients that stopped reading: p99 {stall['p99']:.2f} ms of the "
        f"{n} others ({healthy:.2f} ms without), {stall['missing']} messages missing"
    )
    without, with_port = idle_rss(foxglove=False), idle_rss(foxglove=True)
    print(
        f"idle RSS: {without:.1f} MB without --foxglove-port, {with_port:.1f} MB with it "
        f"(+{with_port - without:.1f} MB)"
    )
    cpu_ratio = statistics.median(r["cpu"] for r in runs["foxglove"]) / statistics.median(
        r["cpu"] for r in runs["rosbridge"]
    )
    lost = sum(r["missing"] + r["errors"] for r in runs["foxglove"])
    ok = cpu_ratio <= 1.0
    print(
        f"target: Foxglove clients cost no more server CPU than rosbridge clients: "
        f"{'PASS' if ok else 'MISS'} ({cpu_ratio:.2f}x); Foxglove clients lost {lost} messages"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
