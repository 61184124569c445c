"""What the realism profile costs (issue 26), and that the exact default costs what it did.

Headless runs (sim seconds per wall second) and the world step of 30 driving robots, with the
default parameters (exact: the kinematic model, /odom = the truth) and with every realism
effect on (latency, motor lag, deadband, scale, slip draws, true geometry, encoder ticks).
Against a checkout before issue 26 (``--baseline DIR``) only the exact rows run there.
"""

from __future__ import annotations

import time

from simbridge.app.config import Params, WorldSpec
from simbridge.headless import Simulation
from simbridge.sim import World


SIM_SECONDS = 30.0
ROBOTS = 30
STEPS = 2000
#: Every effect of the profile on.
PROFILE = {
    "enabled": True,
    "cmd_latency": 0.12,
    "motor_time_constant": 0.25,
    "deadband": 0.02,
    "wheel_speed_scale": 0.95,
    "slip": 0.03,
    "slip_stddev": 0.02,
    "wheel_radius_right": 0.0335,
    "wheelbase": 0.165,
    "encoder_ticks": 1440,
}


def _params(realism: bool) -> Params:
    return Params.parse({"realism": PROFILE}) if realism else Params()


def _speedup(topics: list[str], realism: bool) -> float:
    sim = Simulation(params=_params(realism))
    for topic in topics:
        sim.subscribe(topic, maxlen=10)
    sim.command(0.2, 0.3)
    start = time.perf_counter()
    sim.run(SIM_SECONDS)
    return SIM_SECONDS / (time.perf_counter() - start)


def _step_us(realism: bool) -> float:
    """Microseconds of one World.step of ROBOTS robots in an open world, all driving."""
    spec = WorldSpec.parse(
        {"robots": [{"name": f"r{i}", "pose": [i * 1.0, 0.0, 0.0]} for i in range(ROBOTS)]}
    )
    world = World(spec, _params(realism))
    for name in world.robots:
        world.command(name, 0.2, 0.3)
    best = float("inf")
    for _ in range(3):  # the best of three: the machine is shared
        start = time.perf_counter()
        for _ in range(STEPS):
            world.step()
        best = min(best, (time.perf_counter() - start) / STEPS * 1e6)
    return best


def main() -> int:
    has_profile = "realism" in Params.sections()
    print(f"realism: headless, {SIM_SECONDS:.0f} s of sim time at 20 Hz")
    modes = [("exact", False)] + ([("profile", True)] if has_profile else [])
    for mode, realism in modes:
        for label, topics in (
            ("/odom", ["/odom"]),
            ("/odom + /scan + /tf", ["/odom", "/scan", "/tf"]),
        ):
            print(f"  {mode} {label:<28} {_speedup(topics, realism):8.0f}x real time")
    print(f"realism: world step, {ROBOTS} robots driving, no messages (best of 3 x {STEPS})")
    for mode, realism in modes:
        print(f"  {mode} step {_step_us(realism):8.1f} us")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
