"""HTTP for simbridge: the page, ``/healthz``, and the instructor's ``/admin`` API.

:mod:`simbridge.web.http` is the HTTP/1.1 server and the :class:`WebApp` that answers on both
ports, :mod:`simbridge.web.pool` its budgets of connections (in all, per address, room kept for
the instructor); :mod:`simbridge.web.admin` makes the ``/api/admin/*`` routes of a running
server, which the application's builder adds to its :class:`WebApp` (import it from there: it
needs the graph and the simulation, which plain HTTP does not).
"""

from __future__ import annotations

from simbridge.web.http import (
    HttpRequest,
    HttpResponse,
    Route,
    WebApp,
    parse_target,
    rosbridge_route,
    serve_http,
)


__all__ = [
    "HttpRequest",
    "HttpResponse",
    "Route",
    "WebApp",
    "parse_target",
    "rosbridge_route",
    "serve_http",
]
