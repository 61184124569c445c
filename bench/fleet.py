"""Many robots in one process: how many run in real time on one core.

Each robot publishes ``/NAME/odom`` at 20 Hz and a 360-ray ``/NAME/scan`` at 10 Hz (shared
``/tf`` built every step too), and every one of those messages is built and JSON-encoded as for
a subscribed client: one sink peer (the seam where a socket would be; frames are counted and
dropped) subscribes to every robot's odom and scan. Robots wander (0.3 m/s, a new random turn
rate every second) in a square arena with 9 m^2 per robot and one 1 m box per 10 robots, so
scans see walls and other robots and robots collide.

The process is pinned to one CPU and costs are CPU time of this process (``process_time``:
other developers sharing the machine do not inflate it). "Real time" means the work of one
simulated second (20
ticks: step, collisions, raycasts, messages, encoding) takes under one second. Baseline: the
same world with the brute-force per-robot raycast (every ray against every wall, robots not
seen), the foundation's code path. Reports per-part cost and the largest real-time count.
Target (issue 6): 200 robots in real time; goal 1,000 (Stage's figure).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import time
from collections.abc import Hashable
from typing import Any

import numpy as np

from simbridge.app.config import Params, WorldSpec
from simbridge.graph import Graph
from simbridge.graph.access import Access
from simbridge.robot.bridge import RobotBridge
from simbridge.rosbridge import Frame
from simbridge.rosbridge.front import Rosbridge
from simbridge.sim import World, raycast


class SinkPeer:
    """A subscribed client that counts the frames and bytes it is sent."""

    def __init__(self, front: Rosbridge) -> None:
        self.session = front.new_session()
        self.label = "sink"
        self.frames = 0
        self.bytes = 0
        front.add_peer(self)

    @property
    def access(self) -> Access:
        return self.session.access

    def send(self, frame: Frame, key: Hashable | None = None, limit: int = 0) -> None:
        self.frames += 1
        self.bytes += len(frame.data)


def arena(n: int, seed: int = 0) -> tuple[World, Graph, RobotBridge, SinkPeer]:
    """Build an arena for ``n`` robots, all subscribed by one sink peer."""
    rng = np.random.default_rng(seed)
    half = math.sqrt(9.0 * n) / 2
    walls = [
        [-half, -half, half, -half],
        [half, -half, half, half],
        [half, half, -half, half],
        [-half, half, -half, -half],
    ]
    boxes = [
        {"center": rng.uniform(-half + 1, half - 1, 2).tolist(), "size": [1.0, 1.0]}
        for _ in range(max(1, n // 10))
    ]
    world = World(WorldSpec.parse({"walls": walls, "boxes": boxes, "robots": []}), Params())
    k = 0
    while len(world.robots) < n:
        x, y = rng.uniform(-half + 0.3, half - 0.3, 2)
        with contextlib.suppress(ValueError):
            world.spawn(f"r{k}", (float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
        k += 1
    graph = Graph()
    bridge = RobotBridge(graph, world)
    front = Rosbridge(graph)
    sink = SinkPeer(front)
    for name in world.robots:
        for topic in ("odom", "scan"):
            front.receive(sink, f'{{"op":"subscribe","topic":"/{name}/{topic}"}}', 0.0)
    return world, graph, bridge, sink


def run(n: int, seconds: float = 3.0, *, brute: bool = False) -> dict[str, Any]:
    """Simulate ``seconds`` with ``n`` robots; return the cost per simulated second."""
    world, graph, bridge, sink = arena(n)
    rng = np.random.default_rng(1)
    names = list(world.robots)
    if brute:
        angles = world.angles()

        def brute_scans(wanted: list[str]) -> Any:
            lidar = world.params.lidar
            out = []
            for name in wanted:
                x, y, yaw = world.laser_pose(name)
                r = raycast(x, y, yaw, angles, world.segments, lidar.range_max)
                out.append(np.clip(r, lidar.range_min, lidar.range_max).astype(np.float32))
            return np.array(out)

        world.scans = brute_scans  # type: ignore[method-assign]
    ticks = round(seconds * world.params.sim.rate)
    parts = {"step": 0.0, "publish": 0.0}
    scans_before = 0.0
    original_scans = world.scans

    def timed_scans(wanted: list[str]) -> Any:
        nonlocal scans_before
        t = time.process_time()
        out = original_scans(wanted)
        scans_before += time.process_time() - t
        return out

    world.scans = timed_scans  # type: ignore[method-assign]
    contacts = 0
    t_all = time.process_time()
    for k in range(ticks):
        if k % 20 == 0:
            for name in names:
                world.command(name, 0.3, float(rng.uniform(-1.0, 1.0)))
        t0 = time.process_time()
        world.step()
        t1 = time.process_time()
        bridge.publish(k * world.dt)
        graph.tick(k * world.dt)
        parts["step"] += t1 - t0
        parts["publish"] += time.process_time() - t1
        contacts += len(world.contacts)
    total = time.process_time() - t_all
    return {
        "n": n,
        "per_s": total / seconds,
        "step": parts["step"] / seconds,
        "scan": scans_before / seconds,
        "msgs": (parts["publish"] - scans_before) / seconds,
        "frames_per_s": sink.frames / seconds,
        "mbytes_per_s": sink.bytes / seconds / 1e6,
        "contacts_per_s": contacts / seconds,
        "walls": world.segments.shape[0],
    }


def main() -> int:
    logging.getLogger("simbridge").setLevel(logging.ERROR)  # contact lines go to /rosout
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
        pinned = f"pinned to CPU {min(os.sched_getaffinity(0))}"
    except (AttributeError, OSError):
        pinned = "not pinned"
    print(f"fleet: seconds of work per simulated second ({pinned}; < 1.0 = real time)")
    print(
        f"{'robots':>6} {'walls':>5} {'total':>7} {'step':>7} {'scans':>7} {'msgs':>7} "
        f"{'frames/s':>9} {'MB/s':>6} {'contacts/s':>10} {'brute total':>11} {'x':>5}"
    )
    best = 0
    at_200 = math.inf
    for n in (50, 100, 200, 400, 700, 1000, 1400, 2000):
        r = run(n)
        brute = run(n, brute=True) if n <= 400 else None
        line = (
            f"{n:>6} {r['walls']:>5} {r['per_s']:>7.3f} {r['step']:>7.3f} {r['scan']:>7.3f} "
            f"{r['msgs']:>7.3f} {r['frames_per_s']:>9.0f} {r['mbytes_per_s']:>6.1f} "
            f"{r['contacts_per_s']:>10.1f}"
        )
        if brute is not None:
            line += f" {brute['per_s']:>11.3f} {brute['per_s'] / r['per_s']:>4.1f}x"
        print(line, flush=True)
        if n == 200:
            at_200 = r["per_s"]
        if r["per_s"] < 1.0:
            best = n
        else:
            break
    # Refine between the last real-time count and the first that was not.
    lo, hi = best, n
    while hi - lo > max(25, lo // 20) and r["per_s"] >= 1.0:
        mid = (lo + hi) // 2
        m = run(mid)
        print(f"{mid:>6} {m['walls']:>5} {m['per_s']:>7.3f}  (refining)", flush=True)
        if m["per_s"] < 1.0:
            lo = mid
        else:
            hi = mid
    best = lo
    ok = at_200 < 1.0
    print(
        f"target: 200 robots in real time on one core: {'PASS' if ok else 'MISS'} "
        f"({at_200:.3f} s per s)"
    )
    goal = best >= 1000
    print(f"largest real-time robot count: {best} (goal 1000: {'PASS' if goal else 'MISS'})")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
