from __future__ import annotations

import asyncio
import time

import pytest

from simbridge.app.runner import MAX_CATCH_UP, TURN_STEP, App, LoopStats, _turn_shift
from tests.conftest import AppFactory
from tests.helpers import wait_for


async def test_loop_ticks_and_reports_its_timing(app: App) -> None:
    """The loop steps the world and records lateness and work per tick."""
    await wait_for(lambda: app.stats.ticks >= 5)
    assert app.world.steps >= 5
    summary = app.health()["loop"]
    assert summary["ticks"] >= 5
    assert summary["lateness_ms_p99"] >= 0.0


async def test_loop_survives_an_exception_in_a_tick(app: App) -> None:
    """A failing tick is logged and the loop goes on."""
    calls = []

    def boom(now: float) -> None:
        calls.append(now)
        if len(calls) == 1:
            raise RuntimeError("boom")

    app.tick_hooks.append(boom)
    await wait_for(lambda: len(calls) >= 3)


async def test_loop_skips_ahead_instead_of_bursting_after_a_stall(app: App) -> None:
    """A tick that blocks for 10 dt makes the loop skip ticks, not replay them in a burst."""
    stalled = []

    def stall(now: float) -> None:
        if not stalled:
            stalled.append(now)
            time.sleep((MAX_CATCH_UP + 5) * app.world.dt)

    app.tick_hooks.append(stall)
    await wait_for(lambda: app.stats.skipped_ticks > 0, timeout=5)
    assert app.stats.skipped_ticks >= MAX_CATCH_UP


def test_loop_stats_summary_percentiles() -> None:
    """Percentiles are reported in milliseconds."""
    stats = LoopStats()
    stats.lateness.extend([0.001] * 99 + [0.050])
    stats.work.extend([0.002] * 100)
    summary = stats.summary()
    assert summary["lateness_ms_p50"] == 1.0
    assert summary["lateness_ms_max"] == 50.0
    assert summary["work_ms_p99"] == 2.0


async def test_stop_closes_clients_and_servers(make_app: AppFactory) -> None:
    """stop() ends the loop task and closes the listening sockets."""
    app = await make_app()
    port = app.ws_port
    await app.stop()
    try:
        _, writer = await asyncio.open_connection("127.0.0.1", port)
    except OSError:
        return
    writer.close()
    raise AssertionError("the port still accepts connections after stop()")


def test_a_simulator_moves_towards_its_turn_a_tenth_of_a_period_a_tick() -> None:
    """Rank r of n ticks r/n of the period after each multiple of it (wall clock)."""
    dt = 0.05
    assert _turn_shift((0, 2), dt, 100.0) == 0.0  # on its turn
    assert _turn_shift((1, 2), dt, 100.025) == 0.0
    assert _turn_shift((1, 2), dt, 100.003) == pytest.approx(dt * TURN_STEP)  # far: a tenth
    assert _turn_shift((1, 2), dt, 100.022) == pytest.approx(0.003)  # near: the rest
    assert _turn_shift((1, 2), dt, 100.028) == pytest.approx(-0.003)  # late: earlier
    assert _turn_shift((0, 2), dt, 100.049) == pytest.approx(0.001)  # across the multiple
    assert _turn_shift((2, 3), dt, 100.0) == pytest.approx(-dt * TURN_STEP)  # the short way
    assert _turn_shift((1, 2), dt, 100.02505) == 0.0  # within the tolerance
