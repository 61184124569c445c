"""Wiring of simbridge's protections into one process (see ``docs/security.md``).

:func:`install_security` puts the :class:`~simbridge.graph.guard.Guard` in front of the graph,
and the :class:`~simbridge.graph.safety.Safety` watchdog on the loop. The admin page's HTTP API
checks the admin token itself (:mod:`simbridge.admin`). The WebSocket-level protections
(origins, TLS, client count, stalls, message rate) live in :mod:`simbridge.server`.
"""

from __future__ import annotations

import ipaddress
import logging
from typing import TYPE_CHECKING

from simbridge.graph.guard import Guard
from simbridge.graph.safety import Safety


if TYPE_CHECKING:
    from simbridge.runner import App


__all__ = ["install_security"]

logger = logging.getLogger(__name__)


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
    app.bridge.on_robot_removed.append(safety.forget)
    if s.admin_token is None and not _loopback(s.host):
        logger.warning(
            "no admin token: anyone who can reach %s may reset the world and change parameters "
            "(set --admin-token or SIMBRIDGE_ADMIN_TOKEN)",
            s.host,
        )
    return guard, safety
