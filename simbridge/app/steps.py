"""The step sequence of a world: one tick, the same for the server's loop and the headless API.

A step steps the simulation and publishes it (``/odom``, ``/tf``, ``/scan`` when due,
``/clock``), expires what timed out (service calls, goals), then runs the hooks that depend on
the step in their order (tf2_web_republisher, the safety watchdog, the tutorial nodes, the
grader, then whatever an extension added). A tick of the loop is a step (none while paused)
followed by the loop's hooks (the recorder, the ROS 2 and Foxglove front ends). The builder
(:func:`simbridge.app.build.build`) makes the lists once; :class:`~simbridge.app.runner.App`
ticks them in real time and :class:`~simbridge.headless.Simulation` step by step, and
``/sim/step`` runs :meth:`Steps.step` on both, so the two cannot sequence a step differently.

The two clocks differ in what the caller owns: the real-time loop passes its clock's ``now``,
skips the step while ``/sim/pause`` holds or under ``--no-sim``, and keeps a failing step from
stopping the loop; a headless step is the caller's request, so it always steps, stamps with sim
time after the step and lets a failing step raise. A single step (``/sim/step``) reads the
clock it was made with: the server's monotonic clock, the headless sim time.
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
        hooks: the parts that depend on the step, run after each step in order (TF, the
            watchdog, the tutorial nodes, the grader; a list: an extension may add its own,
            as :attr:`simbridge.app.runner.App.tick_hooks`).
        clock: the ``now`` of a step that no loop hands one (:meth:`step`): the server's
            monotonic clock, the headless API's sim time (read after the step).
        loop_hooks: the parts that run once a tick of the loop, after :attr:`hooks`, but not
            for a single step (the recorder, the ROS 2 and Foxglove front ends: they bring
            their wire in line with the graph, and a single step may be asked from within
            one of them).
        realtime: the server's loop (``now`` given, ``/sim/pause`` honoured, a failing step
            isolated) rather than a headless caller (sim time, every call steps).

    A world built without a simulation (``--no-sim``: no clock) is never stepped; the rest of
    the tick still runs.
    """

    def __init__(
        self,
        robot: RobotGraph,
        hooks: list[Hook],
        *,
        clock: Callable[[], float],
        loop_hooks: list[Hook] | None = None,
        realtime: bool,
    ) -> None:
        self.robot = robot
        self.world = robot.world
        #: The parts that depend on the step, run after every step, in order.
        self.hooks = hooks
        #: The parts run once a tick of the loop, after :attr:`hooks`.
        self.loop_hooks = loop_hooks if loop_hooks is not None else []
        self.clock = clock
        self.realtime = realtime
        self._timeouts = robot.graph.tick
        #: Parts of ticks that raised (each part is isolated: the others still ran).
        self.failures = 0
        self._failed: set[tuple[str, str, str, int | None]] = set()

    def step(self) -> None:
        """Step the world once, whatever ``/sim/pause`` says, and run what depends on the step.

        The one single step of the server and the headless API (``/sim/step``, and each step
        of :meth:`simbridge.headless.Simulation.step`): step, publish (/odom, /tf, /scan when
        due, /clock), expire timeouts, run :attr:`hooks`, all on :attr:`clock`'s ``now``. A
        paused server stepped N times has run its hooks after each of the N steps, as the
        headless API has.
        """
        self._after_step(self._advance(None))

    def tick(self, now: float | None = None) -> None:
        """Run one tick: step and publish, expire timeouts, run the hooks, then the loop's.

        ``now``: the real-time loop's clock; a headless tick reads sim time after its step.
        Paused (or ``--no-sim``), the loop's tick does not step but runs the rest. Each part
        after the step runs whatever failed before it: a hook that raises (a TF request with
        a bad frame, a recorder's full disk) never skips the safety watchdog or another hook.
        A failure is logged once per cause (the part, the exception type and where it was
        raised), not once per tick, and counted in :attr:`failures` (``/healthz``).
        """
        if self.realtime:
            if now is None:
                msg = "a real-time tick needs the loop's now"
                raise ValueError(msg)
            simclock = self.robot.simclock
            if simclock is not None and not simclock.paused:
                self._advance(now)
        else:
            now = self._advance(None)
        self._after_step(now)
        for hook in self.loop_hooks:
            self.isolated(None, hook, now)

    def _advance(self, now: float | None) -> float:
        """Step the world and publish the step; return the step's ``now``.

        Real time: ``now`` (or the clock's, before the step), a failing step isolated;
        headless: the clock's after the step (sim time), a failing step raises to the caller.
        """
        if self.realtime:
            if now is None:
                now = self.clock()
            self.isolated("simulation step", self._step_and_publish, now)
            return now
        self.world.step()
        now = self.clock()
        self.robot.publish(now)
        return now

    def _step_and_publish(self, now: float) -> None:
        self.world.step()
        self.robot.publish(now)

    def _after_step(self, now: float) -> None:
        isolated = self.isolated
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
