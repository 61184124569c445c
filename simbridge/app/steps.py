"""The step sequence of a world: one tick, the same for the server's loop and the headless API.

A tick steps the simulation and publishes the step (``/odom``, ``/tf``, ``/scan`` when due,
``/clock``), expires what timed out (service calls, goals), then runs the hooks in their order
(tf2_web_republisher, the safety watchdog, the tutorial nodes, the grader, the recorder, the
ROS 2 and Foxglove front ends, then whatever an extension added). The builder
(:func:`simbridge.app.build.build`) makes the list once; :class:`~simbridge.app.runner.App`
ticks it in real time and :class:`~simbridge.headless.Simulation` step by step, so the two
cannot sequence a step differently.

The two clocks differ in what the caller owns: the real-time loop passes its clock's ``now``,
skips the step while ``/sim/pause`` holds or under ``--no-sim``, and keeps a failing step from
stopping the loop; a headless step is the caller's request, so it always steps, stamps with sim
time after the step and lets a failing step raise.
"""

from __future__ import annotations

import logging
import traceback
from collections.abc import Callable

from simbridge.robot.assembly import RobotGraph


__all__ = ["MAX_LOGGED_CAUSES", "Hook", "Steps"]

logger = logging.getLogger(__name__)

#: Distinct failure causes logged with a traceback; later new causes are only counted.
MAX_LOGGED_CAUSES = 100

#: A part of a tick run after the step, with the tick's ``now``.
Hook = Callable[[float], None]


class Steps:
    """One world's tick: step, publish, expire timeouts, run the hooks.

    Args:
        robot: the robot world's graph the step publishes on.
        hooks: the parts run after the step, in order (a list: an extension may add its own,
            as :attr:`simbridge.app.runner.App.tick_hooks`).
        realtime: the server's loop (``now`` given, ``/sim/pause`` honoured, a failing step
            isolated) rather than a headless caller (sim time, every call steps).
        simulate: False under ``--no-sim``: nothing to step, the rest of the tick still runs.
    """

    def __init__(
        self, robot: RobotGraph, hooks: list[Hook], *, realtime: bool, simulate: bool = True
    ) -> None:
        self.robot = robot
        self.world = robot.world
        #: The parts run after the step, in order.
        self.hooks = hooks
        self.realtime = realtime
        self.simulate = simulate
        self._timeouts = robot.graph.tick
        #: Parts of ticks that raised (each part is isolated: the others still ran).
        self.failures = 0
        self._failed: set[tuple[str, str, str, int | None]] = set()

    def advance(self, now: float) -> None:
        """Step the simulation once and publish the step (/odom, /tf, /scan, /clock)."""
        self.world.step()
        self.robot.publish(now)

    def tick(self, now: float | None = None) -> None:
        """Run one tick: step and publish, expire timeouts, run the hooks.

        ``now``: the real-time loop's clock; a headless tick reads sim time after its step.
        Each part after the step runs whatever failed before it: a hook that raises (a TF
        request with a bad frame, a recorder's full disk) never skips the safety watchdog or
        another hook. A failure is logged once per cause (the part, the exception type and
        where it was raised), not once per tick, and counted in :attr:`failures`
        (``/healthz``).
        """
        isolated = self.isolated
        if self.realtime:
            if now is None:
                msg = "a real-time tick needs the loop's now"
                raise ValueError(msg)
            if self.simulate and not self.robot.simclock.paused:
                isolated("simulation step", self.advance, now)
        else:
            world = self.world
            world.step()
            now = world.time
            self.robot.publish(now)
        isolated("graph timeouts", self._timeouts, now)
        for hook in self.hooks:
            isolated(None, hook, now)

    def isolated(self, part: str | None, run: Hook, now: float) -> None:
        """Run one part of a tick; a failure is counted and logged once per cause.

        ``part`` names it in the log (``None``: the callable's qualified name, found only when
        it fails: a repr of every hook on every tick cost 1-2 us a tick, a few percent of a
        headless step).
        """
        try:
            run(now)
        except Exception as err:
            part = part or getattr(run, "__qualname__", None) or repr(run)
            self.failures += 1
            where = traceback.extract_tb(err.__traceback__)[-1]
            cause = (part, type(err).__name__, where.filename, where.lineno)
            if cause in self._failed or len(self._failed) >= MAX_LOGGED_CAUSES:
                return
            self._failed.add(cause)
            logger.exception("tick: %s failed (logged once per cause; the other parts ran)", part)
