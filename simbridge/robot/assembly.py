"""The robot world's ROS graph, assembled in one place for the server and the headless API.

:func:`build_robot_graph` is the only code that decides what a simbridge world offers: rosapi and
the parameter services, the robots' topics and services (``/cmd_vel``, ``/odom``, ``/scan``,
``/tf``, ``/spawn``...), the safety watchdog, the e-stop, ``/walls``, ``/clock`` and the sim-time
services, tf2_web_republisher, and the ROS tutorial nodes when the settings (``--demo-nodes``)
or the world file (``demo_nodes: true``) ask for them. :class:`~simbridge.app.runner.App` drives it
in real time and :class:`~simbridge.headless.Simulation` step by step, so the two cannot offer
different graphs.

Client access control (:class:`~simbridge.app.guard.Guard`) is not part of it: it sits between
the sockets and the graph, and the headless API has no clients.
"""

from __future__ import annotations

import logging
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from simbridge.app.config import world_spec
from simbridge.app.settings import ServerSettings
from simbridge.graph.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.estop import EStop
from simbridge.robot.roles import Roles
from simbridge.robot.safety import Safety
from simbridge.robot.simclock import SimClock
from simbridge.robot.tfrepublisher import TfRepublisher, install_tf_republisher
from simbridge.robot.walls import WallsPublisher
from simbridge.rosbridge.rosapi import install_rosapi
from simbridge.sim import World


if TYPE_CHECKING:
    from simbridge.robot.tutorials import TutorialNodes


__all__ = ["RobotGraph", "build_robot_graph"]

logger = logging.getLogger(__name__)

#: Distinct failure causes logged with a traceback; later new causes are only counted.
MAX_LOGGED_CAUSES = 100


@dataclass(eq=False)
class RobotGraph:
    """The parts of a robot world's graph, and what a loop does with them."""

    #: The simulation.
    world: World
    #: Topics, services, parameters, actions.
    graph: Graph
    #: The robots' ROS interface.
    bridge: RobotBridge
    #: Sim time: /clock, pause, single step, real-time factor, sim-time stamps.
    simclock: SimClock
    #: The latching emergency stops, each with a scope (/estop, /NAME/estop, their resets and
    #: state topics).
    estop: EStop
    #: What each connection may do (/simbridge/access), for pages.
    roles: Roles
    #: The walls as a latched /walls marker.
    walls: WallsPublisher
    #: tf2_web_republisher (/republish_tfs, /tf2_web_republisher).
    tf_republisher: TfRepublisher
    #: The /cmd_vel watchdog and stop-on-disconnect.
    safety: Safety
    #: Run after each tick's publishing, with ``now``; extensions may add theirs.
    tick_hooks: list[Callable[[float], None]] = field(default_factory=list)
    #: Parts of ticks that raised (each part is isolated: the others still ran).
    failures: int = 0
    _failed: set[tuple[str, str, str, int | None]] = field(default_factory=set)
    #: The tutorial nodes (talker, listener, /add_two_ints, /fibonacci), when asked for.
    tutorials: TutorialNodes | None = None

    def publish_static(self, now: float) -> None:
        """Publish what is latched once at start: ``/tf_static`` and ``/walls``."""
        self.bridge.publish_static(now)
        self.walls.publish(now)

    def advance(self, now: float) -> None:
        """Step the simulation once and publish the step."""
        self.world.step()
        self.publish(now)

    def publish(self, now: float) -> None:
        """Publish the last step: /odom, /tf, /scan (when due), /clock."""
        self.bridge.publish(now)
        self.simclock.publish(now)

    def tick(self, now: float) -> None:
        """Expire what timed out (service calls...), then run the tick hooks (watchdog, TF).

        Each part runs whatever failed before it: a hook that raises (a TF request with a bad
        frame, a recorder's full disk) never skips the safety watchdog or another hook. A
        failure is logged once per cause (the part, the exception type and where it was
        raised), not once per tick, and counted in :attr:`failures` (``/healthz``).
        """
        self.isolated("graph timeouts", self.graph.tick, now)
        for hook in self.tick_hooks:
            self.isolated(None, hook, now)

    def isolated(self, part: str | None, run: Callable[[float], None], now: float) -> None:
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


def build_robot_graph(
    world: World,
    advance: Callable[[], None],
    *,
    settings: ServerSettings | None = None,
    use_sim_time: bool = False,
) -> RobotGraph:
    """Build the ROS graph of ``world``.

    Args:
        world: the simulation the graph exposes.
        advance: steps the simulation once and publishes the step; ``/sim/step`` calls it (the
            caller knows its clock: the real-time loop's or the headless sim time).
        settings: server limits and timeouts (default: the defaults).
        use_sim_time: stamp headers with sim time instead of the wall clock.
    """
    graph = Graph(settings=settings)
    install_rosapi(graph)
    bridge = RobotBridge(graph, world)
    simclock = SimClock(graph, world, advance, use_sim_time=use_sim_time)
    estop = EStop(graph, world)
    bridge.on_robot_added.append(estop.add_robot)
    bridge.on_robot_removed.append(estop.remove_robot)
    roles = Roles(graph, world, estop)
    walls = WallsPublisher(graph, world)
    tf_republisher = install_tf_republisher(graph, lambda: world.params.sim.rate)
    safety = Safety(graph, world)
    bridge.on_robot_removed.append(safety.forget)
    hooks: list[Callable[[float], None]] = [tf_republisher.tick, safety.tick]
    tutorials = None
    if world_spec(world).demo_nodes or (settings is not None and settings.demo_nodes):
        # imported only when asked for (off by default): an idle server need not hold them
        from simbridge.robot.tutorials import install_tutorials

        tutorials = install_tutorials(graph)
        hooks.append(tutorials.tick)
    return RobotGraph(
        world=world,
        graph=graph,
        bridge=bridge,
        simclock=simclock,
        estop=estop,
        roles=roles,
        walls=walls,
        tf_republisher=tf_republisher,
        safety=safety,
        tick_hooks=hooks,
        tutorials=tutorials,
    )
