"""Headless simulation speed: sim seconds per wall second (real time = 1.0, the baseline)."""

from __future__ import annotations

import time

from simbridge.headless import Simulation


SIM_SECONDS = 60.0


def _speedup(topics: list[str]) -> float:
    sim = Simulation()
    for topic in topics:
        sim.subscribe(topic, maxlen=10)
    sim.command(0.2, 0.3)
    start = time.perf_counter()
    sim.run(SIM_SECONDS)
    return SIM_SECONDS / (time.perf_counter() - start)


def main() -> int:
    print(f"headless: {SIM_SECONDS:.0f} s of sim time at 20 Hz; baseline = real time (1.0x)")
    cases = {
        "no subscribers (world step only)": [],
        "/odom": ["/odom"],
        "/odom + /scan (360 rays, 10 Hz)": ["/odom", "/scan"],
        "/odom + /scan + /tf + /clock": ["/odom", "/scan", "/tf", "/clock"],
    }
    for label, topics in cases.items():
        print(f"  {label:<36} {_speedup(topics):8.0f}x real time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
