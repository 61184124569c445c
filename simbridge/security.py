"""Wiring of simbridge's protections into one process (see ``docs/security.md``).

:func:`install_security` puts the :class:`~simbridge.graph.guard.Guard` in front of the graph,
the :class:`~simbridge.graph.safety.Safety` watchdog on the loop, and the admin token in front
of ``/admin``. The WebSocket-level protections (origins, TLS, client count, stalls, message
rate) live in :mod:`simbridge.server`.
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
from typing import TYPE_CHECKING

from simbridge.graph.guard import Guard
from simbridge.graph.safety import Safety
from simbridge.web import HttpRequest, HttpResponse, Route, WebApp


if TYPE_CHECKING:
    from simbridge.runner import App


__all__ = ["ADMIN_PATHS", "admin_token_of", "install_security", "protect_admin"]

logger = logging.getLogger(__name__)

#: HTTP paths that need the admin token.
ADMIN_PATHS = ("/admin", "/admin.html")


def admin_token_of(request: HttpRequest) -> str | None:
    """Return the token a request presents: ``?token=``, or ``Authorization: Bearer``."""
    values = request.query.get("token")
    if values:
        return values[0]
    auth = request.headers.get("authorization", "")
    scheme, _, value = auth.partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


def protect_admin(web: WebApp, token: str) -> None:
    """Make ``/admin`` (whatever serves it) answer 401 without the admin token."""
    for path in ADMIN_PATHS:
        inner: Route | None = web.routes.get(path)

        def guarded(request: HttpRequest, inner: Route | None = inner) -> HttpResponse:
            given = admin_token_of(request)
            if given is None or not hmac.compare_digest(given.encode(), token.encode()):
                response = HttpResponse.text(
                    "the admin page needs the admin token: open /admin?token=ADMIN_TOKEN\n", 401
                )
                response.headers["WWW-Authenticate"] = 'Bearer realm="simbridge admin"'
                return response
            if inner is not None:
                return inner(request)
            return web._static(request)

        web.routes[path] = guarded


def _loopback(host: str) -> bool:
    if host in ("localhost", ""):
        return host == "localhost"
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def install_security(app: App) -> tuple[Guard, Safety]:
    """Install the guard, the safety watchdog and the admin-page check on ``app``."""
    s = app.settings
    guard = Guard(app.graph, s, robots=lambda: app.world.robots.keys())
    safety = Safety(app.graph, app.world)
    app.tick_hooks.append(safety.tick)
    if s.admin_token is not None:
        protect_admin(app.web, s.admin_token)
    elif not _loopback(s.host):
        logger.warning(
            "no admin token: anyone who can reach %s may reset the world and change parameters "
            "(set --admin-token or SIMBRIDGE_ADMIN_TOKEN)",
            s.host,
        )
    return guard, safety
