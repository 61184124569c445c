"""Who may do what on the bridge: authentication, scopes, per-client limits, admin services.

A :class:`Guard` sits in front of :meth:`Graph.dispatch <simbridge.graph.Graph.dispatch>` as a
gate: every op of a client passes it before it is carried out. It refuses, with a ``status``
error to that client only (a failed ``service_response`` for ``call_service``):

* every op but ``auth`` from a client that has not authenticated, when authentication is on
  (``client_tokens`` or ``auth_secret``; see ``docs/security.md``);
* publishing, advertising (topics, services, actions) outside the client's scope: a client
  whose token maps to robot ``r1`` may publish only under ``/r1/``, and may not call services
  or send goals under another robot's namespace;
* calls to administrative services (:attr:`Graph.admin_services`) unless the client presented
  the admin token (when one is set);
* advertising a service that the server itself provides (it would hijack it for everyone);
* more subscriptions or advertisements than the per-client limits, and publishes above the
  per-client rate (a token bucket). Rate refusals are told at most once a second.

Authentication, either way:

* a token as the query parameter of the WebSocket URL (``ws://host:9090/?token=T``), checked
  before the upgrade (see :func:`token_access`);
* the rosbridge ``auth`` op with a rosauth MAC: the lowercase hex SHA-512 of
  ``secret + client + dest + rand + t + level + end`` (``t`` and ``end`` as decimal seconds),
  accepted when ``|t - now| < auth_time_delta`` and ``end > now`` (rosauth's
  ``ros_mac_authentication``). Its ``level`` is the scope (``"admin"`` gives admin rights and
  every topic). A failed ``auth`` closes the connection, as ROS 1 rosbridge does.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
from collections.abc import Callable, Iterable
from typing import Any

from simbridge.config import ServerSettings
from simbridge.errors import ProtocolError
from simbridge.graph.graph import Graph
from simbridge.graph.topics import Peer
from simbridge.protocol import (
    ANY_SCOPE,
    NOT_AUTHENTICATED,
    Op,
    Refusal,
    Session,
    TokenBucket,
    ops as o,
    status_frame,
)


__all__ = [
    "ADMIN_SCOPE",
    "ANY_SCOPE",
    "DEFAULT_ADMIN_SERVICES",
    "MIN_FRAGMENT_SIZE",
    "Guard",
    "TokenBucket",
    "rosauth_mac",
    "token_access",
]

logger = logging.getLogger(__name__)

#: The rosauth ``level`` (and token scope) of an administrator.
ADMIN_SCOPE = "admin"
#: Smallest ``fragment_size`` accepted (smaller ones would cost a message per few bytes).
MIN_FRAGMENT_SIZE = 256
#: Services that change the world or the server for everyone.
DEFAULT_ADMIN_SERVICES = frozenset(
    {
        "/reset",
        "/rosapi/set_param",
        "/rosapi/delete_param",
        "/spawn",
        "/kill",
        "/sim/pause",
        "/sim/step",
        "/sim/set_real_time_factor",
    }
)
#: Name endings of administrative services of any node (ROS 2 parameter services).
ADMIN_SUFFIXES = ("/set_parameters", "/set_parameters_atomically")


def rosauth_mac(
    secret: str, client: str, dest: str, rand: str, t: int, level: str, end: int
) -> str:
    """Return the rosauth MAC of an ``auth`` op: hex SHA-512 of the fields concatenated."""
    text = f"{secret}{client}{dest}{rand}{t}{level}{end}"
    return hashlib.sha512(text.encode("utf-8")).hexdigest()


def token_access(settings: ServerSettings, token: str | None) -> tuple[str, bool] | None:
    """Return ``(scope, admin)`` granted by a connection token, or ``None`` if it grants none.

    The admin token grants every topic and admin rights; a client token its mapped scope.
    """
    if not token:
        return None
    admin = settings.admin_token
    if admin and hmac.compare_digest(token.encode(), admin.encode()):
        return ANY_SCOPE, True
    for known, scope in settings.client_tokens.items():
        if hmac.compare_digest(token.encode(), known.encode()):
            return (ANY_SCOPE, True) if scope == ADMIN_SCOPE else (scope, False)
    return None


def in_namespace(scope: str, name: str) -> bool:
    """Return whether the absolute name ``name`` lies in the scope's namespace."""
    return scope == ANY_SCOPE or name == f"/{scope}" or name.startswith(f"/{scope}/")


class Guard:
    """The gate in front of the graph (install once per :class:`Graph`)."""

    def __init__(
        self,
        graph: Graph,
        settings: ServerSettings,
        *,
        robots: Callable[[], Iterable[str]] = lambda: (),
        wall_time: Callable[[], float] | None = None,
    ) -> None:
        #: The graph guarded.
        self.graph = graph
        #: Limits and secrets.
        self.settings = settings
        #: Names of the robots (their namespaces are off limits to other robots' clients).
        self.robots = robots
        self._wall_time = wall_time or (lambda: graph.wall_clock_ns() / 1e9)
        graph.admin_services.update(DEFAULT_ADMIN_SERVICES)
        graph.gates.append(self.gate)
        graph.on_connect.append(self.connect)
        graph.handlers[o.Auth] = self._auth

    # -- access ----------------------------------------------------------------------------

    def connect(self, peer: Peer) -> None:
        """Give a new client its access from its connection token (``session.extra``)."""
        s = self.settings
        session = peer.session
        token = session.extra.get("token")
        granted = token_access(s, token if isinstance(token, str) else None)
        if granted is not None:
            scope, admin = granted
        else:
            scope, admin = ANY_SCOPE, False
        # without an admin token, administration is open to whoever may use every topic
        admin = admin or (s.admin_token is None and scope == ANY_SCOPE)
        session.admit(scope, admin)
        session.guarded = True
        if granted is None and s.auth_required:
            session.authenticated = False  # only auth is read until it succeeds

    def access(self, peer: Peer) -> Session:
        """Return the session of ``peer``: its access (scope, admin, rate) lives there."""
        return peer.session

    # -- the gate -------------------------------------------------------------------------

    def gate(self, peer: Peer, op: Op, now: float) -> bool:
        """Return whether ``op`` may be carried out; refuse it (and tell the client) if not.

        Raises:
            Refusal: the op is refused (the graph answers the client).
        """
        session = peer.session
        if not session.authenticated and not isinstance(op, o.Auth):
            raise Refusal(NOT_AUTHENTICATED, cause="unauthenticated")
        size = getattr(op, "fragment_size", None)
        if size is not None and size < MIN_FRAGMENT_SIZE:
            msg = (
                f"fragment_size {size} is too small: at least {MIN_FRAGMENT_SIZE} bytes "
                "(tiny fragments multiply the server's work)"
            )
            raise Refusal(msg, cause="fragment_size")
        check = self._checks.get(type(op))
        return True if check is None else check(self, peer, session, op, now)

    def _may_own(self, session: Session, what: str, name: str, new: bool) -> None:
        if not in_namespace(session.scope, name):
            msg = (
                f"{what} {name}: not allowed; this connection may only use names under "
                f"/{session.scope}/ (its robot)"
            )
            raise Refusal(msg, cause=f"scope {what}")
        session.may_own(what, name, new)

    def _may_reach(self, session: Session, name: str) -> bool:
        """Whether a call or goal to ``name`` stays out of other robots' namespaces."""
        if session.scope == ANY_SCOPE:
            return True
        return not any(
            robot and robot != session.scope and in_namespace(robot, name)
            for robot in self.robots()
        )

    def _publish(self, peer: Peer, session: Session, op: o.Publish, now: float) -> bool:
        if not session.publishes.take(now):
            s = self.settings
            text = (
                f"publish {op.name}: dropped, more than {s.publish_rate:g} publishes per second "
                f"(the server's publish_rate, burst {s.publish_burst}); slow down"
            )
            if session.may_tell("publish_rate", now):
                logger.info("%s: %s", peer.label, text)
                if session.wants_status("error"):
                    peer.send(status_frame("error", text))
            return False
        self._may_own(session, "publish", op.name, op.name not in session.advertisements)
        return True

    def _advertise(self, peer: Peer, session: Session, op: o.Advertise, now: float) -> bool:
        self._may_own(session, "advertise", op.name, op.name not in session.advertisements)
        return True

    def _subscribe(self, peer: Peer, session: Session, op: o.Subscribe, now: float) -> bool:
        if op.type and session.scope != ANY_SCOPE:
            # a typed subscription fixes the type of a topic nobody publishes yet: outside its
            # own namespace that would squat a name (a robot spawned later could not take it)
            name = op.name
            topic = self.graph.topics.topics.get(name)
            if not in_namespace(session.scope, name) and (topic is None or topic.type is None):
                msg = (
                    f"subscribe {name}: refused with a type, the topic is outside "
                    f"/{session.scope}/ and nothing publishes it yet (the type would claim the "
                    "name); subscribe without a type and it waits for the topic"
                )
                raise Refusal(msg, cause="typed subscribe outside scope")
        return True

    def _advertise_service(
        self, peer: Peer, session: Session, op: o.AdvertiseService, now: float
    ) -> bool:
        existing = self.graph.services.services.get(op.name)
        if existing is not None and existing.handler is not None:
            msg = (
                f"advertise_service {op.name}: refused, the server provides this service "
                "itself; choose another name"
            )
            raise Refusal(msg, cause="server service")
        self._may_own(session, "advertise_service", op.name, op.name not in session.services)
        return True

    def _advertise_action(
        self, peer: Peer, session: Session, op: o.AdvertiseAction, now: float
    ) -> bool:
        self._may_own(session, "advertise_action", op.name, op.name not in session.actions)
        return True

    def _call_service(self, peer: Peer, session: Session, op: o.CallService, now: float) -> bool:
        name = op.name
        admin_only = name in self.graph.admin_services or name.endswith(ADMIN_SUFFIXES)
        if admin_only and not session.admin:
            reason = (
                f"service {name} is administrative: connect with the admin token "
                "(?token=ADMIN_TOKEN) to call it"
            )
        elif not self._may_reach(session, name):
            reason = f"service {name} belongs to another robot; this connection may not call it"
        else:
            return True
        logger.info("%s: %s", peer.label, reason)
        raise Refusal(reason, op="call_service", target=op.service, op_id=op.id)

    def _send_action_goal(
        self, peer: Peer, session: Session, op: o.SendActionGoal, now: float
    ) -> bool:
        if not self._may_reach(session, op.name):
            msg = f"action {op.name} belongs to another robot; this connection may not use it"
            raise Refusal(msg, op="send_action_goal", target=op.action, op_id=op.id)
        return True

    _checks: dict[type, Callable[[Any, Peer, Session, Any, float], bool]] = {
        o.Publish: _publish,
        o.Advertise: _advertise,
        o.Subscribe: _subscribe,
        o.AdvertiseService: _advertise_service,
        o.AdvertiseAction: _advertise_action,
        o.CallService: _call_service,
        o.SendActionGoal: _send_action_goal,
    }

    # -- the auth op ---------------------------------------------------------------------

    def _auth(self, peer: Peer, op: o.Auth, now: float) -> None:
        session = peer.session
        secret = self.settings.auth_secret
        if secret is None:
            msg = "auth: this server takes no rosauth MAC; connect with ?token=YOUR_TOKEN"
            raise ProtocolError(msg)
        wall = self._wall_time()
        delta = self.settings.auth_time_delta
        expected = rosauth_mac(secret, op.client, op.dest, op.rand, op.t, op.level, op.end)
        fresh = abs(op.t - wall) < delta and op.end > wall
        if not (fresh and hmac.compare_digest(expected, op.mac.lower())):
            why = "expired or clock skew" if not fresh else "wrong MAC"
            logger.warning("%s failed authentication (%s)", peer.label, why)
            if peer.session.wants_status("error"):
                peer.send(status_frame("error", f"auth: authentication failed ({why})"))
            close = getattr(peer, "close_soon", None)
            if callable(close):
                close(1008, "authentication failed")
            return
        if op.level == ADMIN_SCOPE:
            session.admit(ANY_SCOPE, True)
        elif op.level and op.level in set(self.robots()):
            session.admit(op.level, False)
        else:  # "user" and other rosauth levels: every topic, admin only without admin token
            session.admit(ANY_SCOPE, self.settings.admin_token is None)
        logger.info("%s authenticated (scope %s)", peer.label, session.scope)
        if session.wants_status("info"):
            peer.send(status_frame("info", f"auth: authenticated, scope {session.scope}"))
