"""The observer of ``bench hostile``: a well-behaved client in a process of its own.

``python -m bench.odomwatch URL`` subscribes to ``/r1/odom`` (the rate a student sees) and to
``/rosout`` (the safety watchdog's stops), and every ``PROBE_PERIOD`` seconds sends one
``/r2/cmd_vel`` and then nothing, so the watchdog must stop r2. On SIGTERM it prints, as one
JSON line: each /r1/odom as ``[arrival, stamp]`` (wall seconds), each probe as ``[sent,
first /r2/odom stamp after it]`` and each watchdog stop of r2 as its ``/rosout`` stamp. Being a
separate process, an attacker's work in the bench process cannot delay what it measures.
"""

from __future__ import annotations

import asyncio
import json
import signal
import sys
import time
from typing import Any

from websockets.asyncio.client import connect


PROBE_PERIOD = 2.0
TWIST = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


def _stamp(value: Any) -> float:
    return float(value["sec"]) + float(value["nanosec"]) * 1e-9


async def watch(url: str) -> dict[str, list[Any]]:
    odom: list[list[float]] = []
    probes: list[list[float]] = []
    stops: list[float] = []
    waiting: list[float] = []  # probes sent whose command no /r2/odom has shown yet
    done = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, done.set)
    async with connect(url, max_size=None, open_timeout=30) as ws:
        for topic in ("/r1/odom", "/r2/odom", "/rosout"):
            await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
        await ws.send(
            json.dumps({"op": "advertise", "topic": "/r2/cmd_vel", "type": "geometry_msgs/Twist"})
        )
        print("ready", flush=True)

        async def probe() -> None:
            while True:
                await asyncio.sleep(PROBE_PERIOD)
                waiting.append(time.time())
                msg = {"op": "publish", "topic": "/r2/cmd_vel", "msg": TWIST}
                await ws.send(json.dumps(msg))

        async def receive() -> None:
            async for data in ws:
                msg = json.loads(data)
                topic = msg.get("topic")
                if topic == "/r1/odom":
                    odom.append([time.time(), _stamp(msg["msg"]["header"]["stamp"])])
                elif topic == "/r2/odom" and waiting:
                    stamp = _stamp(msg["msg"]["header"]["stamp"])
                    if stamp > waiting[0]:
                        probes.append([waiting.pop(0), stamp])
                elif topic == "/rosout" and "safety: stopped r2" in msg["msg"]["msg"]:
                    stops.append(_stamp(msg["msg"]["stamp"]))

        tasks = [asyncio.create_task(probe()), asyncio.create_task(receive())]
        await done.wait()
        for task in tasks:
            task.cancel()
    return {"odom": odom, "probes": probes, "stops": stops}


def main() -> None:
    result = asyncio.run(watch(sys.argv[1]))
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
