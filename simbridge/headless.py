"""The simulation without sockets or a real-time loop: for grading, tests and batch runs.

A :class:`Simulation` is the same world, ROS graph and robot interface as the server, stepped
by the caller as fast as Python runs instead of at ``sim.rate`` in real time. Messages go
through the graph exactly as they do for a WebSocket client (payloads validated, defaults
filled, ``/cmd_vel`` limits applied), and are read back as dicts with ROS field names; bulk
float arrays (covariances, ``ranges``) stay numpy arrays. Headers carry sim time by default.

::

    from simbridge.headless import Simulation

    sim = Simulation()                      # bundled world and parameters
    odom = sim.subscribe("/odom")
    sim.publish("/cmd_vel", {"linear": {"x": 0.2}, "angular": {"z": 0.0}})
    sim.run(5.0)                            # 100 steps, no waiting
    print(odom.latest["pose"]["pose"]["position"]["x"])   # 1.0 (about)
"""

from __future__ import annotations

import math
from collections import deque
from pathlib import Path
from typing import Any

from simbridge.app.build import build_headless
from simbridge.app.config import Params, WorldSpec
from simbridge.errors import ServiceError, SimbridgeError
from simbridge.graph.topics import Topic


__all__ = ["Inbox", "Simulation"]

_NODE = "/headless"


class Inbox:
    """The messages of one topic received so far (the newest ``maxlen``)."""

    def __init__(self, topic: str, maxlen: int | None = None) -> None:
        #: Topic name.
        self.topic = topic
        #: Messages, oldest first.
        self.messages: deque[dict[str, Any]] = deque(maxlen=maxlen)
        #: Messages received in total.
        self.count = 0

    def _receive(self, msg: Any, source: object) -> None:
        self.messages.append(msg)
        self.count += 1

    @property
    def latest(self) -> dict[str, Any] | None:
        """Return the newest message, or None before the first."""
        return self.messages[-1] if self.messages else None

    def clear(self) -> None:
        """Forget the messages received so far."""
        self.messages.clear()


class Simulation:
    """A simbridge simulation driven step by step from Python.

    Args:
        world: world spec or file (default: the bundled world).
        params: parameters or file (default: the bundled platform parameters).
        seed: noise seed; equal seeds and calls give equal runs.
        use_sim_time: stamp headers with sim time (default) or the wall clock.
        stamp_origin_ns: with sim time, the header stamp of sim time 0 (default 0).
        bags: the grader records each run into a bag in this directory (default: none).
    """

    def __init__(
        self,
        world: WorldSpec | Path | str | None = None,
        params: Params | Path | str | None = None,
        *,
        seed: int = 0,
        use_sim_time: bool = True,
        stamp_origin_ns: int = 0,
        bags: Path | None = None,
    ) -> None:
        core = build_headless(
            world,
            params,
            seed=seed,
            use_sim_time=use_sim_time,
            stamp_origin_ns=stamp_origin_ns,
            bags=bags,
        )
        #: The simulated world (robots, walls, time).
        self.world = core.world
        #: The robot world's ROS graph, built as the server builds it.
        self.robot = core.robot
        #: The ROS graph.
        self.graph = core.graph
        bridge, clock = self.robot.bridge, self.robot.simclock
        assert bridge is not None and clock is not None  # a headless world always simulates
        #: The robot's topics and services.
        self.bridge = bridge
        #: /clock and the sim-time services.
        self.clock = clock
        #: The grader (``/simbridge/grade/*``), as the server has it: no tasks and no results
        #: file of its own (``simbridge grade --headless`` hands it the task to run).
        self.grader = core.grader
        #: The tick, the server's: step, publish, timeouts, then the hooks in order.
        self.steps = core.steps
        #: The hooks run after each step's publishing, with sim time, in order (an extension
        #: may add its own).
        self.tick_hooks = self.steps.hooks

    # -- time ---------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        """Simulated seconds since the start (or the last reset)."""
        return self.world.time

    @property
    def dt(self) -> float:
        """The step length, seconds."""
        return self.world.dt

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps, publishing each as the server would (ignores ``/sim/pause``)."""
        tick = self.steps.tick
        for _ in range(n):
            tick()

    def run(self, seconds: float) -> None:
        """Advance by ``seconds`` of sim time (rounded to whole steps)."""
        self.step(max(0, round(seconds / self.dt)))

    # -- the robot ------------------------------------------------------------------------------

    def pose(self, robot: str = "") -> tuple[float, float, float]:
        """Return a robot's true pose ``(x, y, theta)``; theta in ``(-pi, pi]``."""
        s = self.world.robots[robot].state
        return s.x, s.y, math.atan2(math.sin(s.theta), math.cos(s.theta))

    def command(self, linear: float, angular: float, robot: str = "") -> None:
        """Set a robot's velocity command directly (as a ``/cmd_vel`` message does)."""
        self.world.command(robot, linear, angular)

    def reset(self) -> None:
        """Every robot back to its start pose, stopped; sim time back to 0."""
        self.call_service("/reset")

    # -- topics and services --------------------------------------------------------------

    def subscribe(self, topic: str, maxlen: int | None = 1000) -> Inbox:
        """Collect the messages of ``topic`` (which must have a type by now).

        Raises:
            SimbridgeError: the topic does not exist.
        """
        found = self.graph.topics.topics.get(topic)
        if found is None or found.type is None:
            known = ", ".join(sorted(self.graph.topics.topics))
            msg = f"no topic {topic} to subscribe to (topics: {known})"
            raise SimbridgeError(msg)
        inbox = Inbox(topic, maxlen)
        self.graph.subscribe(topic, found.type, _NODE, inbox._receive)
        if found.latched is not None:
            inbox._receive(found.latched.msg, None)
        return inbox

    def publish(self, topic: str, msg: dict[str, Any], type_name: str | None = None) -> None:
        """Publish ``msg`` (a dict with ROS field names) as a client would.

        Raises:
            ProtocolError: the message does not fit the topic's type, or the topic has no
                type and none is given, or its subscriber refused it (e.g. a NaN velocity).
        """
        known: Topic | None = self.graph.topics.topics.get(topic)
        type_ = type_name or (known.type if known is not None else None)
        if type_ is None:
            text = f"topic {topic} has no type yet: give type_name"
            raise SimbridgeError(text)
        t = self.graph.advertise(topic, type_, _NODE)
        canonical = self.graph.topics.convert(t, msg)
        out = self.graph.topics.outgoing(t, canonical, self.graph.stamp())
        self.graph.topics.deliver(t, out, self.world.time, None)

    def call_service(self, name: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Call an in-process service (``/reset``, ``/sim/step``, rosapi...); return its reply.

        Raises:
            ServiceError: no such service, or it failed.
        """
        service = self.graph.services.services.get(name)
        if service is None or service.handler is None:
            msg = f"no service {name}"
            raise ServiceError(msg)
        return service.handler(args or {})
