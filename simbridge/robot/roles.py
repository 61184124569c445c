"""What a connection may do, asked by the connection itself: ``/simbridge/access``.

A page opened with a student's token should land on that student's robot, hide what the
connection may not do and show the robot's motion model and mass. The service
``/simbridge/access`` (std_srvs/srv/Trigger, node ``/virtual_robot``) answers the caller with
``success: true`` and, as ``message``, a JSON object:

``client``
    how the instructor's /admin names this connection (``client 7 (r1's token)``);
``admin``
    whether it may call administrative services (reset, spawn, parameters, the global e-stop);
``robots``
    the robots it may drive (its token's robot; every robot for a connection that may drive
    any), and ``any_robot`` whether that holds for robots added later;
``motion_model``, ``world``
    the motion model in use and the world's name;
``robot_info``
    per robot: ``start`` pose ``[x, y, theta]``, ``mass``, ``inertia``, the velocity limits,
    ``radius``, and ``own_params`` (whether the instructor gave it parameters of its own);
``estop``
    ``held``: which of its robots an e-stop holds; ``latches``: the latches holding them (who
    latched each), and ``releasable``: the ids of those it may release itself.

A connection that has not authenticated on a server that needs a token is refused by the
guard like every other call ("not authenticated..."), which tells a page to ask for a token.
"""

from __future__ import annotations

from typing import Any

import orjson

from simbridge.app.config import world_spec
from simbridge.graph.graph import Graph
from simbridge.graph.rosapi import request_fields
from simbridge.graph.services import caller
from simbridge.graph.topics import Peer
from simbridge.robot.estop import EStop, connection_rights, describe_peer
from simbridge.robot.fleet import Elsewhere
from simbridge.sim import World


__all__ = ["ACCESS_SERVICE", "Roles"]

ACCESS_SERVICE = "/simbridge/access"
_NODE = "/virtual_robot"


class Roles:
    """Installs ``/simbridge/access`` on ``graph``."""

    def __init__(
        self, graph: Graph, world: World, estop: EStop, elsewhere: list[Elsewhere] | None = None
    ) -> None:
        self.graph = graph
        self.world = world
        self.estop = estop
        #: Who simulates robots in other processes of the classroom (listed with the others).
        self.elsewhere = elsewhere if elsewhere is not None else []
        graph.add_service(ACCESS_SERVICE, "std_srvs/srv/Trigger", _NODE, self._access)

    def robots_of(self, peer: Peer | None) -> list[str]:
        """Return the robots ``peer`` may drive, sorted."""
        scope, _ = connection_rights(peer)
        if scope == "*":
            return sorted(self.world.robots)
        return [scope] if scope in self.world.robots else []

    def robot_info(self) -> dict[str, dict[str, Any]]:
        """Return each robot's start pose and the parameters it moves with."""
        out = {}
        for name, robot in self.world.robots.items():
            p = self.world.robot_params(name)
            out[name] = {
                "start": [round(v, 6) for v in robot.start],
                "mass": p.mass,
                "inertia": p.inertia,
                "max_linear_velocity": p.max_linear_velocity,
                "max_angular_velocity": p.max_angular_velocity,
                "radius": p.radius,
                "own_params": bool(robot.overrides),
                #: Under a realism profile (its own or the shared one): /odom drifts from
                #: /ground_truth, and the profile takes the place of the motion model.
                "realism": robot.realism(self.world.params.realism) is not None,
            }
        return out

    def remote_info(self, known: dict[str, Any]) -> dict[str, dict[str, Any]]:
        """Return the robots other processes simulate, not in ``known``, as :meth:`robot_info`.

        A robot of another process is listed with this process's default parameters (the
        classroom's shared configuration), no start pose and ``remote: true``.
        """
        names = sorted({n for e in self.elsewhere for n in e.robots()} - set(known))
        if not names:
            return {}
        node = self.graph.params.nodes.get(_NODE)
        flat = node.read() if node is not None else {}
        shared = {
            key: flat.get(f"robot.{key}")
            for key in ("mass", "inertia", "max_linear_velocity", "max_angular_velocity", "radius")
        }
        return {
            name: {"start": None, **shared, "own_params": False, "remote": True} for name in names
        }

    def describe(self, peer: Peer | None) -> dict[str, Any]:
        """Return the access document of ``peer`` (see the module docstring)."""
        scope, admin = connection_rights(peer)
        robots = self.robots_of(peer)
        info = self.robot_info()
        remote = self.remote_info(info)
        info.update(remote)
        listed = sorted({*robots, *(n for n in remote if scope in ("*", n))})
        latches = {latch.id: latch for name in robots for latch in self.estop.held_by(name)}
        return {
            "client": "this process" if peer is None else describe_peer(peer),
            "admin": admin,
            "robots": listed,
            "any_robot": scope == "*",
            "motion_model": self.world.motion.name,
            "world": world_spec(self.world).name,
            "robot_info": info,
            "estop": {
                "held": [n for n in robots if self.world.halted(n)],
                "latches": [latch.summary() for latch in latches.values()],
                "releasable": [
                    latch.id for latch in latches.values() if self.estop.may_release(peer, latch)
                ],
            },
        }

    def _access(self, args: Any) -> dict[str, Any]:
        request_fields(args, (), ACCESS_SERVICE)
        return {"success": True, "message": orjson.dumps(self.describe(caller.get())).decode()}
