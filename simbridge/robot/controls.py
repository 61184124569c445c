"""The instructor's controls of the world, as services of the robot's node.

Two administrative services (see ``DEFAULT_ADMIN_SERVICES`` in :mod:`simbridge.app.guard`: a
peer of any front end calls them only with admin rights), type ``rosapi_msgs/srv/SetParam``
(request ``name``, ``value``; response ``successful``, ``reason``):

==============================  ==============================================================
service                         what it does
==============================  ==============================================================
``/simbridge/motion_model``     ``name``: the motion model, ``kinematic`` or ``dynamic``
                                (``value`` unused)
``/simbridge/robot_params``     ``name``: a robot; ``value``: a JSON object of that robot's own
                                values (``{"robot.mass": 3.0}``; ``null``: back to the shared
                                value), ``realism.*`` too (its own realism profile); all or
                                nothing
==============================  ==============================================================

On success ``reason`` is a JSON document (``{"motion_model": "dynamic"}``, ``{"robot": "r1",
"own": {...}}``); a refused request fails the call with the reason. ``/admin``
(:mod:`simbridge.web.admin`) calls these same services: there is one way to change a robot's
parameters or the motion model.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import orjson

from simbridge.app.config import RealismParams
from simbridge.errors import ServiceError
from simbridge.graph.graph import Graph
from simbridge.graph.rosapi import request_fields
from simbridge.graph.services import caller
from simbridge.robot.bridge import ROBOT_NODE
from simbridge.sim import KinematicModel, MotionModel, World
from simbridge.sim.dynamics import DynamicModel
from simbridge.sim.world import Robot


__all__ = [
    "CONTROL_TYPE",
    "MOTION_MODELS",
    "MOTION_SERVICE",
    "REALISM_NAMES",
    "ROBOT_PARAMS_SERVICE",
    "WorldControls",
    "own_values",
]

#: The services' type: a name and a value (JSON text), answered with a reason.
CONTROL_TYPE = "rosapi_msgs/srv/SetParam"
MOTION_SERVICE = "/simbridge/motion_model"
ROBOT_PARAMS_SERVICE = "/simbridge/robot_params"

#: Motion models the instructor can switch between, by name.
MOTION_MODELS: dict[str, Callable[[], MotionModel]] = {
    "kinematic": KinematicModel,
    "dynamic": DynamicModel,
}

#: The realism profile's parameters, which each robot may have of its own (issue 26).
REALISM_NAMES = frozenset(f"realism.{n}" for n in RealismParams.model_fields)


def own_values(robot: Robot) -> dict[str, object]:
    """A robot's own values by dotted name (``robot.mass``, ``realism.slip``)."""
    out: dict[str, object] = {f"robot.{k}": v for k, v in sorted(robot.overrides.items())}
    out.update((f"realism.{k}", v) for k, v in sorted(robot.realism_own.items()))
    return out


def _first_line(err: Exception) -> str:
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    return lines[0] if lines else type(err).__name__


def _who() -> str:
    peer = caller.get()
    return peer.label if peer is not None else "an in-process caller"


def _answer(document: dict[str, Any]) -> dict[str, Any]:
    return {"successful": True, "reason": orjson.dumps(document).decode()}


class WorldControls:
    """Serves :data:`MOTION_SERVICE` and :data:`ROBOT_PARAMS_SERVICE` on ``graph`` for ``world``."""

    def __init__(self, graph: Graph, world: World) -> None:
        self.graph = graph
        self.world = world
        graph.add_service(MOTION_SERVICE, CONTROL_TYPE, ROBOT_NODE, self._motion)
        graph.add_service(ROBOT_PARAMS_SERVICE, CONTROL_TYPE, ROBOT_NODE, self._robot_params)

    def _motion(self, args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name", "value"), MOTION_SERVICE)
        name = req.get("name")
        factory = MOTION_MODELS.get(name) if isinstance(name, str) else None
        if factory is None:
            msg = f"unknown motion model {name!r}; choose one of {', '.join(sorted(MOTION_MODELS))}"
            raise ServiceError(msg)
        self.world.motion = factory()
        self.graph.log("info", f"motion model switched to '{name}' by {_who()}")
        return _answer({"motion_model": name})

    def _robot_params(self, args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name", "value"), ROBOT_PARAMS_SERVICE)
        name, text = req.get("name"), req.get("value", "")
        world = self.world
        if not isinstance(name, str) or name not in world.robots:
            known = ", ".join(repr(n) for n in sorted(world.robots))
            msg = f"no robot {name!r}; robots: {known}"
            raise ServiceError(msg)
        try:
            changes = orjson.loads(text) if isinstance(text, str) and text else None
        except orjson.JSONDecodeError:
            changes = None
        if not isinstance(changes, dict) or not changes:
            msg = 'expected {"robot": "r1", "changes": {"robot.mass": 3.0, ...}}'
            raise ServiceError(msg)
        own: dict[str, float | None] = {}
        realism: dict[str, object] = {}
        for key, value in changes.items():
            if key in REALISM_NAMES:
                if value is not None and not isinstance(value, bool | int | float):
                    msg = f"{key}: expected a number or boolean (or null), got {value!r}"
                    raise ServiceError(msg)
                realism[key.removeprefix("realism.")] = value
                continue
            if not key.startswith("robot."):
                msg = f"{key}: only robot.* and realism.* parameters may differ between robots"
                raise ServiceError(msg)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int | float)
            ):
                msg = f"{key}: expected a number (or null for the shared value), got {value!r}"
                raise ServiceError(msg)
            own[key.removeprefix("robot.")] = value
        robot = world.robots[name]
        before = dict(robot.realism_own)
        try:  # all or nothing: a refused robot.* value leaves the realism values as they were
            if realism:
                world.set_robot_realism(name, realism)
            if own:
                try:
                    world.set_robot_params(name, own)
                except ValueError:
                    world.set_robot_realism(name, dict.fromkeys(robot.realism_own) | before)
                    raise
        except ValueError as err:
            raise ServiceError(f"robot {name}: {_first_line(err)}") from None
        shown = ", ".join(f"{k} = {v}" for k, v in changes.items())
        self.graph.log("info", f"robot '{name}' parameters set by {_who()}: {shown}")
        return _answer({"robot": name, "own": own_values(robot)})
