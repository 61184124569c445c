"""The step sequence shared by the server's loop and the headless API."""

from __future__ import annotations

from typing import Any

import pytest

from simbridge.app.build import Core, build, build_headless
from simbridge.app.settings import ServerSettings


def test_a_headless_tick_steps_publishes_then_runs_the_hooks_on_sim_time() -> None:
    core = build_headless()
    seen: list[tuple[float, int]] = []
    core.steps.hooks.append(lambda now: seen.append((now, core.world.steps)))
    core.steps.tick()
    core.steps.tick()
    assert seen == [(pytest.approx(core.world.dt), 1), (pytest.approx(2 * core.world.dt), 2)]


def test_a_failing_hook_is_counted_and_the_later_ones_still_run() -> None:
    core = build_headless()
    ran: list[float] = []

    def broken(now: float) -> None:
        raise RuntimeError("broken hook")

    core.steps.hooks.insert(0, broken)
    core.steps.hooks.append(ran.append)
    core.steps.tick()
    core.steps.tick()
    assert len(ran) == 2 and core.steps.failures == 2


def test_a_paused_real_time_tick_does_not_step_but_runs_the_hooks() -> None:
    settings = ServerSettings(host="127.0.0.1", port=0, http_port=None)
    steps = build(settings, health=lambda: {}).core.steps
    ran: list[float] = []
    steps.hooks.append(ran.append)
    steps.tick(1.0)
    assert steps.world.steps == 1
    pause = steps.robot.graph.services.services["/sim/pause"].handler
    assert pause is not None and pause({"data": True})["success"]
    steps.tick(2.0)
    assert steps.world.steps == 1 and ran == [1.0, 2.0]


def _service(core: Core, name: str, args: dict[str, Any]) -> Any:
    handler = core.graph.services.services[name].handler
    assert handler is not None
    return handler(args)


@pytest.mark.parametrize("server", [True, False], ids=["server", "headless"])
def test_sim_step_runs_one_step_and_its_hooks_on_the_server_as_headless(server: bool) -> None:
    """Paused, each /sim/step steps once and runs the step's hooks once, on the core's clock.

    The same Steps.step on both: the server's reads the monotonic clock, the headless API's
    the sim time after the step; the loop's own hooks (front ends, recorder) wait for a tick.
    """
    settings = ServerSettings(host="127.0.0.1", port=0, http_port=None)
    core = build(settings, health=lambda: {}).core if server else build_headless()
    seen: list[tuple[int, float]] = []
    looped: list[float] = []
    core.steps.hooks.append(lambda now: seen.append((core.world.steps, now)))
    core.steps.loop_hooks.append(looped.append)
    assert _service(core, "/sim/pause", {"data": True})["success"]
    before = core.world.steps
    for _ in range(2):
        assert _service(core, "/sim/step", {})["success"]
    assert [n for n, _ in seen] == [before + 1, before + 2] and looped == []
    if not server:
        assert [now for _, now in seen] == pytest.approx([core.world.dt, 2 * core.world.dt])
    else:
        assert seen[0][1] <= seen[1][1] and seen[1][1] > 2 * core.world.dt  # monotonic, not sim
