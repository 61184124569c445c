"""RSS drift over 1,000 connect / subscribe / disconnect cycles against a real simbridge process.

Each cycle opens a WebSocket, subscribes /odom and /scan, advertises a topic and a service,
waits for the first /odom and disconnects (odd cycles cleanly, even ones by dropping the TCP
connection). The server's RSS and open file descriptors are read after 100 warm-up cycles and
after the 1,000th, once the server has seen every client leave.
"""

from __future__ import annotations

import asyncio
import json

from websockets.asyncio.client import connect

from bench._server import health, memory, server


CYCLES = 1000
WARMUP = 100


async def _cycle(url: str, k: int) -> None:
    async with connect(url) as ws:
        for op in (
            {"op": "subscribe", "topic": "/odom"},
            {"op": "subscribe", "topic": "/scan"},
            {"op": "advertise", "topic": f"/c{k}", "type": "std_msgs/String"},
            {"op": "advertise_service", "service": f"/s{k}", "type": "std_srvs/Trigger"},
        ):
            await ws.send(json.dumps(op))
        while '"/odom"' not in str(await ws.recv()):
            pass
        if k % 2 == 0:
            ws.transport.abort()


async def _settle(port: int) -> None:
    for _ in range(100):
        if health(port)["clients"] == 0:
            return
        await asyncio.sleep(0.05)


async def churn() -> int:
    with server() as (port, proc):
        url = f"ws://127.0.0.1:{port}"
        rss = {}
        for k in range(1, CYCLES + 1):
            await _cycle(url, k)
            if k in (WARMUP, CYCLES):
                await _settle(port)
                rss[k] = memory(proc)
        doc = health(port)
        (r0, f0), (r1, f1) = rss[WARMUP], rss[CYCLES]
        print(f"churn: {CYCLES} connect/subscribe/advertise/disconnect cycles (half abrupt)")
        print(
            f"  RSS after {WARMUP} cycles {r0:.1f} MiB -> after {CYCLES} {r1:.1f} MiB: "
            f"drift {r1 - r0:+.2f} MiB over {CYCLES - WARMUP} cycles "
            f"({(r1 - r0) * 1024 / (CYCLES - WARMUP):+.2f} KiB/cycle)"
        )
        print(
            f"  open fds {f0} -> {f1}; server clients now {doc['clients']}, "
            f"connections_total {doc['connections_total']}"
        )
        return 0


def main() -> int:
    """Run the churn benchmark."""
    return asyncio.run(churn())


if __name__ == "__main__":
    raise SystemExit(main())
