#!/usr/bin/env python3
"""The sim-to-real lab's figures (docs/realism.md), made headless in a few seconds.

No robot is needed: a *stand-in* for the course's robot is simbridge itself under a hidden
"worn" profile (the values in :data:`WORN`). The script

1. drives the UMBmark square (1 m, open loop) with growing geometry errors and prints how far
   the odometry ends from the truth;
2. records the stand-in driven by a velocity sequence, fits it (``simbridge fit``), and
   replays the sequence on the ideal and the fitted model (``simbridge compare --fitted``);
3. runs the PID lab's heading step (the page's controller: 10 Hz, Kp 3, Ki 0.1, Kd 0.05) on
   the ideal plant and on the fitted one.

``python examples/realism_lab.py --out DIR`` leaves the bags, ``fitted.yaml`` and
``compare.svg`` in DIR. With a real robot, record it instead (docs/realism.md).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

import yaml

from simbridge.app.config import Params, RealismParams, WorldSpec
from simbridge.headless import Simulation
from simbridge.msgs import TypeRegistry
from simbridge.sim import World
from simbridge.tools.bag import BagWriter
from simbridge.tools.compare import compare_main
from simbridge.tools.fit import fit_main
from simbridge.tools.record import replay_headless


#: The stand-in robot's hidden profile.
WORN = {
    "enabled": True,
    "cmd_latency": 0.15,
    "motor_time_constant": 0.3,
    "deadband": 0.04,
    "wheel_speed_scale": 0.93,
    "encoder_ticks": 360,
}
#: (seconds, linear m/s, angular rad/s): steps, turns, a slow ramp (for the deadband), a square.
SEQUENCE = (
    [(0.0, 0.0, 0.0), (1.0, 0.25, 0.0), (3.0, 0.0, 1.2), (4.5, -0.2, 0.0), (6.0, 0.0, 0.0)]
    + [(7.0 + 0.5 * i, 0.01 + 0.01 * i, 0.0) for i in range(8)]
    + [(11.0 + 7.0 * k + dt, v, w) for k in range(4) for dt, v, w in ((0, 0.2, 0), (5, 0, 0.8))]
    + [(39.0, 0.0, 0.0)]
)


def square_error(e: float) -> tuple[float, float]:
    """Odometry minus truth after a 1 m square, right wheel and wheelbase ``e`` too large."""
    r, b = 0.033, 0.160
    real = RealismParams(enabled=True, wheel_radius_right=r * (1 + e), wheelbase=b * (1 + e))
    world = World(WorldSpec(), Params(realism=real))
    for _ in range(4):
        for v, w, steps in ((0.2, 0.0, 100), (0.0, math.pi / 4, 40)):
            world.command("", v, w)
            for _ in range(steps):
                world.step()
    robot = world.robots[""]
    odom, truth = robot.odometry(), robot.state
    turn = math.atan2(math.sin(odom.theta - truth.theta), math.cos(odom.theta - truth.theta))
    return math.hypot(odom.x - truth.x, odom.y - truth.y), math.degrees(turn)


def heading_step(params: Params) -> tuple[float, float | None]:
    """The page's PID lab (10 Hz), 90 degrees: overshoot (deg) and 5 % settling time (s)."""
    sim = Simulation(world=WorldSpec(), params=params)
    odom = sim.subscribe("/odom")
    kp, ki, kd, limit = 3.0, 0.1, 0.05, params.robot.max_angular_velocity
    goal, integral, prev, peak, settled = math.pi / 2, 0.0, None, 0.0, None
    sim.step()
    for tick in range(100):  # 10 s at 10 Hz
        msg = odom.latest
        assert msg is not None
        q = msg["pose"]["pose"]["orientation"]
        theta = 2 * math.atan2(q["z"], q["w"])
        err, dt = goal - theta, 0.1
        derivative = 0.0 if prev is None else (err - prev) / dt
        prev = err
        raw = kp * err + ki * (integral + err * dt) + kd * derivative
        if abs(raw) < limit:
            integral += err * dt
        sim.command(0.0, max(-limit, min(limit, kp * err + ki * integral + kd * derivative)))
        sim.step(2)
        peak = max(peak, theta - goal)
        if abs(err) > 0.05 * goal:
            settled = None
        elif settled is None:
            settled = tick * dt
    return math.degrees(peak), settled


def record_stand_in(out: Path) -> Path:
    """Drive the stand-in robot with :data:`SEQUENCE`; return its bag (``out/real``)."""
    writer = BagWriter(out / "commands", TypeRegistry(), segment_seconds=1e9)
    base = 1_700_000_000 * 10**9
    for t, v, w in SEQUENCE:
        msg = {"linear": {"x": v, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": w}}
        writer.write("/cmd_vel", "geometry_msgs/msg/Twist", msg, base + round(t * 1e9))
    writer.close()
    hidden = Params.parse({"realism": WORN})
    replay_headless(str(out / "commands"), out / "real", world=WorldSpec(), params=hidden)
    return out / "real"


def main() -> int:
    """Print the lab's figures; return 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="keep the bags, fitted.yaml and compare.svg here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out) if args.out else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        print("1. UMBmark square (1 m, counter-clockwise, open loop): odometry - truth at the end")
        for e in (0.0, 0.01, 0.02, 0.05):
            pos, turn = square_error(e)
            print(f"   geometry error {e:4.0%}: position {pos:.3f} m, heading {turn:+.1f} deg")
        print(f"2. the stand-in robot (hidden profile {json.dumps(WORN)}):")
        real = record_stand_in(out)
        fitted = out / "fitted.yaml"
        with contextlib.redirect_stdout(io.StringIO()) as text:
            fit_main([str(real), "-o", str(fitted)])
        print("   " + text.getvalue().strip().replace("\n", "\n   "))
        with contextlib.redirect_stdout(io.StringIO()) as text:
            compare_main([str(real), "--fitted", str(fitted), "--plot", str(out / "compare.svg")])
        print("   " + text.getvalue().strip().splitlines()[-2])
        print("3. PID lab, heading step 90 deg at 10 Hz (Kp 3, Ki 0.1, Kd 0.05):")
        with fitted.open(encoding="utf-8") as f:
            fitted_params = Params.parse(yaml.safe_load(f))
        for label, params in (("ideal", Params()), ("fitted", fitted_params)):
            overshoot, settle = heading_step(params)
            when = f"{settle:.1f} s" if settle is not None else "not within 10 s"
            print(f"   {label:<7} overshoot {overshoot:5.1f} deg, settled (5 %) after {when}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
