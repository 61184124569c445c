"""Server-side safety of the robots: the ``/cmd_vel`` watchdog, stop on disconnect or lost link.

They are parameters of ``/virtual_robot`` (section ``safety`` of the parameter file). The
course describes a robot that keeps its last command, so the watchdog and stop-on-disconnect
are off by default (``config/classroom_params.yaml`` turns them on); a lost link stops the
robot by default.

* ``safety.cmd_vel_timeout`` > 0: a robot that is moving and has received no ``/cmd_vel`` for
  that many seconds is stopped (turtlesim does the same after 1 s), whatever its client does.
* ``safety.stop_on_disconnect``: when the client that last commanded a robot disconnects
  (cleanly or not), that robot is stopped.
* ``safety.stop_on_lost_link`` (on by default): when that client is lost, gone without closing
  its connection itself (a killed browser or script, a crash, a laptop that left the Wi-Fi,
  found by the keepalive; a page the browser closed for it: see
  :func:`simbridge.rosbridge.server.closed_on_purpose`), that robot is stopped: nobody is left
  who could stop it, and a page may never have sent its zero. A client that closes its
  connection (a script that sent one command and ended, ``simbridge topic pub --once``) leaves
  the robot on that command, as the course describes.

Commands are observed as an in-process subscriber (of node ``/virtual_robot``) of each robot's
``cmd_vel`` topic and timed from when they arrived (not from the next tick: that made the
watchdog stop a robot up to a timeout and two ticks after its last command); robots added to
or removed from the world are followed at the next tick. A robot is therefore stopped by the
first tick more than the timeout after its last command: within the timeout and one tick.
"""

from __future__ import annotations

import logging
from typing import Any

from simbridge.app.config import world_params
from simbridge.errors import ProtocolError
from simbridge.graph.graph import Graph, PeerWatcher
from simbridge.graph.topics import InternalCallback, Peer
from simbridge.msgs.convert import finite_number
from simbridge.robot.bridge import ROBOT_NODE
from simbridge.robot.cmdvel import cmd_vel_type, twist_of
from simbridge.sim import World


__all__ = ["Safety"]

logger = logging.getLogger(__name__)


def _finite_command(msg: Any) -> bool:
    try:
        twist = twist_of(msg)
        return finite_number(twist["linear"]["x"]) and finite_number(twist["angular"]["z"])
    except (KeyError, TypeError):
        return False


class Safety(PeerWatcher):
    """Stops robots whose commands went stale or whose commanding client left."""

    def __init__(self, graph: Graph, world: World) -> None:
        #: Where the commands are observed.
        self.graph = graph
        #: The robots.
        self.world = world
        #: Monotonic time of each robot's last valid command.
        self.last_command: dict[str, float] = {}
        #: The client whose command each robot follows.
        self.commander: dict[str, Peer] = {}
        #: Robots stopped by the watchdog or a disconnect so far.
        self.stops = 0
        #: Commands since the last tick: robot -> when the latest arrived.
        self._fresh: dict[str, float] = {}
        self._callbacks: dict[str, tuple[str, InternalCallback]] = {}
        self._unwatched: set[str] = set()
        self._follow_robots()

    def forget(self, name: str) -> None:
        """Stop watching a robot that left the world (its ``cmd_vel`` topic may go)."""
        entry = self._callbacks.pop(name, None)
        if entry is not None:
            self.graph.topics.unsubscribe_internal(*entry)
        self.last_command.pop(name, None)
        self.commander.pop(name, None)

    def _follow_robots(self) -> None:
        """Watch the ``cmd_vel`` of robots added to the world; forget removed ones."""
        for name in [n for n in self._callbacks if n not in self.world.robots]:
            self.forget(name)
        for name, robot in self.world.robots.items():
            if name in self._callbacks:
                continue

            def on_cmd_vel(msg: Any, source: Peer | None, name: str = name) -> None:
                if not _finite_command(msg):
                    return  # refused by the robot; it does not count as a command
                self._fresh[name] = self.graph.topics.now
                if source is not None:
                    self.commander[name] = source

            topic = robot.topic("cmd_vel")
            # the robot's own node: the watchdog is part of its driver, as in turtlesim
            kind = cmd_vel_type(world_params(self.world))
            try:
                self.graph.subscribe(topic, kind, ROBOT_NODE, on_cmd_vel)
            except ProtocolError:
                # never let one robot's topic stop the watchdog of the others; the robot
                # itself could not subscribe either (its bridge refused it)
                if name not in self._unwatched:
                    self._unwatched.add(name)
                    logger.exception("safety: cannot watch %s", topic)
                continue
            self._callbacks[name] = (topic, on_cmd_vel)

    def tick(self, now: float) -> None:
        """Stamp this tick's commands and stop robots whose command is stale."""
        if self._callbacks.keys() != self.world.robots.keys():
            self._follow_robots()
        for name, arrived in self._fresh.items():
            self.last_command[name] = arrived
        self._fresh.clear()
        timeout = world_params(self.world).safety.cmd_vel_timeout
        if timeout <= 0:
            return
        for name, robot in self.world.robots.items():
            if not (robot.cmd_v or robot.cmd_omega):
                continue
            last = self.last_command.setdefault(name, now)  # commanded some other way: start now
            if now - last > timeout:
                self._stop(name, f"no /cmd_vel for {timeout:g} s (safety.cmd_vel_timeout)")

    def peer_lost(self, peer: Peer) -> None:
        """Stop the robots ``peer`` commanded, when ``safety.stop_on_lost_link`` is on."""
        if not world_params(self.world).safety.stop_on_lost_link:
            return
        for name in [name for name, p in self.commander.items() if p is peer]:
            robot = self.world.robots.get(name)
            if robot is not None and (robot.cmd_v or robot.cmd_omega):
                why = f"its commanding {peer.label} was lost (gone without closing its connection)"
                self._stop(name, why)

    def peer_left(self, peer: Peer) -> None:
        """Stop the robots that ``peer`` commanded, when ``safety.stop_on_disconnect`` is on."""
        mine = [name for name, p in self.commander.items() if p is peer]
        for name in mine:
            del self.commander[name]
        if not world_params(self.world).safety.stop_on_disconnect:
            return
        for name in mine:
            robot = self.world.robots.get(name)
            if robot is not None and (robot.cmd_v or robot.cmd_omega):
                self._stop(name, f"its commanding {peer.label} disconnected")

    def _stop(self, name: str, why: str) -> None:
        self.world.command(name, 0.0, 0.0)
        self.stops += 1
        shown = name or "the robot"
        self.graph.log("warn", f"safety: stopped {shown}: {why}")
