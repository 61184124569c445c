"""One 360-ray LiDAR scan against 20, 100 and 500 wall segments, on one core.

The walls are the default world's plus random segments inside the room (seeded). Compared side
by side with a pure-Python loop over rays and segments (the straightforward implementation) to
show what vectorising buys, and with ir-sim (PyPI ``ir-sim``, installed by the ``bench`` extra):
the same walls as ir-sim linestring obstacles, a robot with its ``lidar2d`` sensor of 360 beams
over the same directions (checked to give the same ranges), timing ``Lidar2D.step`` (what an
ir-sim user pays per scan) and, separately, its ray-casting kernel ``cast_rays`` alone.
Targets (issue 6): <= 1 ms at 100 walls; >= 4x faster than ir-sim's scan at 100 walls.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml

from bench.encoding import _time
from simbridge.app.config import Params, WorldSpec, load_world
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


def _irsim(world: World) -> tuple[Callable[[], object], Callable[[], object]] | None:
    """Return (ir-sim Lidar2D.step, ir-sim cast_rays) on ``world``'s walls, or None."""
    try:
        os.environ.setdefault("MPLBACKEND", "Agg")
        logging.getLogger("matplotlib").setLevel(logging.ERROR)
        import irsim
        from irsim.lib.algorithm.ray_casting_2d import cast_rays
    except ImportError:
        return None
    x, y, yaw = world.laser_pose("")
    rays = world.params.lidar.rays
    inc = 2 * math.pi / rays
    # ir-sim spreads `number` beams over [-range/2, range/2]; this range and a yaw half an
    # increment back give exactly simbridge's directions yaw + k inc (shifted by 180 degrees).
    cfg = {
        "world": {"height": 12, "width": 12, "step_time": 0.1, "offset": [-6, -6]},
        "robot": [
            {
                "kinematics": {"name": "diff"},
                "shape": {"name": "circle", "radius": world.params.robot.radius},
                "state": [x, y, yaw - inc / 2],
                "sensors": [
                    {
                        "name": "lidar2d",
                        "range_min": 0.0,
                        "range_max": world.params.lidar.range_max,
                        "angle_range": 2 * math.pi - inc,
                        "number": rays,
                    }
                ],
            }
        ],
        "obstacle": [
            {
                "shape": {"name": "linestring", "vertices": [[s[0], s[1]], [s[2], s[3]]]},
                "state": [0.0, 0.0, 0.0],
            }
            for s in world.segments.tolist()
        ],
    }
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench_world.yaml"
        path.write_text(yaml.safe_dump(cfg))
        with contextlib.redirect_stdout(io.StringIO()):
            env = irsim.make(str(path), display=False, log_level="ERROR")
    robot = env.robot
    lidar = robot.sensors[0]
    lidar.step(robot.state)
    theirs = np.roll(np.clip(lidar.range_data, 0.12, 3.5), 180)
    np.testing.assert_allclose(theirs, world.scan(""), atol=1e-5)
    geometry = lidar._world_geometry(robot.state)
    objects = lidar._get_detected_objects(geometry)
    range_max = world.params.lidar.range_max
    return (
        lambda: lidar.step(robot.state),
        lambda: cast_rays(geometry, objects, range_max),
    )


def _moving_scan(world: World) -> object:
    """Cast the robot's scan as for a robot that moves (a parked robot's scan is not re-cast).

    The heading flips by 1e-12 rad between calls: every call casts, at the same pose for all
    practical purposes.
    """
    robot = world.robots[""]
    heading = robot.start[2]
    robot.state.theta = heading + 1e-12 if robot.state.theta == heading else heading
    return world.scan("")


def main() -> int:
    print("raycast: one 360-ray scan (median, microseconds)")
    print(
        f"{'walls':>6} {'simbridge':>10} {'pure python':>12} {'x':>6} "
        f"{'ir-sim scan':>12} {'x':>6} {'ir-sim kernel':>14} {'x':>6}"
    )
    at_100 = math.inf
    ratio_100 = 0.0
    for n in (20, 100, 500):
        world = _world(n)
        ours = _time(lambda world=world: _moving_scan(world))
        slow = _time(lambda world=world: _python_scan(world), repeat=3, min_time=0.2)
        np.testing.assert_allclose(
            world.scan(""), np.clip(_python_scan(world), 0.12, 3.5), rtol=1e-5, atol=1e-5
        )
        ir = _irsim(world)
        line = f"{n:>6} {ours * 1e6:>10.1f} {slow * 1e6:>12.1f} {slow / ours:>5.1f}x"
        if ir is not None:
            scan_t = _time(ir[0], repeat=5, min_time=0.1)
            kernel_t = _time(ir[1], repeat=5, min_time=0.1)
            line += f" {scan_t * 1e6:>12.1f} {scan_t / ours:>5.1f}x"
            line += f" {kernel_t * 1e6:>14.1f} {kernel_t / ours:>5.1f}x"
            if n == 100:
                ratio_100 = scan_t / ours
        else:
            line += "  (ir-sim not installed: pip install -e '.[bench]')"
        if n == 100:
            at_100 = ours
        print(line)
    ok = at_100 <= 1e-3
    print(f"target: <= 1 ms at 100 walls: {'PASS' if ok else 'MISS'} ({at_100 * 1e6:.0f} us)")
    fast = ratio_100 >= 4.0
    print(
        f"target: >= 4x faster than ir-sim's scan at 100 walls: {'PASS' if fast else 'MISS'} "
        f"({ratio_100:.1f}x)"
    )
    return 0 if ok and fast else 1


if __name__ == "__main__":
    raise SystemExit(main())
