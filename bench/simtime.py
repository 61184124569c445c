"""Real-time factor of the server loop: achieved sim seconds per wall second vs the requested."""

from __future__ import annotations

import asyncio
import time

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings


SECONDS = 2.0


async def _measure() -> list[tuple[float, float, int]]:
    app = App(ServerSettings(host="127.0.0.1", port=0, http_port=None))
    await app.start()
    rows = []
    try:
        for factor in (1.0, 2.0, 5.0, 10.0, 20.0):
            app.simclock.set_real_time_factor(factor)
            await asyncio.sleep(0.2)  # settle on the new period
            s0, t0, late0 = app.world.time, time.monotonic(), app.stats.late_ticks
            await asyncio.sleep(SECONDS)
            achieved = (app.world.time - s0) / (time.monotonic() - t0)
            rows.append((factor, achieved, app.stats.late_ticks - late0))
    finally:
        await app.stop()
    return rows


def main() -> int:
    print(f"server loop real-time factor ({SECONDS:.0f} s each; baseline = the requested factor)")
    print(f"  {'requested':>9} {'achieved':>9} {'ratio':>6} {'late ticks':>10}")
    for factor, achieved, late in asyncio.run(_measure()):
        print(f"  {factor:9.1f} {achieved:9.2f} {achieved / factor:6.3f} {late:10d}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
