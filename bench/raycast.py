"""One 360-ray LiDAR scan against 20, 100 and 500 wall segments, on one core.

The walls are the default world's plus random segments inside the room (seeded). Compared side
by side with a pure-Python loop over rays and segments (the straightforward implementation) to
show what vectorising buys. Target (issue 2): <= 1 ms at 100 walls.
"""

from __future__ import annotations

import math

import numpy as np

from bench.encoding import _time
from simbridge.config import Params, WorldSpec, load_world
from simbridge.sim import World


def _world(n_walls: int) -> World:
    base = load_world(None)
    segs = [list(s) for s in base.segments()]
    rng = np.random.default_rng(1)
    while len(segs) < n_walls:
        x, y = rng.uniform(-2.8, 2.8), rng.uniform(-1.8, 1.8)
        a, r = rng.uniform(0, 2 * math.pi), rng.uniform(0.1, 0.6)
        segs.append([x, y, x + r * math.cos(a), y + r * math.sin(a)])
    spec = WorldSpec(walls=[tuple(s) for s in segs[:n_walls]])  # type: ignore[misc]
    return World(spec, Params())


def _python_scan(world: World) -> list[float]:
    x, y, yaw = world.laser_pose("")
    out = []
    segs = world.segments.tolist()
    for k in range(world.params.lidar.rays):
        th = yaw + 2 * math.pi * k / world.params.lidar.rays
        dx, dy = math.cos(th), math.sin(th)
        best = world.params.lidar.range_max
        for x1, y1, x2, y2 in segs:
            ex, ey = x2 - x1, y2 - y1
            den = dx * ey - dy * ex
            if den == 0:
                continue
            px, py = x1 - x, y1 - y
            t = (px * ey - py * ex) / den
            u = (px * dy - py * dx) / den
            if t >= 0 and 0 <= u <= 1 and t < best:
                best = t
        out.append(best)
    return out


def main() -> int:
    print("raycast: one 360-ray scan (median, microseconds)")
    print(f"{'walls':>6} {'simbridge':>11} {'pure python':>12} {'speed-up':>9}")
    at_100 = math.inf
    for n in (20, 100, 500):
        world = _world(n)
        ours = _time(lambda world=world: world.scan(""))
        slow = _time(lambda world=world: _python_scan(world), repeat=3, min_time=0.2)
        np.testing.assert_allclose(
            world.scan(""), np.clip(_python_scan(world), 0.12, 3.5), rtol=1e-5, atol=1e-5
        )
        if n == 100:
            at_100 = ours
        print(f"{n:>6} {ours * 1e6:>11.1f} {slow * 1e6:>12.1f} {slow / ours:>8.1f}x")
    ok = at_100 <= 1e-3
    print(f"target: <= 1 ms at 100 walls: {'PASS' if ok else 'MISS'} ({at_100 * 1e6:.0f} us)")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
