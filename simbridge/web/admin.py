"""The instructor's ``/admin``: token check, and the JSON API the admin page calls.

Every request to ``/api/admin/*`` needs the admin token (``--admin-token`` or
``SIMBRIDGE_ADMIN_TOKEN``), sent as ``Authorization: Bearer <token>`` (or ``X-Admin-Token``).
Without a configured token every request is refused: admin is off by default.

=========================  ======  ==========================================================
path                       method  what it does
=========================  ======  ==========================================================
``/api/admin/state``       GET     clients, parameters with descriptions (and the read-only
                                  ones), motion models, e-stop
``/api/admin/params``      POST    ``{"changes": {"robot.mass": 3.0}}``: all or nothing
``/api/admin/motion``      POST    ``{"model": "dynamic"}`` (or ``"kinematic"``)
``/api/admin/reset``       POST    every robot back to its start pose, stopped
=========================  ======  ==========================================================

:func:`check_admin_token` is the one place the token is compared (constant time); other
administrative entry points (services, CLI) reuse it.
"""

from __future__ import annotations

import hmac
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

import orjson

from simbridge.config import ServerSettings
from simbridge.errors import ServiceError, SimbridgeError
from simbridge.graph import ROBOT_NODE, Graph
from simbridge.sim import KinematicModel, MotionModel, World
from simbridge.sim.dynamics import DynamicModel
from simbridge.web.http import HttpRequest, HttpResponse, WebApp


if TYPE_CHECKING:
    from simbridge.server import Client


__all__ = [
    "MOTION_MODELS",
    "AdminRefused",
    "check_admin_token",
    "install_admin",
    "token_from_headers",
]

#: Motion models the instructor can switch between, by name.
MOTION_MODELS: dict[str, Callable[[], MotionModel]] = {
    "kinematic": KinematicModel,
    "dynamic": DynamicModel,
}


class AdminRefused(SimbridgeError):
    """An administrative request without a valid admin token.

    Attributes:
        status: the HTTP status that fits (401: no token given; 403: wrong token or admin off).
    """

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


def check_admin_token(expected: str | None, presented: str | None) -> None:
    """Allow an administrative change only with the configured token.

    Raises:
        AdminRefused: admin is off (no token configured), no token was presented, or it is wrong.
    """
    if not expected:
        msg = (
            "admin is disabled on this server: start simbridge with --admin-token TOKEN "
            "(or SIMBRIDGE_ADMIN_TOKEN) to allow changes"
        )
        raise AdminRefused(msg, 403)
    if not presented:
        msg = "admin token required (send 'Authorization: Bearer TOKEN')"
        raise AdminRefused(msg, 401)
    if not hmac.compare_digest(expected.encode(), presented.encode()):
        raise AdminRefused("wrong admin token", 403)


def token_from_headers(headers: Mapping[str, str]) -> str | None:
    """Return the token of a request (lower-case header names), or None."""
    auth = headers.get("authorization", "")
    scheme, _, value = auth.partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return headers.get("x-admin-token") or None


def _body(request: HttpRequest) -> dict[str, Any]:
    try:
        value = orjson.loads(request.body or b"{}")
    except orjson.JSONDecodeError as err:
        msg = f"request body is not JSON: {err}"
        raise ServiceError(msg) from None
    if not isinstance(value, dict):
        msg = "request body must be a JSON object"
        raise ServiceError(msg)
    return value


class _Admin:
    def __init__(self, graph: Graph, world: World, clients: Callable[[], Iterable[Client]]) -> None:
        self.graph = graph
        self.world = world
        self.clients = clients

    def state(self) -> dict[str, Any]:
        params = self.graph.params.node(ROBOT_NODE)
        topics = self.graph.topics.topics.values()
        clients = []
        for c in sorted(self.clients(), key=lambda c: c.session.client_id):
            subs = sorted(t.name for t in topics if any(p is c for p, _ in t.subscriptions))
            clients.append(
                {
                    "id": c.session.client_id,
                    "label": c.label,
                    "subscriptions": subs,
                    "publishing": sorted(c.session.advertisements),
                    "frames_sent": c.frames_sent,
                    "queued": len(c.queue),
                    "dropped": c.queue.dropped,
                }
            )
        return {
            "clients": clients,
            "params": params.read(),
            "descriptions": params.descriptions,
            "read_only": sorted(params.read_only),
            "motion_model": self.world.motion.name,
            "motion_models": sorted(MOTION_MODELS),
            "estopped": self.world.estopped,
            "sim_time_s": round(self.world.time, 3),
        }

    def params(self, body: dict[str, Any]) -> dict[str, Any]:
        changes = body.get("changes")
        if not isinstance(changes, dict) or not changes:
            msg = 'expected {"changes": {"robot.mass": 3.0, ...}}'
            raise ServiceError(msg)
        self.graph.params.set(ROBOT_NODE, changes)
        return {"params": self.graph.params.node(ROBOT_NODE).read()}

    def motion(self, body: dict[str, Any]) -> dict[str, Any]:
        name = body.get("model")
        factory = MOTION_MODELS.get(name) if isinstance(name, str) else None
        if factory is None:
            msg = f"unknown motion model {name!r}; choose one of {', '.join(sorted(MOTION_MODELS))}"
            raise ServiceError(msg)
        self.world.motion = factory()
        self.graph.log("info", f"motion model switched to '{name}' by the instructor")
        return {"motion_model": name}

    def reset(self, body: dict[str, Any]) -> dict[str, Any]:
        self.world.reset()
        self.graph.log("info", "world reset by the instructor")
        return {"reset": True}


def install_admin(
    web: WebApp,
    *,
    graph: Graph,
    world: World,
    clients: Callable[[], Iterable[Client]],
    settings: ServerSettings,
) -> None:
    """Add the ``/api/admin/*`` routes to ``web``.

    Args:
        web: where the routes go.
        graph: whose ``/virtual_robot`` parameters and clients the page shows.
        world: what is reset and whose motion model is switched.
        clients: the connected WebSocket clients, when asked.
        settings: whose ``admin_token`` every request must present.
    """
    admin = _Admin(graph, world, clients)
    posts: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
        "/api/admin/params": admin.params,
        "/api/admin/motion": admin.motion,
        "/api/admin/reset": admin.reset,
    }

    def route(request: HttpRequest) -> HttpResponse:
        path = request.path.rstrip("/")
        want = "GET" if path == "/api/admin/state" else "POST"
        if request.method != want:
            response = HttpResponse.json({"error": f"use {want} for {path}"}, 405)
            response.headers["Allow"] = want
            return response
        try:
            check_admin_token(settings.admin_token, token_from_headers(request.headers))
            if path == "/api/admin/state":
                return HttpResponse.json(admin.state())
            return HttpResponse.json(posts[path](_body(request)))
        except AdminRefused as err:
            return HttpResponse.json({"error": str(err)}, err.status)
        except ServiceError as err:
            return HttpResponse.json({"error": str(err)}, 400)

    for path in ("/api/admin/state", *posts):
        web.routes[path] = route
