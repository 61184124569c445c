"""Who a client is: authentication, and the access each connection gets.

A :class:`Guard` authenticates the peers of a :class:`~simbridge.graph.Graph`, whatever their
front end, and gives each its :class:`~simbridge.graph.access.Access`: a scope (``"*"``, every
topic, or a robot's name, its namespace only) and admin rights. It turns on the graph's access
rules (:class:`~simbridge.graph.access.AccessRules`), which every front end applies to its
peers; rosbridge's :class:`~simbridge.rosbridge.admission.Admission` applies them to every op
with the type and payload checks: nothing but ``auth`` before a client has
authenticated (when ``client_tokens`` or ``auth_secret`` is set; see ``docs/security.md``),
names within the client's scope, administrative services (:data:`DEFAULT_ADMIN_SERVICES`) for
admin rights only, the per-client publish rate.

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

from simbridge.app.settings import ServerSettings
from simbridge.errors import ProtocolError
from simbridge.graph.access import ANY_SCOPE, NO_ROBOT, Access
from simbridge.graph.graph import Graph, PeerWatcher
from simbridge.graph.topics import Peer
from simbridge.rosbridge import ops as o


__all__ = [
    "ADMIN_SCOPE",
    "ANY_SCOPE",
    "DEFAULT_ADMIN_SERVICES",
    "NO_ROBOT",
    "Guard",
    "rosauth_mac",
    "token_access",
]

logger = logging.getLogger(__name__)

#: The rosauth ``level`` (and token scope) of an administrator.
ADMIN_SCOPE = "admin"
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
        "/simbridge/motion_model",
        "/simbridge/robot_params",
    }
)


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


class Guard(PeerWatcher):
    """Authentication and access of a graph's clients (one per :class:`Graph`).

    :func:`simbridge.app.build.guard_graph` puts it in front of the graph: it turns on the
    graph's access rules and has the graph tell the guard of each new peer.
    """

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

    # -- access ----------------------------------------------------------------------------

    def peer_connected(self, peer: Peer) -> None:
        """Give a new peer its access from its connection token (``access.token``)."""
        s = self.settings
        access = peer.access
        granted = token_access(s, access.token)
        if granted is not None:
            scope, admin = granted
        else:
            scope, admin = ANY_SCOPE, False
        # without an admin token, administration is open to whoever may use every topic
        admin = admin or (s.admin_token is None and scope == ANY_SCOPE)
        # without a token where one is required, only auth is read until it succeeds
        access.guarded = True
        access.scope, access.admin = scope, admin
        access.authenticated = granted is not None or not s.auth_required

    # -- the auth op ---------------------------------------------------------------------

    def auth(self, peer: Peer, op: o.Auth, now: float) -> tuple[str, str]:
        """Check a rosbridge ``auth`` op; admit ``peer`` or not; return the status to send.

        Raises:
            ProtocolError: this server takes no rosauth MAC.
        """
        access = peer.access
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
            return "error", f"auth: authentication failed ({why})"
        if op.level == ADMIN_SCOPE:
            _admit(access, ANY_SCOPE, True)
        elif op.level and op.level in set(self.robots()):
            _admit(access, op.level, False)
        else:  # "user" and other rosauth levels: every topic, admin only without admin token
            _admit(access, ANY_SCOPE, self.settings.admin_token is None)
        logger.info("%s authenticated (scope %s)", peer.label, access.scope)
        return "info", f"auth: authenticated, scope {access.scope}"


def _admit(access: Access, scope: str, admin: bool) -> None:
    access.authenticated = True
    access.scope, access.admin = scope, admin
