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
``/api/admin/estop``       POST    ``{"action": "latch"}`` (the global e-stop), ``{"action":
                                  "release", "id": 3}`` (one latch, whoever latched it) or
                                  ``{"action": "release_all"}``
``/api/admin/robot``       POST    ``{"robot": "r1", "changes": {"robot.mass": 3.0}}``: that
                                  robot's own values (``null``: back to the shared value);
                                  ``realism.*`` too: that robot's own realism profile
                                  (``{"realism.enabled": true, "realism.slip": 0.1}``)
=========================  ======  ==========================================================

The state lists each client by the robot it may drive and how it connected (``client 7 (r1's
token)``), every latched e-stop with who latched it, each robot's own parameters, and for each
parameter what it affects (``affects``): e.g. mass and inertia matter in the dynamic model only.

The changes to the world go through the graph's services, called as the instructor: the
motion model and a robot's own values through ``/simbridge/motion_model`` and
``/simbridge/robot_params`` (:mod:`simbridge.robot.controls`), the reset through ``/reset``: the
services an admin client of any front end calls, with the same checks and messages.

:func:`check_admin_token` is the one place the token is compared (constant time); other
administrative entry points (services, CLI) reuse it.
"""

from __future__ import annotations

import hmac
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import orjson

from simbridge.app.guard import token_access
from simbridge.app.settings import ServerSettings
from simbridge.errors import ServiceError, SimbridgeError
from simbridge.graph import Graph
from simbridge.graph.access import ANY_SCOPE, Access
from simbridge.graph.params import ParamNode
from simbridge.robot.bridge import ROBOT_NODE
from simbridge.robot.controls import (
    MOTION_MODELS,
    MOTION_SERVICE,
    REALISM_NAMES,
    ROBOT_PARAMS_SERVICE,
    own_values,
)
from simbridge.robot.estop import INSTRUCTOR, EStop, connection_rights, describe_peer
from simbridge.robot.roles import Roles
from simbridge.sim import World
from simbridge.sim.world import PER_ROBOT_PARAMS
from simbridge.web.http import HttpRequest, HttpResponse, Route


if TYPE_CHECKING:
    from simbridge.graph.topics import Peer


__all__ = [
    "MOTION_MODELS",
    "AdminRefused",
    "ClientView",
    "admin_credentials",
    "admin_routes",
    "check_admin_token",
    "token_from_headers",
]

_DYNAMIC = "the dynamic motion model only (the kinematic model ignores it)"
#: What each parameter changes, for the instructor (by dotted name or section prefix).
AFFECTS: dict[str, str] = {
    "robot.mass": _DYNAMIC,
    "robot.inertia": _DYNAMIC,
    "robot.wheel_radius": _DYNAMIC,
    "robot.max_wheel_torque": _DYNAMIC,
    "robot.velocity_gain": _DYNAMIC,
    "robot.wheelbase": "the dynamic motion model (turning torque) and /tf_static wheel frames",
    "robot.max_linear_velocity": "both motion models: /cmd_vel is clamped to it",
    "robot.max_angular_velocity": "both motion models: /cmd_vel is clamped to it",
    "robot.radius": "collisions, LiDAR returns off robots and the drawn footprint (all robots)",
    "robot.cmd_vel_stamped": "the type of every /cmd_vel (startup only)",
    "lidar.": "every robot's /scan",
    "sim.": "the simulation loop",
    "safety.": "the server's safety watchdog",
    "realism.": "robots under a realism profile (realism.enabled): their motion and /odom; "
    "the true pose is on /ground_truth",
}


def affects(name: str) -> str:
    """Return what parameter ``name`` changes, in words ('' when not known)."""
    if name in AFFECTS:
        return AFFECTS[name]
    return next((text for prefix, text in AFFECTS.items() if name.startswith(prefix)), "")


@dataclass(frozen=True, slots=True)
class ClientView:
    """A connected client as the console lists it, in plain values its front end fills in.

    The console reads the rest (subscriptions, robots, name) from the graph's side of
    ``peer``; the composition root makes these from the server's connections, so the page
    imports no front end's types.
    """

    #: The client as a peer of the graph.
    peer: Peer
    #: Its front end's number of the connection.
    id: int
    #: The topics it advertises.
    publishing: tuple[str, ...] = ()
    #: Frames sent to it so far.
    frames_sent: int = 0
    #: Frames waiting in its queue.
    queued: int = 0
    #: Frames dropped from its queue.
    dropped: int = 0


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


#: The robot's parameters without a simulation (``--no-sim``): none.
_NO_ROBOT = ParamNode(ROBOT_NODE, read=dict, write=lambda values: None)


class _Admin:
    def __init__(
        self,
        graph: Graph,
        world: World,
        clients: Callable[[], Iterable[ClientView]],
        estop: EStop | None,
        roles: Roles | None,
    ) -> None:
        self.graph = graph
        self.world = world
        self.clients = clients
        self.estops = estop
        self.roles = roles

    def state(self) -> dict[str, Any]:
        """The console's document, in one pass over what it reports.

        Each subscription, client and robot is visited a bounded number of times (the topics'
        subscriptions once, grouped by client; the clients once, grouped by robot), so the cost
        grows with the size of the answer, never with clients x topics x subscriptions.
        """
        params = self.graph.params.nodes.get(ROBOT_NODE, _NO_ROBOT)
        subscribed: dict[object, set[str]] = {}
        for topic in self.graph.topics.topics.values():
            for sink in topic.sinks.values():
                for peer in sink.peers():
                    subscribed.setdefault(peer, set()).add(topic.name)
        clients: list[dict[str, Any]] = []
        drivers: dict[str, list[str]] = {}
        for c in sorted(self.clients(), key=lambda c: c.id):
            peer = c.peer
            robots = self.roles.robots_of(peer) if self.roles is not None else []
            any_robot = connection_rights(peer)[0] == "*"
            name = describe_peer(peer)
            clients.append(
                {
                    "id": c.id,
                    "label": peer.label,
                    "name": name,
                    "robots": robots,
                    "any_robot": any_robot,
                    "subscriptions": sorted(subscribed.get(peer, ())),
                    "publishing": sorted(c.publishing),
                    "frames_sent": c.frames_sent,
                    "queued": c.queued,
                    "dropped": c.dropped,
                }
            )
            if not any_robot:
                for robot_name in robots:
                    drivers.setdefault(robot_name, []).append(name)
        values = params.read()
        robot_rows: dict[str, dict[str, Any]] = {}
        for name, robot in sorted(self.world.robots.items()):
            s = robot.state
            robot_rows[name] = {
                "own": own_values(robot),
                "pose": [round(s.x, 3), round(s.y, 3), round(s.theta, 3)],
                "held": self.world.halted(name),
                "clients": drivers.get(name, []),
            }
        return {
            "clients": clients,
            "params": values,
            "descriptions": params.descriptions,
            "affects": {name: affects(name) for name in values},
            "read_only": sorted(params.read_only),
            "per_robot": sorted(f"robot.{n}" for n in PER_ROBOT_PARAMS) + sorted(REALISM_NAMES),
            "robots": robot_rows,
            "motion_model": self.world.motion.name,
            "motion_models": sorted(MOTION_MODELS),
            "estopped": self.world.estopped,
            "estops": [latch.summary() for latch in self.estops.latches.values()]
            if self.estops is not None
            else [],
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
        """Switch the motion model through the graph's ``/simbridge/motion_model``."""
        answer = self._call(MOTION_SERVICE, {"name": body.get("model"), "value": ""})
        return dict(orjson.loads(answer["reason"]))

    def estop(self, body: dict[str, Any]) -> dict[str, Any]:
        estop = self.estops
        if estop is None:
            msg = "this server has no e-stop (it runs without a simulation)"
            raise ServiceError(msg)
        action = body.get("action")
        if action == "latch":
            latch = estop.latch_global(INSTRUCTOR)
            return {"latched": latch.summary()}
        if action == "release":
            latch_id = body.get("id")
            if not isinstance(latch_id, int) or isinstance(latch_id, bool):
                msg = 'expected {"action": "release", "id": N} with the id of a latched e-stop'
                raise ServiceError(msg)
            return {"released": [estop.release_latch(latch_id).summary()]}
        if action == "release_all":
            released = [estop.release_latch(i).summary() for i in list(estop.latches)]
            return {"released": released}
        msg = (
            f"unknown e-stop action {action!r}; use 'latch', 'release' (with an id) "
            "or 'release_all'"
        )
        raise ServiceError(msg)

    def robot(self, body: dict[str, Any]) -> dict[str, Any]:
        """Set one robot's own values through the graph's ``/simbridge/robot_params``."""
        request = {"name": body.get("robot"), "value": orjson.dumps(body.get("changes")).decode()}
        answer = self._call(ROBOT_PARAMS_SERVICE, request)
        return dict(orjson.loads(answer["reason"]))

    def reset(self, body: dict[str, Any]) -> dict[str, Any]:
        """Reset the world through the graph's ``/reset``: the one reset every client calls."""
        self._call("/reset", {})
        self.graph.log("info", "world reset by the instructor")
        return {"reset": True}

    def _call(self, name: str, request: dict[str, Any]) -> Any:
        """Call the graph's service ``name`` as the instructor; return its response.

        Raises:
            ServiceError: there is no such service (no simulation) or it refused the request.
        """
        service = self.graph.services.services.get(name)
        if service is None:
            msg = f"this server has no {name} (it runs without a simulation)"
            raise ServiceError(msg)
        answers: list[tuple[bool, Any]] = []
        self.graph.services.call(
            _INSTRUCTOR_PEER, service, request, 0.0, lambda ok, values: answers.append((ok, values))
        )
        ok, values = answers[0] if answers else (False, f"{name} did not answer")
        if not ok:
            raise ServiceError(str(values))
        return values


class _Instructor:
    """The instructor at /admin, as a caller of the graph's services."""

    label = INSTRUCTOR

    def __init__(self) -> None:
        self.access = Access(ANY_SCOPE, admin=True, guarded=True)


#: The instructor as a peer of the graph (its label and access are all the graph reads).
_INSTRUCTOR_PEER: Peer = _Instructor()


def connection_check(
    settings: ServerSettings, clients: Callable[[], Iterable[ClientView]], request: HttpRequest
) -> HttpResponse:
    """``GET /api/access?token=T``: why a WebSocket upgrade would be refused, for a page.

    A browser learns nothing from a refused upgrade (the HTTP 401 or 503 is hidden from
    scripts: the socket just closes), so a page that could not connect asks here, on the
    WebSocket port or the HTTP port, and says why in words: ``token`` is ``"accepted"``,
    ``"refused"`` or ``"none"``; ``token_required`` whether a connection needs one; ``full``
    whether ``max_clients`` are connected. It tells nothing the upgrade does not (a refused
    token is refused there too). Readable from the page's origin (CORS, within
    ``allowed_origins``).
    """
    s = settings
    connected = len(list(clients()))
    token = (request.query.get("token") or [""])[0]
    granted = token_access(s, token) if token else None
    body = {
        "server": "simbridge",
        "token": "none" if not token else ("refused" if granted is None else "accepted"),
        "token_required": s.auth_required,
        "full": connected >= s.max_clients,
        "clients": connected,
        "max_clients": s.max_clients,
    }
    response = HttpResponse.json(body)
    origin = request.headers.get("origin")
    if origin and (s.allowed_origins is None or origin in s.allowed_origins):
        response.headers["Access-Control-Allow-Origin"] = origin
        response.headers["Vary"] = "Origin"
    response.headers["Cache-Control"] = "no-store"
    return response


def admin_routes(
    *,
    graph: Graph,
    world: World,
    clients: Callable[[], Iterable[ClientView]],
    settings: ServerSettings,
    estop: EStop | None,
    roles: Roles | None,
) -> dict[str, Route]:
    """Return the ``/api/admin/*`` routes (and ``/api/access``), by path.

    The builder adds them to the page's :class:`~simbridge.web.http.WebApp`, with
    :func:`admin_credentials` as its ``privileged``.

    Args:
        graph: whose ``/virtual_robot`` parameters and clients the page shows.
        world: what is reset and whose motion model is switched.
        clients: the connected WebSocket clients, when asked (plain records).
        settings: whose ``admin_token`` every request must present.
        estop: the e-stops the console lists, latches and releases (None: ``--no-sim``).
        roles: what each client may drive (the clients' list names their robots; None:
            ``--no-sim``, no robot here).
    """
    admin = _Admin(graph, world, clients, estop, roles)
    posts: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
        "/api/admin/params": admin.params,
        "/api/admin/motion": admin.motion,
        "/api/admin/reset": admin.reset,
        "/api/admin/estop": admin.estop,
        "/api/admin/robot": admin.robot,
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

    routes: dict[str, Route] = dict.fromkeys(("/api/admin/state", *posts), route)
    routes["/api/access"] = lambda request: connection_check(settings, clients, request)
    return routes


def admin_credentials(settings: ServerSettings) -> Callable[[Mapping[str, str]], bool]:
    """Return whether a request's headers carry the admin token (``WebApp.privileged``).

    A request whose headers carry it is the instructor's: the HTTP server makes room for it
    whatever fills its pool (:mod:`simbridge.web.pool`).
    """

    def privileged(headers: Mapping[str, str]) -> bool:
        token, expected = token_from_headers(headers), settings.admin_token
        if not expected or not token:
            return False
        return hmac.compare_digest(expected.encode(), token.encode())

    return privileged
