"""Simulation time as ROS sees it: ``/clock``, sim-time stamps, pause, single step, speed.

As a ROS 2 simulator (Gazebo) does, simbridge publishes the simulated time on ``/clock``
(rosgraph_msgs/msg/Clock, every step) and, with ``use_sim_time``, stamps every header with it
instead of the wall clock: nodes started with ``use_sim_time:=true`` then agree with the
simulation when it is paused, stepped or run faster than real time. Sim time starts at 0 and
restarts at 0 on ``/reset`` (as Gazebo's reset does).

Services (node ``/sim``; std_srvs types, plus one simbridge type where no standard one fits):

* ``/sim/pause`` (std_srvs/srv/SetBool): ``{data: true}`` pauses, ``{data: false}`` resumes;
  answers ``{success, message}``. While paused nothing moves and nothing is published on
  ``/odom``, ``/tf``, ``/scan`` or ``/clock``.
* ``/sim/step`` (std_srvs/srv/Trigger): while paused, advance exactly one step (``1/sim.rate``
  seconds) and publish it before answering; refused (``success: false``) while running.
* ``/sim/set_real_time_factor`` (simbridge_msgs/srv/SetRealTimeFactor, request
  ``float64 factor``, response ``bool success, string message``): run the loop at ``factor``
  times real time, ``0 < factor <= MAX_REAL_TIME_FACTOR``; the step length stays ``1/sim.rate``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from simbridge.errors import ServiceError
from simbridge.graph.graph import Graph
from simbridge.graph.rosapi import request_fields
from simbridge.msgs.convert import finite_number
from simbridge.sim import World


__all__ = ["CLOCK_TOPIC", "MAX_REAL_TIME_FACTOR", "SIM_NODE", "SimClock"]

SIM_NODE = "/sim"
CLOCK_TOPIC = "/clock"
#: The fastest the real-time loop may be asked to run (the headless API has no limit).
MAX_REAL_TIME_FACTOR = 20.0
#: The real-time-factor service's type (no standard interface fits) and its .srv text.
RTF_TYPE = "simbridge_msgs/srv/SetRealTimeFactor"
RTF_DEFINITION = "float64 factor\n---\nbool success\nstring message"


class SimClock:
    """The simulation's clock and its ROS interface.

    Args:
        graph: where ``/clock`` and the services live.
        world: whose ``time`` is the sim time.

    With ``use_sim_time`` the builder makes :meth:`time_ns` the graph's clock for header stamps
    (:func:`simbridge.robot.assembly.build_robot_graph`).
    """

    def __init__(self, graph: Graph, world: World) -> None:
        self.graph = graph
        self.world = world
        #: One step of the world and what depends on it, for ``/sim/step``: the application's
        #: :meth:`simbridge.app.steps.Steps.step` (the builder sets it; None: not stepped).
        self.stepper: Callable[[], None] | None = None
        #: No step happens until resumed (``/sim/pause``) except single steps.
        self.paused = False
        #: Simulated seconds per real second (the real-time loop's speed).
        self.real_time_factor = 1.0
        graph.nodes[SIM_NODE] = "the simulation's clock: pause, step, real-time factor"
        self.topic = graph.advertise(CLOCK_TOPIC, "rosgraph_msgs/msg/Clock", SIM_NODE)
        graph.add_service("/sim/pause", "std_srvs/srv/SetBool", SIM_NODE, self._pause)
        graph.add_service("/sim/step", "std_srvs/srv/Trigger", SIM_NODE, self._step)
        if not graph.registry.has_service(RTF_TYPE):
            graph.registry.register_srv(RTF_TYPE, RTF_DEFINITION)
        graph.add_service(
            "/sim/set_real_time_factor",
            RTF_TYPE,
            SIM_NODE,
            self._set_rtf,
        )

    def time_ns(self) -> int:
        """Return the sim time in nanoseconds."""
        return round(self.world.time * 1e9)

    def publish(self, now: float) -> None:
        """Publish ``/clock`` (when anyone listens)."""
        if self.topic.wanted():
            sec, nanosec = divmod(self.time_ns(), 1_000_000_000)
            self.graph.publish(self.topic, {"clock": {"sec": sec, "nanosec": nanosec}}, now)

    def set_real_time_factor(self, factor: object) -> None:
        """Set the loop speed.

        Raises:
            ServiceError: ``factor`` is not in ``(0, MAX_REAL_TIME_FACTOR]``.
        """
        if not (finite_number(factor) and 0 < factor <= MAX_REAL_TIME_FACTOR):
            top = f"{MAX_REAL_TIME_FACTOR:g}"
            msg = f"real-time factor must be a number in (0, {top}], got {factor!r}"
            raise ServiceError(msg)
        self.real_time_factor = float(factor)

    # -- services -----------------------------------------------------------------------------

    def _pause(self, args: Any) -> dict[str, Any]:
        fields = request_fields(args, ("data",), "/sim/pause")
        data = fields.get("data", False)
        if not isinstance(data, bool):
            msg = f"/sim/pause: data must be true (pause) or false (resume), got {data!r}"
            raise ServiceError(msg)
        was = self.paused
        self.paused = data
        state = "paused" if data else "running"
        note = "" if was != data else " (already)"
        self.graph.log("info", f"simulation {state}{note} at t={self.world.time:.3f} s")
        return {"success": True, "message": f"{state}{note} at t={self.world.time:.3f} s"}

    def _step(self, args: Any) -> dict[str, Any]:
        request_fields(args, (), "/sim/step")
        if not self.paused:
            return {
                "success": False,
                "message": "the simulation is running; pause it first (/sim/pause {data: true})",
            }
        if self.stepper is None:
            return {"success": False, "message": "this simulation has no step sequence to run"}
        self.stepper()
        return {"success": True, "message": f"stepped to t={self.world.time:.3f} s"}

    def _set_rtf(self, args: Any) -> dict[str, Any]:
        fields = request_fields(args, ("factor",), "/sim/set_real_time_factor")
        try:
            self.set_real_time_factor(fields.get("factor"))
        except ServiceError as err:
            return {"success": False, "message": str(err)}
        return {"success": True, "message": f"real-time factor {self.real_time_factor:g}"}
