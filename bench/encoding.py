"""Encoding a /scan and an /odom for N subscribers: simbridge vs stdlib json per subscriber.

simbridge encodes a published message once per encoding (orjson, numpy arrays natively) and
writes the same bytes to every subscriber. The baseline is what rosbridge_suite does: build the
JSON text of the publish message for each subscriber with the stdlib ``json.dumps`` (here from a
dict already holding plain lists, which favours the baseline: no message conversion counted).

Targets (issue 2): a /scan frame encoded in <= 15 us; >= 10x faster than the baseline at N = 10.
"""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from simbridge.app.config import Params, load_world
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.rosbridge import Outgoing
from simbridge.rosbridge.frames import publish_frame
from simbridge.sim import World


def _messages() -> dict[str, dict[str, Any]]:
    """Capture one real /scan and /odom as the bridge builds them."""
    graph = Graph()
    world = World(load_world(None), Params())
    bridge = RobotBridge(graph, world)
    captured: dict[str, Any] = {}
    for name in ("/scan", "/odom"):
        topic = graph.topics.topics[name]
        topic.internal.append(("bench", lambda msg, src, n=name: captured.setdefault(n, msg)))
    world.command("", 0.2, 0.1)
    world.step()
    bridge.publish(0.0)
    return captured


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def _time(
    fn: Callable[[], object],
    repeat: int = 7,
    min_time: float = 0.05,
    *,
    clock: Callable[[], float] = time.perf_counter,
    pick: Callable[[list[float]], float] = statistics.median,
) -> float:
    """Seconds per call (``pick`` of ``repeat`` batches of at least ``min_time`` each).

    ``clock``: wall time by default; ``time.thread_time`` counts this thread's CPU only.
    """
    n = 1
    while True:
        t0 = clock()
        for _ in range(n):
            fn()
        if clock() - t0 >= min_time:
            break
        n *= 2
    samples = []
    for _ in range(repeat):
        t0 = clock()
        for _ in range(n):
            fn()
        samples.append((clock() - t0) / n)
    return pick(samples)


def main() -> int:
    msgs = _messages()
    print("encoding: one publish frame per subscriber (median per message, microseconds)")
    print(
        f"{'topic':<7} {'N':>4} {'simbridge':>11} {'stdlib/sub':>11} {'speed-up':>9} {'bytes':>6}"
    )
    results: dict[tuple[str, int], tuple[float, float]] = {}
    for topic, msg in msgs.items():
        plain = _plain(msg)
        size = len(publish_frame(Outgoing(topic, None, msg), "none", topic).data)
        for n in (1, 10, 100):

            def ours(msg: Any = msg, topic: str = topic, n: int = n) -> None:
                out = Outgoing(topic, None, msg)
                for _ in range(n):
                    publish_frame(out, "none", topic)

            def baseline(plain: Any = plain, topic: str = topic, n: int = n) -> None:
                for _ in range(n):
                    json.dumps({"op": "publish", "topic": topic, "msg": plain})

            a, b = _time(ours), _time(baseline)
            results[(topic, n)] = (a, b)
            print(f"{topic:<7} {n:>4} {a * 1e6:>11.1f} {b * 1e6:>11.1f} {b / a:>8.1f}x {size:>6}")
    scan1 = results[("/scan", 1)][0] * 1e6
    a10, b10 = results[("/scan", 10)]
    ok1 = scan1 <= 15.0
    ok10 = b10 / a10 >= 10.0
    print(f"target: /scan frame <= 15 us: {'PASS' if ok1 else 'MISS'} ({scan1:.1f} us)")
    print(f"target: >= 10x the stdlib way at N=10: {'PASS' if ok10 else 'MISS'} ({b10 / a10:.1f}x)")
    return 0 if ok1 and ok10 else 1


if __name__ == "__main__":
    raise SystemExit(main())
