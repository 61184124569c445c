"""The emergency stop: a latch in the server, not a request to the page.

Services of node ``/virtual_robot`` (std_srvs/srv/Trigger: empty request, ``{success,
message}`` response):

* ``/estop`` latches the stop: every robot halts at once (velocity zero, no coasting, whatever
  the motion model) and every ``/cmd_vel`` is ignored while latched;
* ``/estop/reset`` releases it; robots stay still until the next command. Nothing else releases
  the latch: not ``/reset``, not a disconnect, not a new client.

Topic ``/estop/state`` (std_msgs/msg/Bool, latched) tells every page whether it is latched, so a
late or reconnecting page shows the truth at once.
"""

from __future__ import annotations

from typing import Any

from simbridge.graph.graph import Graph
from simbridge.graph.rosapi import request_fields
from simbridge.sim import World


__all__ = ["ESTOP_RESET_SERVICE", "ESTOP_SERVICE", "ESTOP_STATE_TOPIC", "EStop"]

ESTOP_SERVICE = "/estop"
ESTOP_RESET_SERVICE = "/estop/reset"
ESTOP_STATE_TOPIC = "/estop/state"
_NODE = "/virtual_robot"


class EStop:
    """Installs the e-stop services and state topic on ``graph`` for ``world``."""

    def __init__(self, graph: Graph, world: World) -> None:
        self.graph = graph
        self.world = world
        self.state = graph.advertise(ESTOP_STATE_TOPIC, "std_msgs/msg/Bool", _NODE, latch=True)
        graph.add_service(ESTOP_SERVICE, "std_srvs/srv/Trigger", _NODE, self._latch)
        graph.add_service(ESTOP_RESET_SERVICE, "std_srvs/srv/Trigger", _NODE, self._release)
        self.publish()

    def publish(self) -> None:
        """Publish (latch) the current state on ``/estop/state``."""
        self.graph.publish(self.state, {"data": self.world.estopped}, 0.0)

    def _latch(self, args: Any) -> dict[str, Any]:
        request_fields(args, (), ESTOP_SERVICE)
        was = self.world.estopped
        self.world.estop()
        self.publish()
        if not was:
            self.graph.log("warn", "EMERGENCY STOP latched: robots halted, /cmd_vel ignored")
        return {"success": True, "message": "emergency stop latched; call /estop/reset to release"}

    def _release(self, args: Any) -> dict[str, Any]:
        request_fields(args, (), ESTOP_RESET_SERVICE)
        was = self.world.estopped
        self.world.release_estop()
        self.publish()
        if was:
            self.graph.log("info", "emergency stop released")
        return {"success": True, "message": "emergency stop released" if was else "not latched"}
