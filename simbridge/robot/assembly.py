"""The robot world's ROS graph, assembled in one place for the server and the headless API.

:func:`build_robot_graph` is the only code that decides what a simbridge world offers: rosapi and
the parameter services, the robots' topics and services (``/cmd_vel``, ``/odom``, ``/scan``,
``/tf``, ``/spawn``...), the safety watchdog, the e-stop, ``/walls``, ``/clock`` and the sim-time
services, tf2_web_republisher, and the ROS tutorial nodes when the settings (``--demo-nodes``)
or the world file (``demo_nodes: true``) ask for them. The application's builder
(:func:`simbridge.app.build.build`) calls it for the server and for
:class:`~simbridge.headless.Simulation` alike, so the two cannot offer different graphs; the
step sequence that drives it is :class:`simbridge.app.steps.Steps`. Without a simulation
(``--no-sim``, ``simulate=False``) it makes none of the nodes that simulate. It also wires the
nodes to each other and to the graph's peers (:meth:`Graph.watch
<simbridge.graph.graph.Graph.watch>`): no node adds itself from its constructor.

Client access control (:class:`~simbridge.app.guard.Guard`) is not part of it: it sits between
the sockets and the graph, and the headless API has no clients.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from simbridge.app.config import world_spec
from simbridge.app.settings import ServerSettings
from simbridge.graph.graph import Graph
from simbridge.graph.paramservices import install_parameter_services
from simbridge.graph.rosapi import install_rosapi
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.controls import WorldControls
from simbridge.robot.estop import EStop
from simbridge.robot.roles import Roles
from simbridge.robot.safety import Safety
from simbridge.robot.simclock import SimClock
from simbridge.robot.tfrepublisher import TfRepublisher, install_tf_republisher
from simbridge.robot.walls import WallsPublisher
from simbridge.sim import World


if TYPE_CHECKING:
    from simbridge.robot.tutorials import TutorialNodes


__all__ = ["RobotGraph", "build_robot_graph"]


@dataclass(eq=False)
class RobotGraph:
    """The parts of a robot world's graph.

    Without a simulation (``simulate=False``, ``--no-sim``) the parts that simulate are None:
    the robots' interface, the clock, the e-stops, the roles, ``/walls``, the watchdog and the
    instructor's controls; the graph keeps rosapi, tf2_web_republisher and the tutorial nodes.
    """

    #: The simulation.
    world: World
    #: Topics, services, parameters, actions.
    graph: Graph
    #: tf2_web_republisher (/republish_tfs, /tf2_web_republisher).
    tf_republisher: TfRepublisher
    #: The robots' ROS interface.
    bridge: RobotBridge | None = None
    #: Sim time: /clock, pause, single step, real-time factor, sim-time stamps.
    simclock: SimClock | None = None
    #: The latching emergency stops, each with a scope (/estop, /NAME/estop, their resets and
    #: state topics).
    estop: EStop | None = None
    #: What each connection may do (/simbridge/access), for pages.
    roles: Roles | None = None
    #: The walls as a latched /walls marker.
    walls: WallsPublisher | None = None
    #: The /cmd_vel watchdog and stop-on-disconnect.
    safety: Safety | None = None
    #: Its nodes' parts of a tick, in order, run after each step's publishing (TF, the
    #: watchdog, the tutorial nodes).
    hooks: tuple[Callable[[float], None], ...] = ()
    #: The tutorial nodes (talker, listener, /add_two_ints, /fibonacci), when asked for.
    tutorials: TutorialNodes | None = None
    #: The instructor's controls: /simbridge/motion_model, /simbridge/robot_params.
    controls: WorldControls | None = None

    def publish_static(self, now: float) -> None:
        """Publish what is latched once at start: ``/tf_static`` and ``/walls``."""
        if self.bridge is not None:
            self.bridge.publish_static(now)
        if self.walls is not None:
            self.walls.publish(now)

    def publish(self, now: float) -> None:
        """Publish the last step: /odom, /tf, /scan (when due), /clock."""
        if self.bridge is not None:
            self.bridge.publish(now)
        if self.simclock is not None:
            self.simclock.publish(now)


def _shifted(clock: Callable[[], int], origin_ns: int) -> Callable[[], int]:
    """``clock`` read ``origin_ns`` later (itself when 0)."""
    return clock if not origin_ns else lambda: origin_ns + clock()


def build_robot_graph(
    world: World,
    *,
    settings: ServerSettings | None = None,
    use_sim_time: bool = False,
    stamp_origin_ns: int = 0,
    simulate: bool = True,
) -> RobotGraph:
    """Build the ROS graph of ``world``.

    Args:
        world: the simulation the graph exposes.
        settings: server limits and timeouts (default: the defaults).
        use_sim_time: stamp headers with sim time instead of the wall clock.
        stamp_origin_ns: with ``use_sim_time``, the header stamp of sim time 0 (a replay
            stamps on its bag's time line); ``/clock`` stays the sim time.
        simulate: False for ``--no-sim``: none of the robot's and the clock's topics and
            services, no e-stop, no roles, no ``/walls``; a rosbridge (with Zenoh or DDS, in
            front of the ROS 2 graph, whose robots have all of those) with rosapi,
            tf2_web_republisher and, when asked for, the tutorial nodes.
    """
    s = settings or ServerSettings()
    graph = Graph(service_timeout=s.service_timeout, max_parameter_names=s.max_parameter_names)
    install_rosapi(graph)
    install_parameter_services(graph)  # every parameter node's, present and future
    bridge: RobotBridge | None = None
    simclock: SimClock | None = None
    estop: EStop | None = None
    roles: Roles | None = None
    walls: WallsPublisher | None = None
    controls: WorldControls | None = None
    safety: Safety | None = None
    if simulate:
        bridge = RobotBridge(graph, world)
        controls = WorldControls(graph, world)
        simclock = SimClock(graph, world)
        if use_sim_time:  # every header of the graph stamped with sim time
            graph.wall_clock_ns = _shifted(simclock.time_ns, stamp_origin_ns)
        estop = EStop(graph, world, s)
        bridge.on_robot_added.append(estop.add_robot)
        bridge.on_robot_removed.append(estop.remove_robot)
        roles = Roles(graph, world, estop, bridge.elsewhere)
        walls = WallsPublisher(graph, world)
    tf_republisher = install_tf_republisher(graph, lambda: world.params.sim.rate, s)
    hooks: list[Callable[[float], None]] = [tf_republisher.tick]
    if bridge is not None:
        safety = Safety(graph, world)
        bridge.on_robot_removed.append(safety.forget)
        hooks.append(safety.tick)
    robot = RobotGraph(
        world=world,
        graph=graph,
        tf_republisher=tf_republisher,
        bridge=bridge,
        simclock=simclock,
        estop=estop,
        roles=roles,
        walls=walls,
        safety=safety,
        controls=controls,
    )
    if world_spec(world).demo_nodes or (settings is not None and settings.demo_nodes):
        # imported only when asked for (off by default): an idle server need not hold them
        from simbridge.robot.tutorials import install_tutorials

        robot.tutorials = install_tutorials(graph)
        hooks.append(robot.tutorials.tick)
    robot.hooks = tuple(hooks)
    # who hears of the peers of every front end, in this order (no node adds itself)
    watching = (estop, tf_republisher, safety, robot.tutorials)
    graph.watch(*(part for part in watching if part is not None))
    return robot
