"""Robots at run time: spawn, kill and teleport services, turtlesim-style.

ROS 2 ``simulation_interfaces`` is not in the rosbags type store, so simbridge serves the
well-known turtlesim service shapes (field lists as in ROS 2 turtlesim, definitions registered
here so rosapi and CDR know them):

========================================  ==============================  ===================
service                                   type                            request -> response
========================================  ==============================  ===================
``/spawn``                                ``turtlesim/srv/Spawn``         ``x, y, theta, name``
                                                                          -> ``name``
``/kill``                                 ``turtlesim/srv/Kill``          ``name`` -> (empty)
``/NAME/teleport_absolute``               ``turtlesim/srv/TeleportAbsolute``  ``x, y, theta``
                                                                          -> (empty)
========================================  ==============================  ===================

``/spawn`` with an empty ``name`` picks ``robotN``. A spawned robot's pose is also its start
pose (``/reset`` puts it back there; ``/reset`` keeps spawned robots). A pose whose footprint
would overlap a wall or another robot (or another robot's start pose) is refused with the
reason. The single un-namespaced robot's teleport service is ``/teleport_absolute``.

Contacts are published as ``simbridge_msgs/msg/Contact`` (:data:`CONTACT_DEFINITION`).
"""

from __future__ import annotations

from typing import Any, Protocol

from simbridge.errors import ServiceError
from simbridge.graph.graph import Graph
from simbridge.graph.rosapi import request_fields
from simbridge.msgs.convert import finite_number
from simbridge.sim import Robot, World


__all__ = [
    "CONTACT_DEFINITION",
    "CONTACT_TYPE",
    "Elsewhere",
    "Fleet",
    "add_robot_services",
    "install_fleet",
    "remove_robot_services",
]

CONTACT_TYPE = "simbridge_msgs/msg/Contact"
#: The contact message: published on ``/NAME/contact`` each step an obstacle stops the robot.
CONTACT_DEFINITION = """\
# A robot's motion was stopped (fully or partly) by an obstacle during one step.
std_msgs/Header header        # frame_id: the robot's odom frame (r1/odom)
string robot                  # the robot that was stopped ('' for the single robot)
string other                  # 'wall', or the name of the robot it touched
geometry_msgs/Point point     # the contact point on the obstacle
geometry_msgs/Vector3 normal  # unit vector from the obstacle towards the robot
"""

_SERVICES = {
    "turtlesim/srv/Spawn": "float32 x\nfloat32 y\nfloat32 theta\nstring name\n---\nstring name\n",
    "turtlesim/srv/Kill": "string name\n---\n",
    "turtlesim/srv/TeleportAbsolute": "float32 x\nfloat32 y\nfloat32 theta\n---\n",
}


class Elsewhere(Protocol):
    """Robots that other simbridge processes of the classroom simulate.

    A ROS 2 front end sees them (another process's ``/NAME/odom`` publisher); the composition
    root gives it to the fleet and the roles, which refuse and list those names.
    """

    def robots(self) -> list[str]:
        """Return the names of the robots other processes simulate, sorted."""

    def simulator_of(self, name: str) -> str | None:
        """Return who simulates robot ``name`` elsewhere (for people), or None."""


class Fleet(Protocol):
    """What the fleet services need of the robots' ROS interface (a ``RobotBridge``)."""

    #: Where the services live.
    graph: Graph
    #: Whose robots are spawned and removed.
    world: World
    #: The node that provides the services (the robots' driver).
    node: str
    #: The robots that have topics, by name.
    robots: dict[str, Any]
    #: Who simulates robots elsewhere (their names are taken).
    elsewhere: list[Elsewhere]

    def add_robot(self, robot: Robot) -> None:
        """Create the topics of one robot."""

    def remove_robot(self, name: str) -> None:
        """Remove the topics of one robot."""

    def publish_static(self, now: float) -> None:
        """Publish ``/tf_static`` again (the set of robots changed)."""


def _number(req: dict[str, Any], key: str, service: str) -> float:
    value = req.get(key, 0.0)
    if not finite_number(value):
        msg = f"{service}: field '{key}' must be a finite number, got {value!r}"
        raise ServiceError(msg)
    return float(value)


def _name(req: dict[str, Any], service: str) -> str:
    value = req.get("name", "")
    if not isinstance(value, str):
        msg = f"{service}: field 'name' must be a string, got {value!r}"
        raise ServiceError(msg)
    return value.strip("/")


def _elsewhere(bridge: Fleet, name: str) -> str | None:
    """Return who simulates robot ``name`` in another process, or None."""
    return next((w for e in bridge.elsewhere if (w := e.simulator_of(name)) is not None), None)


def install_fleet(bridge: Fleet) -> None:
    """Register the types and the ``/spawn`` and ``/kill`` services of ``bridge``'s world."""
    registry = bridge.graph.registry
    if not registry.known(CONTACT_TYPE):
        registry.register_msg(CONTACT_TYPE, CONTACT_DEFINITION)
    for name, text in _SERVICES.items():
        if not registry.has_service(name):
            registry.register_srv(name, text)
    world, graph = bridge.world, bridge.graph

    def spawn(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("x", "y", "theta", "name"), "/spawn")
        pose = (_number(req, "x", "/spawn"), _number(req, "y", "/spawn"))
        theta = _number(req, "theta", "/spawn")
        name = _name(req, "/spawn")
        if not name:  # robotN, free here and in the other processes of the classroom
            n = 1
            while f"robot{n}" in world.robots or _elsewhere(bridge, f"robot{n}"):
                n += 1
            name = f"robot{n}"
        where = _elsewhere(bridge, name)
        if where is not None:
            msg = (
                f"/spawn: robot name '{name}' is taken by another simbridge process of this "
                f"classroom ({where}); choose another name"
            )
            raise ServiceError(msg)
        try:
            robot = world.spawn(name, (*pose, theta))
        except ValueError as err:
            raise ServiceError(f"/spawn: {err}") from None
        try:
            bridge.add_robot(robot)
        except Exception as err:
            world.remove(name)
            bridge.robots.pop(name, None)
            raise ServiceError(f"/spawn: cannot create the topics of '{name}': {err}") from None
        bridge.publish_static(0.0)
        graph.log("info", f"spawned robot '{name}' at ({pose[0]:g}, {pose[1]:g}, {theta:g})")
        return {"name": name}

    def kill(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("name",), "/kill")
        name = _name(req, "/kill")
        if name not in world.robots:
            known = ", ".join(repr(n) for n in world.robots) or "none"
            raise ServiceError(f"/kill: no robot named '{name}' (robots: {known})")
        world.remove(name)
        bridge.remove_robot(name)
        bridge.publish_static(0.0)
        graph.log("info", f"removed robot '{name}'")
        return {}

    graph.add_service("/spawn", "turtlesim/srv/Spawn", bridge.node, spawn)
    graph.add_service("/kill", "turtlesim/srv/Kill", bridge.node, kill)


def add_robot_services(bridge: Fleet, robot: Robot) -> None:
    """Register the per-robot services (``teleport_absolute``) of ``robot``."""
    service = robot.topic("teleport_absolute")
    world = bridge.world
    name = robot.name

    def teleport(args: Any) -> dict[str, Any]:
        req = request_fields(args, ("x", "y", "theta"), service)
        pose = (_number(req, "x", service), _number(req, "y", service))
        theta = _number(req, "theta", service)
        try:
            world.teleport(name, (*pose, theta))
        except (KeyError, ValueError) as err:
            raise ServiceError(f"{service}: {err}") from None
        return {}

    bridge.graph.add_service(service, "turtlesim/srv/TeleportAbsolute", bridge.node, teleport)


def remove_robot_services(bridge: Fleet, robot: Robot) -> None:
    """Remove the per-robot services of ``robot``."""
    bridge.graph.services.services.pop(robot.topic("teleport_absolute"), None)
