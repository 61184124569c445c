"""What the ROS 2 benchmarks (``bench.zenoh``, ``bench.dds``) measure alike.

* the server's CPU (its own user + system seconds over the window's wall seconds) while one
  rosbridge client subscribes to a robot world's topics, against the same while one ROS 2
  subscriber (another process, of either transport) takes them: :func:`compare_outward`, in
  rounds that alternate which goes first (a drift of the machine's load falls on both alike),
  printed with the median of the rounds' ratios by :func:`report_outward`;
* ``/odom`` latency (arrival minus the header stamp, the wall clock when the server published
  it) of a rosbridge client (:func:`rosbridge_latencies`), printed beside others by
  :func:`print_latencies`.

A ROS 2 subscriber process prints ``start`` once it counts (matched, or its subscribers
declared), then one JSON line, ``{"messages": N}`` (and ``"latencies"`` when asked), when done.
"""

from __future__ import annotations

import asyncio
import json
import statistics
import subprocess
import time
from collections.abc import Callable
from typing import Any

import psutil
from websockets.asyncio.client import connect

from bench.procs import cpu_seconds, load_average, percentile


#: One side of a round: the server's CPU share while it ran, and the messages it counted.
Share = tuple[float, int]


def robot_topics(robots: int, prefix: str = "r") -> list[tuple[str, str]]:
    """Return every robot's /odom and /scan of a world of ``robots`` robots, and /tf."""
    topics = [(f"/{prefix}{k + 1}/odom", "nav_msgs/msg/Odometry") for k in range(robots)]
    topics += [(f"/{prefix}{k + 1}/scan", "sensor_msgs/msg/LaserScan") for k in range(robots)]
    topics.append(("/tf", "tf2_msgs/msg/TFMessage"))
    return topics


def cpu_share(proc: psutil.Process, seconds: float) -> float:
    """Return the server's CPU share over the next ``seconds`` (whatever it does meanwhile)."""
    t0, c0 = time.monotonic(), cpu_seconds(proc)
    time.sleep(seconds)
    return (cpu_seconds(proc) - c0) / (time.monotonic() - t0)


async def _rosbridge_share(
    proc: psutil.Process, port: int, topics: list[tuple[str, str]], seconds: float
) -> Share:
    count = 0
    async with connect(f"ws://127.0.0.1:{port}", max_size=None) as ws:
        for name, _ in topics:
            await ws.send(json.dumps({"op": "subscribe", "topic": name}))
        warm = time.monotonic() + 2
        while time.monotonic() < warm:  # read, as the ROS 2 subscriber does: no backlog counted
            await ws.recv()
        t0, c0 = time.monotonic(), cpu_seconds(proc)
        end = t0 + seconds
        while time.monotonic() < end:
            await ws.recv()
            count += 1
        share = (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
    return share, count


def _subscriber_share(proc: psutil.Process, sub: subprocess.Popen[str]) -> Share:
    assert sub.stdout is not None
    sub.stdout.readline()  # "start": it counts from now on
    t0, c0 = time.monotonic(), cpu_seconds(proc)
    line = sub.stdout.readline()
    share = (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
    sub.wait(timeout=30)
    return share, int(json.loads(line)["messages"])


def compare_outward(
    proc: psutil.Process,
    port: int,
    topics: list[tuple[str, str]],
    seconds: float,
    rounds: int,
    subscriber: Callable[[], subprocess.Popen[str]],
) -> list[tuple[Share, Share]]:
    """Return ``rounds`` pairs (rosbridge client, ROS 2 subscriber) of the server's CPU.

    ``subscriber()`` starts the ROS 2 subscriber process of one round (``seconds`` long).
    """
    results: list[tuple[Share, Share]] = []
    for k in range(rounds):
        if k % 2 == 0:
            first = asyncio.run(_rosbridge_share(proc, port, topics, seconds))
            time.sleep(2)
            results.append((first, _subscriber_share(proc, subscriber())))
        else:
            second = _subscriber_share(proc, subscriber())
            time.sleep(2)
            results.append((asyncio.run(_rosbridge_share(proc, port, topics, seconds)), second))
        time.sleep(2)
    return results


def report_outward(
    title: str, idle: float, results: list[tuple[Share, Share]], *, label: str, target: float
) -> bool:
    """Print the rounds and the median ratio (``label``'s CPU over rosbridge's); met or not."""
    ratios = [ros2[0] / max(rb[0], 1e-9) for rb, ros2 in results]
    print(f"{title}, {load_average()}")
    print(f"nobody subscribed: server CPU {100 * idle:.1f} %")
    column = f"{label} CPU %"
    width = len(column) + 2
    print(
        f"{'round':7}{'rosbridge CPU %':>16}{'messages':>10}{column:>{width}}{'messages':>10}"
        f"{'ratio':>8}"
    )
    for k, ((rb, rb_count), (ros2, ros2_count)) in enumerate(results):
        print(
            f"{k + 1:<7}{100 * rb:>16.1f}{rb_count:>10}{100 * ros2:>{width}.1f}{ros2_count:>10}"
            f"{ratios[k]:>7.2f}x"
        )
    ratio = statistics.median(ratios)
    ok = ratio <= target
    print(
        f"{label} / rosbridge server CPU, median of {len(results)} rounds: {ratio:.2f}x"
        f" (rounds {min(ratios):.2f}-{max(ratios):.2f}x); target <= {target:.1f}x: "
        f"{'met' if ok else 'NOT met'}"
    )
    return ok


async def rosbridge_latencies(
    port: int, topic: str, seconds: float, out: list[float], *, warmup: float = 0.0
) -> None:
    """Append the latency of each ``topic`` message a rosbridge client gets to ``out``.

    For ``seconds`` after ``warmup`` seconds (whose messages are not counted).
    """
    async with connect(f"ws://127.0.0.1:{port}", max_size=None) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
        end = time.monotonic() + warmup + seconds
        while time.monotonic() < end:
            try:
                raw = await asyncio.wait_for(ws.recv(), 2)
            except TimeoutError:
                continue
            msg: dict[str, Any] = json.loads(raw)
            if msg.get("topic") != topic or time.monotonic() < end - seconds:
                continue
            stamp = msg["msg"]["header"]["stamp"]
            out.append(time.time() - (stamp["sec"] + stamp["nanosec"] * 1e-9))


def print_latencies(rows: list[tuple[str, list[float]]], width: int = 28) -> None:
    """Print messages, p50 and p99 (ms) of each row's latencies."""
    print(f"{'':{width}}{'messages':>10}{'p50 ms':>10}{'p99 ms':>10}")
    for label, values in rows:
        p50, p99 = percentile(values, 0.5) * 1e3, percentile(values, 0.99) * 1e3
        print(f"{label:{width}}{len(values):>10}{p50:>10.2f}{p99:>10.2f}")
