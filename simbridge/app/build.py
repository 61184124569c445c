"""The composition root: the whole application made from the settings, in one place and order.

:func:`build` makes a server's parts, :func:`build_headless` the parts without sockets that
:class:`~simbridge.headless.Simulation` steps; both go through the same world part, so the server
and the headless API offer the same graph, grader and step sequence. The order is the one a
reader follows:

1. the world (``--no-sim``: the walls without robots) and its ROS graph
   (:func:`~simbridge.robot.assembly.build_robot_graph`: rosapi, the robots, safety, e-stop,
   /walls, /clock, tf2_web_republisher, the tutorial nodes); ``--no-sim`` builds it without
   the parts that simulate (``simulate=False``: no robot, no clock, no e-stop, no roles);
2. the grader (a server's tasks and results journal; headless: none of either);
3. a server's front ends: the guard (who each peer is), the rosbridge front end, its WebSocket
   server, the page's HTTP answers with ``/admin`` and its grading pages, the recorder
   (``--record``), then Zenoh, DDS and Foxglove when asked for;
4. the step sequence (:class:`~simbridge.app.steps.Steps`), made once: the hooks that depend on
   a step (TF, the watchdog, the tutorial nodes, the grader) and the loop's (the ROS 2 and
   Foxglove front ends, the recorder). ``/sim/step`` is its :meth:`~simbridge.app.steps.Steps.step`
   on both, on the server's monotonic clock or the headless sim time.

No part adds itself to another from elsewhere: what is wired to what is written here and in
:func:`~simbridge.robot.assembly.build_robot_graph` (the peers each node hears of,
:meth:`Graph.watch <simbridge.graph.graph.Graph.watch>`; the guard, :func:`guard_graph`; the
front ends' taps, flushers and parameter listeners).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from simbridge.app.config import Params, WorldSpec, load_params, load_world, resource_dir
from simbridge.app.guard import DEFAULT_ADMIN_SERVICES, Guard
from simbridge.app.settings import ServerSettings, budgets
from simbridge.app.steps import Hook, Steps
from simbridge.grading import install_grader
from simbridge.grading.grader import Grader
from simbridge.grading.results import ResultsLog
from simbridge.graph.graph import Graph
from simbridge.robot.assembly import RobotGraph, build_robot_graph
from simbridge.rosbridge.front import Rosbridge
from simbridge.rosbridge.server import BridgeServer, Client
from simbridge.sim import World
from simbridge.web import WebApp, rosbridge_route
from simbridge.web.admin import ClientView, admin_credentials, admin_routes
from simbridge.web.grading import grading_routes


if TYPE_CHECKING:
    from simbridge.foxglove.front import FoxgloveFront
    from simbridge.ros2.dds.link import DdsLink
    from simbridge.ros2.dds.options import DdsOptions
    from simbridge.ros2.zenoh.config import ZenohOptions
    from simbridge.ros2.zenoh.link import ZenohLink
    from simbridge.tools.recorder import GraphRecorder


__all__ = ["Core", "Parts", "build", "build_headless", "guard_graph", "offload"]


@dataclass(eq=False)
class Core:
    """The parts of a world without sockets: what a server and the headless API share."""

    #: The simulation.
    world: World
    #: The robot world's ROS graph.
    robot: RobotGraph
    #: The grader (``/simbridge/grade/*``).
    grader: Grader
    #: The tick: step, publish, timeouts, the hooks in order.
    steps: Steps

    @property
    def graph(self) -> Graph:
        """The ROS graph."""
        return self.robot.graph


@dataclass(eq=False)
class Parts:
    """A server's parts: the core and its front ends."""

    core: Core
    #: Who each peer of every front end is (docs/security.md).
    guard: Guard
    #: The rosbridge clients: their sessions, budgets and ops.
    rosbridge: Rosbridge
    #: The WebSocket server.
    server: BridgeServer
    #: HTTP answers (page, /healthz, /admin).
    web: WebApp
    #: ``--record DIR``: the graph's topics into a bag, or None.
    recorder: GraphRecorder | None = None
    #: The ROS 2 graph through Zenoh (``--zenoh``), or None.
    zenoh: ZenohLink | None = None
    #: The ROS 2 graph through DDS (``--dds``), or None.
    dds: DdsLink | None = None
    #: The Foxglove WebSocket protocol (``--foxglove-port``), or None.
    foxglove: FoxgloveFront | None = None


def offload(work: Callable[[], None], done: Callable[[BaseException | None], None]) -> bool:
    """Run ``work`` on a worker thread of the running loop, then ``done(error)`` on the loop.

    Returns False, having run nothing, with no running loop or with its executor shut down (the
    grading journal then flushes in the call: :data:`simbridge.grading.results.Offload`).
    """
    try:
        future = asyncio.get_running_loop().run_in_executor(None, work)
    except RuntimeError:
        return False

    def finished(f: asyncio.Future[None]) -> None:
        done(None if f.cancelled() else f.exception())

    future.add_done_callback(finished)
    return True


def guard_graph(graph: Graph, guard: Guard) -> None:
    """Put ``guard`` in front of ``graph``: its access rules on, each new peer given its access.

    The builder's wiring of the guard (a test that makes a guard alone calls it too): the rules
    of :attr:`Graph.access` apply, with the guard's robots and the administrative services,
    and the graph tells the guard of each peer that connects.
    """
    rules = graph.access
    rules.guarded = True
    rules.robots = guard.robots
    rules.admin_services.update(DEFAULT_ADMIN_SERVICES)
    graph.watch(guard)


def _client_view(client: Client) -> ClientView:
    """A rosbridge connection as /admin lists it (the page imports no rosbridge type)."""
    session = client.session
    return ClientView(
        peer=client,
        id=session.client_id,
        publishing=tuple(session.advertisements),
        frames_sent=client.frames_sent,
        queued=len(client.queue),
        dropped=client.queue.dropped,
    )


def _world(
    settings: ServerSettings | None,
    world: WorldSpec | Path | str | None,
    params: Params | Path | str | None,
    *,
    seed: int,
    no_sim: bool,
    use_sim_time: bool,
    stamp_origin_ns: int = 0,
) -> tuple[World, RobotGraph]:
    spec = world if isinstance(world, WorldSpec) else load_world(world)
    if no_sim:
        spec = spec.without_robots()
    prm = params if isinstance(params, Params) else load_params(params)
    sim = World(spec, prm, seed=seed)
    robot = build_robot_graph(
        sim,
        settings=settings,
        use_sim_time=use_sim_time,
        stamp_origin_ns=stamp_origin_ns,
        simulate=not no_sim,
    )
    return sim, robot


def _steps(
    robot: RobotGraph,
    hooks: list[Hook],
    *,
    clock: Callable[[], float],
    realtime: bool,
    loop_hooks: list[Hook] | None = None,
) -> Steps:
    """Make the step sequence; ``/sim/step`` is its single step (server and headless alike)."""
    steps = Steps(robot, hooks, clock=clock, loop_hooks=loop_hooks, realtime=realtime)
    if robot.simclock is not None:
        robot.simclock.stepper = steps.step
    return steps


def build_headless(
    world: WorldSpec | Path | str | None = None,
    params: Params | Path | str | None = None,
    *,
    seed: int = 0,
    use_sim_time: bool = True,
    stamp_origin_ns: int = 0,
    bags: Path | None = None,
) -> Core:
    """Make the parts without sockets, stepped by the caller on sim time.

    ``/sim/step`` runs :meth:`Steps.step` on sim time, as the server's does on its clock. The
    grader has no tasks and no results file of its own (``simbridge grade --headless`` hands
    it the task to run); with ``bags``, it records each run into a bag in that directory.
    ``stamp_origin_ns``: the header stamp of sim time 0.
    """
    sim, robot = _world(
        None,
        world,
        params,
        seed=seed,
        no_sim=False,
        use_sim_time=use_sim_time,
        stamp_origin_ns=stamp_origin_ns,
    )
    graph = robot.graph
    grader = Grader(graph, sim, ResultsLog(None), {}, bags=bags)
    if bags is not None:
        from simbridge.tools.bag import BagWriter

        grader.recorder = lambda path: BagWriter(path, graph.registry)
    steps = _steps(robot, [*robot.hooks, grader.tick], clock=lambda: sim.time, realtime=False)
    core = Core(sim, robot, grader, steps)
    robot.publish_static(0.0)
    return core


def build(
    settings: ServerSettings,
    *,
    health: Callable[[], dict[str, Any]],
    world: WorldSpec | Path | str | None = None,
    params: Params | Path | str | None = None,
    static_dir: Path | None = None,
    seed: int = 0,
    no_sim: bool = False,
    zenoh: ZenohOptions | None = None,
    dds: DdsOptions | None = None,
    record: tuple[Path | str, Sequence[str] | None] | None = None,
    run_bags: bool = False,
) -> Parts:
    """Make a server's parts from its settings and options, in the module docstring's order.

    Args:
        settings: the server's settings.
        health: produces the ``/healthz`` document (the process's figures).
        world: the world spec or file (default: the bundled world).
        params: the parameters or their file (default: the bundled platform parameters).
        seed: the noise seed.
        static_dir: the page's directory (default: the bundled page).
        no_sim: ``--no-sim``: the bridge alone (no robot, no /clock, /reset...; with Zenoh or
            DDS, a rosbridge in front of the ROS 2 graph).
        zenoh: the Zenoh front end's options, or None (it needs the [zenoh] extra).
        dds: the DDS front end's options, or None (it needs the [dds] extra).
        record: ``--record DIR`` and ``--record-topics`` (None: every topic), or None.
        run_bags: the grader records each run into a bag beside its results file.

    Raises:
        ConfigError: the tasks directory or the results file (named by its setting).
        BagError: the ``--record`` directory exists.
    """
    sim, robot = _world(
        settings, world, params, seed=seed, no_sim=no_sim, use_sim_time=settings.use_sim_time
    )
    graph = robot.graph
    grader = install_grader(graph, sim, settings, offload=offload)
    if run_bags and grader.bags is not None:  # the runs' bags, beside the results file
        from simbridge.tools.bag import BagWriter

        grader.recorder = lambda path: BagWriter(path, graph.registry)
    hooks: list[Hook] = [*robot.hooks, grader.tick]  # after each step
    loop_hooks: list[Hook] = []  # once a tick of the loop

    guard = Guard(graph, settings, robots=lambda: sim.robots.keys())
    guard_graph(graph, guard)
    rosbridge = Rosbridge(
        graph,
        *budgets(settings),
        authenticator=guard,
        default_queue_length=settings.default_queue_length,
    )
    web = WebApp(static_dir or resource_dir("static"), health)
    server = BridgeServer(rosbridge, settings, web.handle_websocket_port)
    rosbridge.subscribers.send_many = server.send_many  # one broadcast per shared frame
    web.routes.update(
        admin_routes(
            graph=graph,
            world=sim,
            clients=lambda: [_client_view(c) for c in server.clients],
            settings=settings,
            estop=robot.estop,
            roles=robot.roles,
        )
    )
    web.routes.update(grading_routes(grader, settings))
    web.routes["/api/rosbridge"] = rosbridge_route(lambda: server.port, tls=bool(settings.certfile))
    web.privileged = admin_credentials(settings)  # the instructor always finds room
    recorder = None
    if record is not None:
        from simbridge.tools.recorder import GraphRecorder

        recorder = GraphRecorder(graph, Path(record[0]), record[1])
    zenoh_link = None
    if zenoh is not None:
        from simbridge.ros2.zenoh.link import ZenohLink  # the [zenoh] extra, only when asked

        zenoh_link = ZenohLink(graph, zenoh, simulator=not no_sim, settings=settings)
        graph.topics.taps.append(zenoh_link.on_deliver)  # what it forwards to ROS 2
        if robot.bridge is not None:  # the other processes' robots
            robot.bridge.elsewhere.append(zenoh_link)
        graph.topics.flushers.append(zenoh_link.flush_early)
        loop_hooks.append(zenoh_link.tick)
    dds_link = None
    if dds is not None:
        from simbridge.ros2.dds.link import DdsLink  # the [dds] extra, only when asked

        dds_link = DdsLink(graph, dds, simulator=not no_sim, settings=settings)
        graph.topics.taps.append(dds_link.on_deliver)
        graph.topics.flushers.append(dds_link.flush_early)
        loop_hooks.append(dds_link.tick)
    foxglove = None
    if settings.foxglove_port is not None:
        from simbridge.foxglove.front import FoxgloveFront  # the [foxglove] extra, if asked

        foxglove = FoxgloveFront(
            graph,
            port=settings.foxglove_port,
            host=settings.host,
            scope=settings.foxglove_scope,
            settings=settings,
        )
        graph.topics.taps.append(foxglove.on_deliver)
        graph.params.on_change.append(foxglove.params_changed)  # every node's parameters
        loop_hooks.append(foxglove.tick)
    if recorder is not None:  # after the front ends, as when the command added it at start
        loop_hooks.append(recorder.tick)

    # the loop's clock (asyncio's is time.monotonic)
    steps = _steps(robot, hooks, clock=time.monotonic, loop_hooks=loop_hooks, realtime=True)
    return Parts(
        Core(sim, robot, grader, steps),
        guard=guard,
        rosbridge=rosbridge,
        server=server,
        web=web,
        recorder=recorder,
        zenoh=zenoh_link,
        dds=dds_link,
        foxglove=foxglove,
    )
