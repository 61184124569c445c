"""A load-generator process: many rosbridge WebSocket clients on one asyncio loop.

    python -m bench.loadgen SPEC_JSON      (prints one JSON line of results on stdout)

SPEC: ``{"url", "clients": [{"subscribe": [topics], "drive": topic or null}], "start", "end"}``
with ``start``/``end`` wall-clock seconds (``time.time()``): only messages stamped inside the
window are counted. Each client subscribes (``queue_length`` 0: the server's default bound)
and, if ``drive`` is set, publishes a Twist on it at 10 Hz (a slowly turning command).

Latency is receive time minus the message's ``header.stamp`` (wall clock of the same host, set
by the server when it publishes). The stamp is read with a regular expression from the head of
the frame, so a client's cost per message stays small and the clients keep up. Per client and
topic the result lists the stamps received (as integer nanoseconds), so the caller can find
losses by comparing clients with each other.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import sys
import time
from typing import Any

from websockets.asyncio.client import connect


_TOPIC = re.compile(rb'"topic":\s*"([^"]+)"')
_STAMP = re.compile(rb'"stamp":\s*\{\s*"sec":\s*(\d+),\s*"nanosec":\s*(\d+)')


async def _client(
    url: str, spec: dict[str, Any], start: float, end: float, out: dict[str, Any]
) -> None:
    stamps: dict[str, list[int]] = {t: [] for t in spec["subscribe"]}
    arrivals: dict[str, list[float]] = {t: [] for t in spec["subscribe"]}
    latencies: list[float] = []
    out.update(stamps=stamps, arrivals=arrivals, latencies=latencies, error=None)
    async with connect(url, max_size=None, compression=None, ping_interval=None) as ws:
        for topic in spec["subscribe"]:
            await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
        drive = spec.get("drive")
        driver = None
        if drive:
            await ws.send(
                json.dumps({"op": "advertise", "topic": drive, "type": "geometry_msgs/msg/Twist"})
            )

            async def drive_loop() -> None:
                k = 0
                t0 = time.monotonic()
                while True:
                    k += 1
                    w = 0.8 * math.sin(k / 15.0)
                    msg = {
                        "linear": {"x": 0.2, "y": 0, "z": 0},
                        "angular": {"x": 0, "y": 0, "z": w},
                    }
                    await ws.send(json.dumps({"op": "publish", "topic": drive, "msg": msg}))
                    await asyncio.sleep(max(0.0, t0 + k * 0.1 - time.monotonic()))

            driver = asyncio.create_task(drive_loop())
        try:
            while True:
                remaining = end + 1.0 - time.time()
                if remaining <= 0:
                    break
                try:
                    data = await asyncio.wait_for(ws.recv(), remaining)
                except TimeoutError:
                    break
                now = time.time()
                raw = data.encode() if isinstance(data, str) else data
                head = raw[:400]
                m = _STAMP.search(head)
                t = _TOPIC.search(head)
                if m is None or t is None:
                    continue
                stamp_ns = int(m.group(1)) * 1_000_000_000 + int(m.group(2))
                if not (start <= stamp_ns / 1e9 < end):
                    continue
                topic = t.group(1).decode()
                if topic in stamps:
                    stamps[topic].append(stamp_ns)
                    arrivals[topic].append(now)
                latencies.append(now - stamp_ns / 1e9)
        finally:
            if driver is not None:
                driver.cancel()


async def _main(spec: dict[str, Any]) -> list[dict[str, Any]]:
    results: list[dict[str, Any]] = [{} for _ in spec["clients"]]

    async def one(i: int, c: dict[str, Any]) -> None:
        try:
            await _client(spec["url"], c, spec["start"], spec["end"], results[i])
        except Exception as err:  # reported, not raised: the other clients carry on
            results[i]["error"] = f"{type(err).__name__}: {err}"

    await asyncio.gather(*(one(i, c) for i, c in enumerate(spec["clients"])))
    return results


def main() -> None:
    spec = json.loads(sys.argv[1])
    results = asyncio.run(_main(spec))
    sys.stdout.write(json.dumps(results) + "\n")


if __name__ == "__main__":
    main()
