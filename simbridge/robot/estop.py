"""The emergency stop: latches in the server, each with a scope and an owner.

A class shares one world: a student's stop must halt their robot, not everyone's, and only they
(or the instructor) may release it. Services of node ``/virtual_robot`` (std_srvs/srv/Trigger:
empty request, ``{success, message}``; the message says what the call covered):

* ``/estop`` latches a stop of the robots the calling connection may drive: its own robot for a
  client token scoped to a robot, every robot for a connection that may drive any. From an
  administrator (the admin token, or anyone on a server without one) it is the **global**
  stop: every robot, also robots spawned later.
* ``/<robot>/estop`` latches a stop of that robot only (the guard lets a connection call it only
  for a robot it may drive).
* ``/estop/reset`` releases the caller's own latches; an administrator's releases every latch.
  ``/<robot>/estop/reset`` does the same for that robot only. A latch is released by the
  connection that latched it, by a later connection with the same token once that one has gone
  (a page that reconnected), or by an administrator; nothing else releases it: not ``/reset``,
  not a disconnect.

While a robot is held it is still (velocity zero, no coasting, whatever the motion model) and
its ``/cmd_vel`` is ignored. Latched topics (std_msgs/msg/Bool) let a late or reconnecting page
show the truth at once: ``/<robot>/estop/state`` is true while that robot is held, and
``/estop/state`` while any robot is (for the un-namespaced robot of a one-robot world, its own).

The instructor's ``/admin`` lists every latch (who latched it, what it covers, since when) and
releases each (:meth:`EStop.latch_global`, :meth:`EStop.release_latch`).
"""

from __future__ import annotations

import hashlib
import itertools
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from simbridge.app.settings import ServerSettings
from simbridge.errors import ServiceError
from simbridge.graph.access import NO_ROBOT
from simbridge.graph.graph import Graph, PeerWatcher
from simbridge.graph.rosapi import request_fields
from simbridge.graph.services import caller
from simbridge.graph.topics import Peer, Topic
from simbridge.sim import World


__all__ = [
    "ESTOP_RESET_SERVICE",
    "ESTOP_SERVICE",
    "ESTOP_STATE_TOPIC",
    "EStop",
    "Latch",
    "connection_rights",
    "describe_peer",
]

ESTOP_SERVICE = "/estop"
ESTOP_RESET_SERVICE = "/estop/reset"
ESTOP_STATE_TOPIC = "/estop/state"
_NODE = "/virtual_robot"
_BOOL = "std_msgs/msg/Bool"
_TRIGGER = "std_srvs/srv/Trigger"
#: The instructor acting from /admin (no connection).
INSTRUCTOR = "the instructor (/admin)"


def connection_rights(peer: Peer | None) -> tuple[str, bool]:
    """Return ``(scope, admin)`` of a connection: ``"*"`` (any robot) or its robot's name.

    The guard (:mod:`simbridge.app.guard`) gives every client its access on connect; a graph
    without a guard (a test, a tool) trusts everyone.
    """
    if peer is None or not peer.access.guarded:
        return "*", True
    return peer.access.scope, peer.access.admin


def _credential(peer: Peer | None) -> str | None:
    token = None if peer is None else peer.access.token
    return hashlib.sha256(token.encode()).hexdigest() if isinstance(token, str) else None


def describe_peer(peer: Peer) -> str:
    """Name a connection for people: ``client 7 (r1's token)``."""
    scope, admin = connection_rights(peer)
    token = peer.access.token
    if admin and isinstance(token, str):
        what = "admin token"
    elif isinstance(token, str):
        what = f"{scope}'s token" if scope != "*" else "a token for every robot"
    elif admin:
        what = "no token, admin"
    else:
        what = (
            "no token"
            if scope == "*"
            else "no robot"
            if scope == NO_ROBOT
            else f"authenticated for {scope}"
        )
    return f"client {peer.access.peer_id} ({what})"


@dataclass(slots=True)
class Latch:
    """One latched emergency stop."""

    id: int
    #: Who latched it, for people ("client 7 (r1's token)", "the instructor (/admin)").
    by: str
    #: The connection that latched it (its client id), None from /admin.
    owner: int | None
    #: A hash of that connection's token (a reconnected page of the same token may release it).
    credential: str | None
    #: The robots it holds; None: every robot, also robots added later (the global stop).
    robots: frozenset[str] | None
    #: Wall-clock seconds (Unix time) when it was latched.
    since: float

    def covers(self, name: str) -> bool:
        """Whether this latch holds robot ``name``."""
        return self.robots is None or name in self.robots

    def scope_text(self) -> str:
        """What it holds, in words."""
        if self.robots is None:
            return "every robot"
        return ", ".join(n or "(default)" for n in sorted(self.robots)) or "no robot"

    def summary(self) -> dict[str, Any]:
        """The latch as JSON for /admin and ``/simbridge/access``."""
        return {
            "id": self.id,
            "by": self.by,
            "global": self.robots is None,
            "robots": None if self.robots is None else sorted(self.robots),
            "covers": self.scope_text(),
            "since": round(self.since, 3),
        }


class EStop(PeerWatcher):
    """Installs the e-stop services and state topics on ``graph`` for ``world``."""

    def __init__(self, graph: Graph, world: World, settings: ServerSettings | None = None) -> None:
        self.graph = graph
        self.world = world
        #: Latched stops by id.
        self.latches: dict[int, Latch] = {}
        #: Latches past which a stop of robots already held makes no new one.
        self.max_latches = (settings or ServerSettings()).max_estop_latches
        #: Connected peers by client id (to tell whether a latch's connection is still there).
        self.connected: set[int] = set()
        self._ids = itertools.count(1)
        self.state = graph.advertise(ESTOP_STATE_TOPIC, _BOOL, _NODE, latch=True)
        self._robot_state: dict[str, Topic] = {}
        self._shown: dict[str, bool] = {}
        graph.add_service(ESTOP_SERVICE, _TRIGGER, _NODE, lambda args: self._latch(args, None))
        graph.add_service(
            ESTOP_RESET_SERVICE, _TRIGGER, _NODE, lambda args: self._release(args, None)
        )
        for name in list(world.robots):
            self.add_robot(name)
        self.publish()

    # -- peers (Graph.watch) ----------------------------------------------------------------

    def peer_connected(self, peer: Peer) -> None:
        """Count ``peer`` connected (a latch of a connection that left is released by all)."""
        self.connected.add(peer.access.peer_id)

    def peer_left(self, peer: Peer) -> None:
        """Count ``peer`` gone."""
        self.connected.discard(peer.access.peer_id)

    # -- robots ---------------------------------------------------------------------------

    def add_robot(self, name: str) -> None:
        """Give robot ``name`` its ``/<name>/estop`` services and state topic."""
        if not name or name in self._robot_state:
            return
        base = f"/{name}/estop"
        self._robot_state[name] = self.graph.advertise(f"{base}/state", _BOOL, _NODE, latch=True)
        self.graph.add_service(base, _TRIGGER, _NODE, lambda args: self._latch(args, name))
        self.graph.add_service(
            f"{base}/reset", _TRIGGER, _NODE, lambda args: self._release(args, name)
        )
        self.publish()

    def remove_robot(self, name: str) -> None:
        """Remove robot ``name``'s e-stop services and topic, and it from every latch."""
        topic = self._robot_state.pop(name, None)
        if topic is None:
            return
        self.graph.topics.unadvertise(topic.name, _NODE)
        for service in (f"/{name}/estop", f"/{name}/estop/reset"):
            self.graph.services.services.pop(service, None)
        self._shown.pop(name, None)
        for latch in list(self.latches.values()):
            if latch.robots is not None and name in latch.robots:
                latch.robots = latch.robots - {name}
                if not latch.robots:
                    del self.latches[latch.id]
        self._apply()

    # -- state ----------------------------------------------------------------------------

    def held_by(self, name: str) -> list[Latch]:
        """Return the latches holding robot ``name``."""
        return [latch for latch in self.latches.values() if latch.covers(name)]

    def _apply(self) -> None:
        if any(latch.robots is None for latch in self.latches.values()):
            self.world.estop()  # halts every robot at once (again: harmless)
        else:
            self.world.release_estop()
        held: set[str] = set()
        for latch in self.latches.values():
            if latch.robots is not None:
                held |= latch.robots
        self.world.hold(frozenset(held & set(self.world.robots)))
        self.publish()

    def publish(self) -> None:
        """Publish (latch) the state topics that changed."""
        robots = list(self.world.robots)
        anyone = any(self.world.halted(n) for n in robots) or self.world.estopped
        if self._shown.get("") != anyone:
            self._shown[""] = anyone
            self.graph.publish(self.state, {"data": anyone}, 0.0)
        for name, topic in self._robot_state.items():
            value = self.world.halted(name)
            if self._shown.get(name) != value:
                self._shown[name] = value
                self.graph.publish(topic, {"data": value}, 0.0)

    # -- latching and releasing -------------------------------------------------------------

    def _now(self) -> float:
        return self.graph.wall_clock_ns() / 1e9

    def _add(self, latch: Latch) -> Latch:
        self.latches[latch.id] = latch
        self._apply()
        self.graph.log("warn", f"EMERGENCY STOP latched by {latch.by}: {latch.scope_text()} halted")
        return latch

    def latch_global(self, by: str = INSTRUCTOR) -> Latch:
        """Latch the global stop (every robot, also later ones) for ``by``; return it."""
        return self._add(Latch(next(self._ids), by, None, None, None, self._now()))

    def latch_for(self, peer: Peer | None, robot: str | None) -> Latch:
        """Latch a stop for ``peer``: of ``robot``, or of every robot it may drive.

        Latches are counted: a stop ``peer`` has latched already (the same robots) is not
        latched again, its latch is returned; one whose connection has gone and that ``peer``
        may release (a reconnected page of the same token, an administrator) becomes
        ``peer``'s. Past ``max_estop_latches`` latches, a stop of robots that are all held
        already returns a latch that holds them (nothing new is kept, nothing is logged); a
        stop of a robot that is not held always latches.

        Raises:
            ServiceError: ``peer`` may drive no robot (its robot does not exist).
        """
        scope, admin = connection_rights(peer)
        robots: frozenset[str] | None
        if robot is None and admin:
            robots = None
        elif robot is not None:
            robots = frozenset({robot})
        elif scope == "*":
            robots = frozenset(self.world.robots)
        else:
            robots = frozenset({scope}) & frozenset(self.world.robots)
        if robots is not None and not robots and scope == NO_ROBOT:
            msg = f"{ESTOP_SERVICE}: this connection may drive no robot, so it stops none"
            raise ServiceError(msg)
        if robots is not None and not robots:
            msg = f"{ESTOP_SERVICE}: this connection's robot '{scope}' does not exist"
            raise ServiceError(msg)
        kept = self._kept(peer, robots)
        if kept is not None:
            return kept
        if peer is not None and len(self.latches) >= self.max_latches:
            holding = self._holding(robots)
            if holding is not None:
                return holding
        by = INSTRUCTOR if peer is None else describe_peer(peer)
        owner = None if peer is None else peer.access.peer_id
        return self._add(Latch(next(self._ids), by, owner, _credential(peer), robots, self._now()))

    def _kept(self, peer: Peer | None, robots: frozenset[str] | None) -> Latch | None:
        """Return ``peer``'s latch of exactly ``robots``, if it has one (or may take one over)."""
        for latch in self.latches.values():
            if latch.robots != robots:
                continue
            if peer is None:
                if latch.owner is None:
                    return latch
                continue
            client = peer.access.peer_id
            if latch.owner == client:
                return latch
            gone = latch.owner is not None and latch.owner not in self.connected
            if gone and self.may_release(peer, latch):
                # it could release it: it takes it over rather than add one more
                latch.owner, latch.by = client, describe_peer(peer)
                latch.credential = _credential(peer)
                return latch
        return None

    def _holding(self, robots: frozenset[str] | None) -> Latch | None:
        """Return a latch holding ``robots`` if latches hold all of them (None: every robot)."""
        if robots is None:
            return next((latch for latch in self.latches.values() if latch.robots is None), None)
        if not all(self.held_by(name) for name in robots):
            return None
        return self.held_by(min(robots))[0]

    def may_release(self, peer: Peer | None, latch: Latch) -> bool:
        """Whether ``peer`` (None: the instructor) may release ``latch``."""
        if peer is None or connection_rights(peer)[1]:
            return True
        if latch.owner == peer.access.peer_id:
            return True
        gone = latch.owner is not None and latch.owner not in self.connected
        return gone and latch.credential is not None and latch.credential == _credential(peer)

    def release_latch(self, latch_id: int) -> Latch:
        """Release one latch (the instructor, from /admin).

        Raises:
            ServiceError: no such latch.
        """
        latch = self.latches.pop(latch_id, None)
        if latch is None:
            msg = f"no e-stop {latch_id} is latched (it may have been released already)"
            raise ServiceError(msg)
        self._apply()
        self.graph.log("info", f"emergency stop of {latch.by} released by the instructor")
        return latch

    def release_for(self, peer: Peer | None, robot: str | None) -> str:
        """Release what ``peer`` may release (of ``robot`` only, or all); say what happened."""
        released: list[Latch] = []
        for latch in list(self.latches.values()):
            if robot is not None and not latch.covers(robot):
                continue
            if not self.may_release(peer, latch):
                continue
            if robot is None or latch.robots is None or latch.robots == {robot}:
                if robot is not None and latch.robots is None and not self._is_admin(peer):
                    continue
                del self.latches[latch.id]
            else:
                latch.robots = latch.robots - {robot}
            released.append(latch)
        self._apply()
        who = INSTRUCTOR if peer is None else describe_peer(peer)
        if released:
            what = "; ".join(f"{latch.scope_text()} (latched by {latch.by})" for latch in released)
            self.graph.log("info", f"emergency stop released by {who}: {what}")
        return self._release_message(peer, robot, released)

    def _is_admin(self, peer: Peer | None) -> bool:
        return peer is None or connection_rights(peer)[1]

    def _release_message(self, peer: Peer | None, robot: str | None, done: list[Latch]) -> str:
        names: Iterable[str] = [robot] if robot is not None else self._robots_of(peer)
        still = []
        for name in names:
            for latch in self.held_by(name):
                still.append(f"{name or '(default)'} is still held by {latch.by}")
        parts = []
        if done:
            parts.append("released: " + "; ".join(latch.scope_text() for latch in done))
        else:
            parts.append("nothing of this connection's was latched")
        if still:
            parts.append(
                "; ".join(sorted(set(still)))
                + " (only that connection or the instructor can release it)"
            )
        return "; ".join(parts)

    def _robots_of(self, peer: Peer | None) -> list[str]:
        scope, _ = connection_rights(peer)
        if scope == "*":
            return sorted(self.world.robots)
        return [scope] if scope in self.world.robots else []

    # -- services -------------------------------------------------------------------------

    def _latch(self, args: Any, robot: str | None) -> dict[str, Any]:
        service = ESTOP_SERVICE if robot is None else f"/{robot}/estop"
        request_fields(args, (), service)
        peer = caller.get()
        latch = self.latch_for(peer, robot)
        release = ESTOP_RESET_SERVICE if robot is None else f"/{robot}/estop/reset"
        mine = latch.owner == (None if peer is None else peer.access.peer_id)
        if not mine:
            message = (
                f"emergency stop: {latch.scope_text()} is held already by {latch.by} (past "
                f"{self.max_latches} latches, the server's max_estop_latches, a stop of held "
                "robots makes no new latch); only that connection or the instructor releases it"
            )
            return {"success": True, "message": message}
        message = (
            f"emergency stop latched for {latch.scope_text()}"
            + (" (global)" if latch.robots is None else "")
            + f"; call {release} from this connection (or ask the instructor) to release it"
        )
        return {"success": True, "message": message}

    def _release(self, args: Any, robot: str | None) -> dict[str, Any]:
        service = ESTOP_RESET_SERVICE if robot is None else f"/{robot}/estop/reset"
        request_fields(args, (), service)
        message = self.release_for(caller.get(), robot)
        held = (
            self.world.halted(robot)
            if robot is not None
            else any(self.world.halted(n) for n in self._robots_of(caller.get()))
        )
        return {"success": not held, "message": message}
