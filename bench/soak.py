"""A soak with churn: a real simbridge process under connecting, leaving, stalling clients.

For ``SOAK_SECONDS`` (default 600): five steady clients watch /odom (their rate is checked every
10 s window); every 50 ms a client connects, subscribes /odom and /scan, advertises a topic and a
service, publishes /cmd_vel and leaves (half of them cleanly, half by dropping the TCP
connection); every 5 s a client subscribes /scan and never reads (evicted by --stall-timeout 5);
every second a few malformed frames arrive. The server's RSS and open file descriptors are taken
after a 30 s warm-up and again at the end, once every churn client is gone.
"""

from __future__ import annotations

import asyncio
import json
import os
import random

from websockets.asyncio.client import connect

from bench._server import health, memory, now, server
from tests.helpers import stalled_client


SECONDS = float(os.environ.get("SOAK_SECONDS", "600"))
HOSTILE = [b"\xff\xfe", "{oops", '{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":NaN}}}']


async def _watch(url: str, counts: list[int], stop: asyncio.Event) -> None:
    async with connect(url) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        while not stop.is_set():
            try:
                await asyncio.wait_for(ws.recv(), 1.0)
            except TimeoutError:
                continue
            counts[0] += 1


async def _churn_one(url: str, k: int) -> None:
    async with connect(url) as ws:
        for op in (
            {"op": "subscribe", "topic": "/odom"},
            {"op": "subscribe", "topic": "/scan"},
            {"op": "advertise", "topic": f"/churn_{k}", "type": "std_msgs/String"},
            {"op": "advertise_service", "service": f"/churn_srv_{k}", "type": "std_srvs/Trigger"},
            {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.0}}},
        ):
            await ws.send(json.dumps(op))
        await ws.recv()
        if k % 2:
            ws.transport.abort()  # abrupt: no close handshake


async def soak() -> int:
    with server("--stall-timeout", "5", "--max-clients", "500") as (port, proc):
        url = f"ws://127.0.0.1:{port}"
        stop = asyncio.Event()
        counts = [[0] for _ in range(5)]
        watchers = [asyncio.create_task(_watch(url, c, stop)) for c in counts]
        rng = random.Random(7)
        start = now()
        rss0 = fds0 = None
        windows: list[float] = []
        last_window, last_total = start, 0
        churned = stalled = hostile = errors = 0
        tasks: set[asyncio.Task[None]] = set()
        socks = []
        tick = 0
        while now() - start < SECONDS:
            tick += 1
            task = asyncio.create_task(_churn_one(url, tick))
            tasks.add(task)
            task.add_done_callback(tasks.discard)
            churned += 1
            if tick % 100 == 0:
                socks.append(await stalled_client(port, {"op": "subscribe", "topic": "/scan"}))
                stalled += 1
            if tick % 20 == 0:
                async with connect(url) as bad:
                    for frame in HOSTILE:
                        await bad.send(frame)
                        hostile += 1
                    await bad.send(rng.randbytes(64))
                    hostile += 1
            if rss0 is None and now() - start > min(30.0, SECONDS / 4):
                rss0, fds0 = memory(proc)
            if now() - last_window >= 10:
                total = sum(c[0] for c in counts)
                windows.append((total - last_total) / 5 / (now() - last_window))
                last_window, last_total = now(), total
            await asyncio.sleep(0.05)
        await asyncio.gather(*tasks, return_exceptions=True)
        for task in list(tasks):
            if task.exception() is not None:
                errors += 1
        stop.set()
        await asyncio.gather(*watchers)
        for sock in socks:
            sock.close()
        await asyncio.sleep(3)
        doc = health(port)
        rss1, fds1 = memory(proc)
        assert rss0 is not None and fds0 is not None
        print(f"soak: {SECONDS:.0f} s with churn against a real simbridge process")
        print(
            f"  churn clients {churned} (half abrupt), stalled {stalled}, hostile frames {hostile}"
        )
        print(
            f"  server: connections_total {doc['connections_total']}, clients now "
            f"{doc['clients']}, stalled evicted {doc.get('stalled_total')}"
        )
        print(
            f"  RSS after 30 s warm-up {rss0:.1f} MiB -> end {rss1:.1f} MiB "
            f"(drift {rss1 - rss0:+.1f} MiB)"
        )
        print(f"  open fds after warm-up {fds0} -> end {fds1}")
        print(
            f"  steady /odom rate per 10 s window: min {min(windows):.1f} Hz, "
            f"max {max(windows):.1f} Hz over {len(windows)} windows"
        )
        loop = doc["loop"]
        print(
            f"  loop: ticks {loop['ticks']}, late {loop['late_ticks']}, skipped "
            f"{loop['skipped_ticks']}, lateness p99 {loop['lateness_ms_p99']} ms"
        )
        return 0


def main() -> int:
    """Run the soak."""
    return asyncio.run(soak())


if __name__ == "__main__":
    raise SystemExit(main())
