"""Who a peer of the graph is, and the access rules every front end admits its peers by.

A peer of any front end (a rosbridge client, a ROS 2 node over Zenoh, a Foxglove client) has
an :class:`Access`: a scope (``"*"``, every name, or a robot's name, its namespace only), admin
rights, and whether it has authenticated yet. The graph's :class:`AccessRules` decide by name
what a peer may do, the same way for every front end:

* **publish, advertise, provide** a topic, service or action: only within the peer's scope
  (:meth:`AccessRules.publish_refusal`);
* **call** a service or send a goal: not another robot's (a peer scoped to ``r1`` reaches no
  name under ``/r2/``), and administrative services (:attr:`AccessRules.admin_services`, and
  every node's ``set_parameters``) need admin rights (:meth:`AccessRules.reach_refusal`).

The rules apply once something authenticates the peers (``guarded``, set by the composition
root's guard); a graph without one trusts every peer. Who grants which access (tokens, rosauth,
the ROS 2 role) is decided outside the graph, by the application's guard.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field


__all__ = [
    "ADMIN_SUFFIXES",
    "ANY_SCOPE",
    "NO_ROBOT",
    "Access",
    "AccessRules",
    "TokenBucket",
    "in_namespace",
]

#: The scope of a peer that may use every name.
ANY_SCOPE = "*"
#: The scope of a peer that may drive no robot (a ROS 2 peer in class mode): not a robot name,
#: so no name lies in its namespace.
NO_ROBOT = "-"
#: Name endings of administrative services of any node (ROS 2 parameter services).
ADMIN_SUFFIXES = ("/set_parameters", "/set_parameters_atomically")


def in_namespace(scope: str, name: str) -> bool:
    """Return whether the absolute name ``name`` lies in the scope's namespace."""
    return scope == ANY_SCOPE or name == f"/{scope}" or name.startswith(f"/{scope}/")


@dataclass(slots=True)
class Access:
    """What one peer may do, as its front end's guard decided it."""

    #: ``"*"`` (every name) or a robot name (its namespace only).
    scope: str = ANY_SCOPE
    #: The peer may call administrative services.
    admin: bool = False
    #: The peer is admitted (else its front end reads nothing but its credentials).
    authenticated: bool = True
    #: A guard gave this access (a graph without one trusts every peer).
    guarded: bool = False
    #: The token the peer connected with, if any (the e-stops and the grader key by it).
    token: str | None = None
    #: Process-unique number of the peer (its front end numbers its connections).
    peer_id: int = 0


@dataclass(slots=True)
class AccessRules:
    """The graph's rules, by name, for the peers of every front end."""

    #: The rules apply (a guard authenticates the peers).
    guarded: bool = False
    #: Services that need admin rights.
    admin_services: set[str] = field(default_factory=set)
    #: Names of the robots: their namespaces are off limits to other robots' peers.
    robots: Callable[[], Iterable[str]] = lambda: ()

    def admin_only(self, name: str) -> bool:
        """Return whether calling service ``name`` needs admin rights."""
        return name in self.admin_services or name.endswith(ADMIN_SUFFIXES)

    def may_reach(self, access: Access, name: str) -> bool:
        """Whether a call or goal to ``name`` stays out of other robots' namespaces."""
        if access.scope == ANY_SCOPE:
            return True
        return not any(
            robot and robot != access.scope and in_namespace(robot, name) for robot in self.robots()
        )

    def publish_refusal(self, access: Access, name: str) -> str | None:
        """Return why a peer may not publish on (or provide) ``name``; None if it may."""
        if not self.guarded or in_namespace(access.scope, name):
            return None
        if access.scope == NO_ROBOT:
            return f"{name}: not allowed; this peer may drive no robot and publishes nothing here"
        return f"{name}: not allowed; this peer may only use names under /{access.scope}/"

    def reach_refusal(self, access: Access, name: str) -> str | None:
        """Return why a peer may not call service or action ``name``; None if it may."""
        if not self.guarded:
            return None
        if self.admin_only(name) and not access.admin:
            return f"{name} is administrative: this peer has no admin rights"
        if not self.may_reach(access, name):
            return f"{name} belongs to another robot; this peer may not use it"
        return None


@dataclass(slots=True)
class TokenBucket:
    """``rate`` events per second sustained, ``burst`` at once (monotonic seconds)."""

    rate: float
    burst: float
    tokens: float = math.nan
    last: float = -math.inf

    def take(self, now: float, cost: float = 1.0) -> bool:
        """Spend ``cost`` tokens if there are enough; return whether the event may go on."""
        self.refill(now)
        if self.tokens >= cost:
            self.tokens -= cost
            return True
        return False

    def refill(self, now: float) -> None:
        """Add the tokens earned since the last call."""
        if math.isnan(self.tokens):
            self.tokens = self.burst
        elif now > self.last:
            self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = max(self.last, now)

    def charge(self, now: float, cost: float) -> float:
        """Spend ``cost`` tokens even into debt; return seconds until the balance is positive."""
        self.refill(now)
        self.tokens -= cost
        return 0.0 if self.tokens >= 0 else -self.tokens / self.rate

    def owed(self, now: float) -> float:
        """Return seconds until the balance is positive again (0: it is; nothing is spent).

        A bucket shared by several spenders (one token's connections) may have been charged by
        the others while one waited: it asks again before it spends.
        """
        self.refill(now)
        return 0.0 if self.tokens >= 0 else -self.tokens / self.rate
