"""Latency of normal clients with and without stalled clients, against a real simbridge process.

A publisher sends a std_msgs/String carrying its send time on /lat at 50 Hz and a 100 kB
/blob at 10 Hz; ten normal clients subscribe /lat, /blob and /odom and read everything. The
latency is publish-to-receive of /lat at each normal client (all clients live in this process:
one clock). Phase "baseline": nobody stalls. Phase "stalled": three more clients subscribe /blob
(1 MB/s each) and never read a byte. Same load otherwise; each phase lasts PHASE seconds.
"""

from __future__ import annotations

import asyncio
import json
import os
import time

from websockets.asyncio.client import ClientConnection, connect

from bench._server import health, server
from bench.procs import percentile
from tests.helpers import stalled_client


PHASE = float(os.environ.get("STALL_PHASE_SECONDS", "20"))
NORMAL = 10


async def _reader(ws: ClientConnection, lat: list[float], stop: asyncio.Event) -> None:
    while not stop.is_set():
        try:
            data = await asyncio.wait_for(ws.recv(), 0.5)
        except TimeoutError:
            continue
        if isinstance(data, str) and data.startswith('{"op":"publish","topic":"/lat"'):
            sent = float(json.loads(data)["msg"]["data"])
            lat.append(time.perf_counter() - sent)


async def _phase(url: str, port: int, stalled: int) -> tuple[list[float], int]:
    stop = asyncio.Event()
    lat: list[float] = []
    clients = [await connect(url, max_size=None) for _ in range(NORMAL)]
    for ws in clients:
        for topic in ("/lat", "/blob", "/odom"):
            await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
    sub = {"op": "subscribe", "topic": "/blob", "type": "std_msgs/String"}
    socks = [await stalled_client(port, sub) for _ in range(stalled)]
    readers = [asyncio.create_task(_reader(ws, lat, stop)) for ws in clients]
    pub = await connect(url)
    for topic in ("/lat", "/blob"):
        await pub.send(json.dumps({"op": "advertise", "topic": topic, "type": "std_msgs/String"}))
    blob = "x" * 100_000
    await asyncio.sleep(1.0)
    lat.clear()
    start = time.perf_counter()
    k = 0
    while time.perf_counter() - start < PHASE:
        k += 1
        msg = {"data": repr(time.perf_counter())}
        await pub.send(json.dumps({"op": "publish", "topic": "/lat", "msg": msg}))
        if k % 5 == 0:
            await pub.send(json.dumps({"op": "publish", "topic": "/blob", "msg": {"data": blob}}))
        await asyncio.sleep(0.02)
    await asyncio.sleep(0.5)
    doc = health(port)
    stop.set()
    await asyncio.gather(*readers)
    for ws in [*clients, pub]:
        await ws.close()
    for sock in socks:
        sock.close()
    return lat, int(doc["dropped_frames"])


async def stall() -> int:
    with server("--stall-timeout", "1000") as (port, _proc):
        url = f"ws://127.0.0.1:{port}"
        base, _ = await _phase(url, port, 0)
        await asyncio.sleep(1.0)
        slow, dropped = await _phase(url, port, 3)
    print(f"stall: {NORMAL} normal clients, /lat at 50 Hz + 100 kB /blob at 10 Hz, {PHASE:.0f} s")
    print(f"  {'':<28}{'n':>7}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for name, lat in (("baseline (nobody stalls)", base), ("3 stalled clients", slow)):
        p50, p99 = percentile(lat, 0.5) * 1e3, percentile(lat, 0.99) * 1e3
        print(f"  {name:<28}{len(lat):>7}{p50:>9.2f}{p99:>9.2f}{max(lat) * 1e3:>9.2f}")
    ratio = percentile(slow, 0.99) / percentile(base, 0.99)
    print(
        f"  p99 ratio stalled/baseline: {ratio:.2f}; frames dropped for stalled clients: {dropped}"
    )
    return 0


def main() -> int:
    """Run the stalled-client latency benchmark."""
    return asyncio.run(stall())


if __name__ == "__main__":
    raise SystemExit(main())
