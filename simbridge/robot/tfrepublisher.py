"""tf2_web_republisher, emulated: the transforms web TF clients ask for, from /tf and /tf_static.

roslibjs' ``TFClient`` (1.x, ``groovyCompatibility: false``) and roslibpy's ``TFClient`` call the
service ``/republish_tfs`` (``tf2_web_republisher_interfaces/srv/RepublishTFs``) and subscribe to
the topic it names (``tf2_web_republisher/TFArray``); roslibjs 2.x ``ROS2TFClient`` sends goals to
the action ``/tf2_web_republisher`` (``tf2_web_republisher_interfaces/action/TFSubscription``)
and reads the feedback; the default ``TFClient`` of roslibjs 1.x (``groovyCompatibility: true``)
and 2.x speaks the node's ROS 1 actionlib interface (``/tf2_web_republisher/goal``,
``/cancel``, ``/status``, ``/feedback``, ``/result``; type ``tf2_web_republisher/
TFSubscriptionAction``), served here too (feedback only to the goal's sender). Either way
simbridge sends, at ``rate`` Hz, each requested
``target_frame <- source_frame`` transform (a ``geometry_msgs/TransformStamped``: header frame
the target, child the source) whenever it moved by more than ``trans_thres`` metres or
``angular_thres`` radians since it was last sent (always the first time). A threshold of zero
or below (either one) sends the transform at every ``rate`` tick, moved or not, as the real
node's ``TFPair::updateNeeded`` does: roslibjs replaces a zero threshold by its default, so a
client that wants every transform passes a negative one.

Frame names are compared without a leading ``/`` (REP-105 names as roslibjs strips them). The
transform tree is the latest transform of each child frame on /tf and /tf_static; a transform
between frames is composed through their common ancestor (once per tick for every request that
asks for the same pair). A republished topic with no subscriber for ``timeout`` is removed, as
the real node does.

What a client can make it do is bounded (``docs/security.md``); a request over a bound is
refused with the reason (a failed ``service_response``, or an ``action_result`` with
``result: false``):

* frame names must be valid strings (no lone UTF-16 surrogates, no NUL); thresholds finite;
  ``rate`` finite and positive, capped at the simulation rate (TF changes no
  faster); a ``timeout`` over ``tf_max_timeout`` is capped to it (``0`` means the default 10 s);
* a client holds at most ``tf_requests_per_client`` requests (goals and republished topics
  together) and at most ``tf_transforms_per_client`` transforms a second (frames times rate);
  the whole class at most ``tf_transforms_total``;
* a client's requests go when it leaves: its goals are cancelled and its republished topics
  removed at once, whatever their ``timeout``.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from simbridge.app.settings import ServerSettings
from simbridge.errors import ServiceError
from simbridge.graph.actions import ABORTED, CANCELED, Goal
from simbridge.graph.graph import PeerWatcher
from simbridge.graph.services import caller
from simbridge.graph.topics import Peer, Topic
from simbridge.msgs.convert import finite_number
from simbridge.robot.actionlib import (
    ABORTED as AL_ABORTED,
    PREEMPTED,
    REJECTED,
    ActionlibGoal,
    ActionlibServer,
)


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = ["REPUBLISHER_NODE", "TfBuffer", "TfRepublisher", "install_tf_republisher"]

REPUBLISHER_NODE = "/tf2_web_republisher"
_ACTION_TYPE = "tf2_web_republisher_interfaces/action/TFSubscription"
_SERVICE_TYPE = "tf2_web_republisher_interfaces/srv/RepublishTFs"
_TOPIC_TYPE = "tf2_web_republisher/msg/TFArray"
_ACTIONLIB_ACTION = "tf2_web_republisher/TFSubscription"

logger = logging.getLogger(__name__)

#: Frames in one request at most (a page asks for a handful).
MAX_FRAMES = 100
#: Length of a frame name at most (characters).
MAX_FRAME_NAME = 256

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Pose = tuple[Vec, Quat]


def _qmul(a: Quat, b: Quat) -> Quat:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _rotate(q: Quat, v: Vec) -> Vec:
    x, y, z, _w = _qmul(_qmul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def _compose(a: Pose, b: Pose) -> Pose:
    """Return a * b: b expressed in a's parent."""
    t = _rotate(a[1], b[0])
    return (a[0][0] + t[0], a[0][1] + t[1], a[0][2] + t[2]), _qmul(a[1], b[1])


def _inverse(a: Pose) -> Pose:
    q = (-a[1][0], -a[1][1], -a[1][2], a[1][3])
    t = _rotate(q, a[0])
    return (-t[0], -t[1], -t[2]), q


_IDENTITY: Pose = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def _strip(frame: str) -> str:
    return frame.lstrip("/")


class TfBuffer:
    """The latest transform of every child frame."""

    def __init__(self) -> None:
        #: child frame -> (parent frame, transform parent <- child).
        self.parents: dict[str, tuple[str, Pose]] = {}

    def add(self, msg: Any) -> None:
        """Take the transforms of a tf2_msgs/TFMessage (canonical dict)."""
        for tf in msg.get("transforms", []):
            t = tf["transform"]["translation"]
            r = tf["transform"]["rotation"]
            pose = ((t["x"], t["y"], t["z"]), (r["x"], r["y"], r["z"], r["w"]))
            self.parents[_strip(tf["child_frame_id"])] = (_strip(tf["header"]["frame_id"]), pose)

    def _to_root(self, frame: str) -> tuple[str, Pose]:
        pose = _IDENTITY
        seen = {frame}
        while frame in self.parents:
            parent, step = self.parents[frame]
            pose = _compose(step, pose)
            frame = parent
            if frame in seen:  # a cycle in bad data: stop
                break
            seen.add(frame)
        return frame, pose

    def lookup(self, target: str, source: str) -> Pose | None:
        """Return ``target <- source``, or ``None`` when the frames are not connected."""
        root_s, pose_s = self._to_root(_strip(source))
        root_t, pose_t = self._to_root(_strip(target))
        if root_s != root_t:
            return None
        return _compose(_inverse(pose_t), pose_s)


@dataclass(eq=False, slots=True)
class _Request:
    """One client's frame subscription (a goal or a republished topic)."""

    source_frames: list[str]
    target_frame: str
    angular_thres: float
    trans_thres: float
    period: float
    next_due: float = -math.inf
    sent: dict[str, Pose] = field(default_factory=dict)
    goal: Goal | None = None
    #: A ROS 1 actionlib goal (roslibjs' default TFClient).
    al_goal: ActionlibGoal | None = None
    topic: Topic | None = None
    timeout: float = 10.0
    last_subscribed: float = -math.inf
    listened: bool = False
    #: The client that asked (None: in process); its requests go with it.
    owner: Peer | None = None

    @property
    def cost(self) -> float:
        """Transforms a second it may send at most (what the budgets count)."""
        return len(self.source_frames) / self.period


def _moved(old: Pose, new: Pose, trans: float, angle: float) -> bool:
    if trans <= 0 or angle <= 0:
        return True  # tf2_web_republisher: "send every time"
    d = math.dist(old[0], new[0])
    dot = abs(sum(a * b for a, b in zip(old[1], new[1], strict=True)))
    turned = 2.0 * math.acos(min(1.0, dot))
    return d > trans or turned > angle


class TfRepublisher(PeerWatcher):
    """Serves the tf2_web_republisher action and service from the graph's /tf and /tf_static."""

    def __init__(
        self,
        graph: Graph,
        max_rate: Callable[[], float] | None = None,
        settings: ServerSettings | None = None,
    ) -> None:
        #: The graph it reads TF from and sends on.
        self.graph = graph
        #: The server's budgets of TF requests (``tf_*``).
        self.settings = settings or ServerSettings()
        #: The transform tree.
        self.buffer = TfBuffer()
        #: Active requests.
        self.requests: list[_Request] = []
        self._topics = itertools.count(1)
        self._listening = False
        #: This tick's lookups, shared by every request that asks for the same pair.
        self._poses: dict[tuple[str, str], Pose | None] = {}
        #: Failures already logged (once per cause).
        self._failed: set[str] = set()
        self._max_rate = max_rate or (lambda: 20.0)
        graph.actions.add_server(REPUBLISHER_NODE, _ACTION_TYPE, REPUBLISHER_NODE, self)
        graph.add_service("/republish_tfs", _SERVICE_TYPE, REPUBLISHER_NODE, self._republish)
        #: The ROS 1 actionlib interface of the same node.
        self.actionlib = ActionlibServer(
            graph,
            REPUBLISHER_NODE,
            _ACTIONLIB_ACTION,
            REPUBLISHER_NODE,
            self._actionlib_goal,
            self._actionlib_cancel,
            private=True,
        )

    # -- feeding --------------------------------------------------------------------------

    def _on_tf(self, msg: Any, source: Peer | None) -> None:
        self.buffer.add(msg)

    def _listen(self, on: bool) -> None:
        """Follow /tf and /tf_static only while some client wants transforms."""
        if on == self._listening:
            return
        self._listening = on
        for name in ("/tf", "/tf_static"):
            if on:
                topic = self.graph.subscribe(
                    name, "tf2_msgs/msg/TFMessage", REPUBLISHER_NODE, self._on_tf
                )
                if topic.latched is not None:
                    self.buffer.add(topic.latched.msg)
            else:
                self.graph.topics.unsubscribe_internal(name, self._on_tf)

    def _add(self, request: _Request) -> None:
        self.requests.append(request)
        self._listen(True)

    def _remove(self, request: _Request) -> None:
        if request in self.requests:
            self.requests.remove(request)
        if not self.requests:
            self._listen(False)

    def _request(self, values: Any, owner: Peer | None, what: str) -> _Request:
        """Check a request (goal or service) against the rules and budgets; build it.

        Raises:
            ServiceError: the request is refused; the text says why.
        """
        if not isinstance(values, dict):
            msg = f"{what}: expected a request object"
            raise ServiceError(msg)
        frames = values.get("source_frames", [])
        target = values.get("target_frame", "")
        if not isinstance(frames, list):
            msg = f"{what}: source_frames must be a list of frame names"
            raise ServiceError(msg)
        if len(frames) > MAX_FRAMES:
            msg = f"{what}: {len(frames)} source_frames; at most {MAX_FRAMES} in one request"
            raise ServiceError(msg)
        for frame in [*frames, target]:
            _check_frame(frame, what)
        numbers = {}
        for key, default in (("angular_thres", 0.0), ("trans_thres", 0.0), ("rate", 10.0)):
            value = values.get(key, default)
            # a threshold may be negative ("send every time"); the budgets count the rate
            floor = 0.0 if key == "rate" else -math.inf
            if not finite_number(value) or value < floor:
                bound = " >= 0" if key == "rate" else ""
                msg = f"{what}: {key} must be a finite number{bound}, got {value!r}"
                raise ServiceError(msg)
            numbers[key] = float(value)
        # as many sends a second as TF changes at most; 0 means the node's default, 10 Hz
        rate = min(numbers["rate"] or 10.0, self.max_rate())
        request = _Request(
            list(frames),
            target,
            numbers["angular_thres"],
            numbers["trans_thres"],
            1.0 / max(rate, 0.1),
            owner=owner,
        )
        self._admit(request, what)
        return request

    def max_rate(self) -> float:
        """The fastest a request is served: the simulation rate (TF changes no faster)."""
        return self._max_rate()

    def _admit(self, request: _Request, what: str) -> None:
        """Refuse a request over the owner's or the class's budget (``docs/security.md``)."""
        s = self.settings
        if request.owner is None:
            return
        mine = [r for r in self.requests if r.owner is request.owner]
        if len(mine) >= s.tf_requests_per_client:
            msg = (
                f"{what}: refused, this client already has {len(mine)} TF requests (the "
                f"server's tf_requests_per_client, {s.tf_requests_per_client}); cancel one first"
            )
            raise ServiceError(msg)
        cost = request.cost
        if sum(r.cost for r in mine) + cost > s.tf_transforms_per_client:
            msg = (
                f"{what}: refused, this client's TF requests would send up to "
                f"{sum(r.cost for r in mine) + cost:.0f} transforms a second (the server's "
                f"tf_transforms_per_client, {s.tf_transforms_per_client:g}); ask for fewer "
                "frames or a lower rate"
            )
            raise ServiceError(msg)
        if sum(r.cost for r in self.requests) + cost > s.tf_transforms_total:
            msg = (
                f"{what}: refused, the server is sending as many transforms as it allows for "
                f"everyone (tf_transforms_total, {s.tf_transforms_total:g} a second); try "
                "again later or ask for fewer frames"
            )
            raise ServiceError(msg)

    def peer_left(self, peer: Peer) -> None:
        """Remove the republished topics of a client that left (its goals are cancelled)."""
        for request in [r for r in self.requests if r.owner is peer]:
            if request.topic is not None:
                self.graph.topics.unadvertise(request.topic.name, REPUBLISHER_NODE)
            self._remove(request)
        self.actionlib.peer_left(peer)

    # -- action (ROS2TFClient) -------------------------------------------------------------

    def goal(self, goal: Goal) -> None:
        """Start sending feedback for a TFSubscription goal (or refuse it with the reason)."""
        try:
            request = self._request(goal.args, goal.caller, f"goal of {REPUBLISHER_NODE}")
        except ServiceError as err:
            goal.finish(ABORTED, str(err), ok=False)
            return
        request.goal = goal
        self._add(request)

    def cancel(self, goal: Goal) -> None:
        """Stop a TFSubscription goal: it ends canceled (status 5)."""
        for request in [r for r in self.requests if r.goal is goal]:
            self._remove(request)
        goal.finish(CANCELED, {})

    # -- ROS 1 actionlib (the default TFClient of roslibjs) ------------------------------------

    def _actionlib_goal(self, goal: ActionlibGoal, now: float) -> None:
        """Start a goal of the default TFClient (or reject it, status 5, with the reason)."""
        try:
            request = self._request(goal.goal, goal.peer, f"goal of {REPUBLISHER_NODE}/goal")
        except ServiceError as err:
            goal.finish(REJECTED, {}, now, str(err))
            return
        request.al_goal = goal
        self._add(request)

    def _actionlib_cancel(self, goal: ActionlibGoal, now: float) -> None:
        """Roslibjs cancels its goal each time its frame list changes: it ends preempted."""
        for request in [r for r in self.requests if r.al_goal is goal]:
            self._remove(request)
        goal.finish(PREEMPTED, {}, now)

    # -- service (TFClient, roslibpy) ------------------------------------------------------

    def _republish(self, values: Any) -> dict[str, Any]:
        request = self._request(values, caller.get(), "republish_tfs")
        timeout = values.get("timeout") or {}
        try:
            seconds = float(timeout.get("sec", 0)) + float(timeout.get("nanosec", 0)) / 1e9
        except (AttributeError, TypeError, ValueError):
            msg = "republish_tfs: timeout must be a builtin_interfaces/Duration {sec, nanosec}"
            raise ServiceError(msg) from None
        # a lifetime without subscribers: never longer than tf_max_timeout (not 63 years)
        limit = self.settings.tf_max_timeout
        request.timeout = min(seconds, limit) if seconds > 0 else min(10.0, limit)
        name = f"/tf_repub_{next(self._topics)}"
        request.topic = self.graph.advertise(name, _TOPIC_TYPE, REPUBLISHER_NODE)
        self._add(request)
        return {"topic_name": name}

    # -- sending ------------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Send what is due (call once per simulation step).

        A request whose sending fails is dropped (its goal aborted), logged once per cause;
        the other requests are served.
        """
        self.actionlib.tick(now)
        self._poses.clear()
        for request in list(self.requests):
            try:
                self._serve(request, now)
            except Exception as err:
                self._drop_failed(request, err)

    def _drop_failed(self, request: _Request, err: Exception) -> None:
        cause = f"{type(err).__name__}: {err}"[:200]
        if cause not in self._failed and len(self._failed) < 100:
            self._failed.add(cause)
            logger.exception("a TF request failed and was dropped (logged once per cause)")
        if request.topic is not None:
            self.graph.topics.unadvertise(request.topic.name, REPUBLISHER_NODE)
        self._remove(request)
        if request.goal is not None:
            request.goal.finish(ABORTED, f"TF request failed: {cause}", ok=False)
        if request.al_goal is not None:
            text = f"TF request failed: {cause}"
            request.al_goal.finish(AL_ABORTED, {}, self.actionlib.now, text)

    def _serve(self, request: _Request, now: float) -> None:
        if (request.goal is not None and request.goal.done) or (
            request.al_goal is not None and request.al_goal.done
        ):
            self._remove(request)
            return
        if request.topic is not None and self._expired(request, now):
            return
        if now < request.next_due:
            return
        request.next_due = max(request.next_due + request.period, now)
        if request.topic is not None:
            listening = bool(request.topic.sinks)
            if listening and not request.listened:
                request.sent.clear()  # a (new) subscriber gets every transform once
            request.listened = listening
            if not listening:
                return
        transforms = self._changed(request)
        if not transforms:
            return
        if request.goal is not None:
            request.goal.feedback({"transforms": transforms})
        elif request.al_goal is not None:
            request.al_goal.feedback({"transforms": transforms}, now)
        elif request.topic is not None:
            self.graph.publish(request.topic, {"transforms": transforms}, now)

    def _expired(self, request: _Request, now: float) -> bool:
        topic = request.topic
        assert topic is not None
        if topic.sinks or request.last_subscribed == -math.inf:
            request.last_subscribed = now
            return False
        if now - request.last_subscribed < request.timeout:
            return False
        self.graph.topics.unadvertise(topic.name, REPUBLISHER_NODE)
        self._remove(request)
        return True

    def _changed(self, request: _Request) -> list[dict[str, Any]]:
        sec, nanosec = self.graph.stamp()
        out = []
        for frame in request.source_frames:
            key = (request.target_frame, frame)
            if key in self._poses:
                pose = self._poses[key]
            else:
                pose = self._poses[key] = self.buffer.lookup(*key)
            if pose is None:
                continue
            child = _strip(frame)
            old = request.sent.get(child)
            if old is not None and not _moved(
                old, pose, request.trans_thres, request.angular_thres
            ):
                continue
            request.sent[child] = pose
            (x, y, z), (qx, qy, qz, qw) = pose
            out.append(
                {
                    "header": {
                        "stamp": {"sec": sec, "nanosec": nanosec},
                        "frame_id": _strip(request.target_frame),
                    },
                    "child_frame_id": child,
                    "transform": {
                        "translation": {"x": x, "y": y, "z": z},
                        "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
                    },
                }
            )
        return out


def _check_frame(frame: object, what: str) -> None:
    """Refuse a frame name that is not a sane string (it would fail every later send)."""
    if not isinstance(frame, str):
        msg = f"{what}: frame names must be strings, got {frame!r}"
        raise ServiceError(msg)
    if len(frame) > MAX_FRAME_NAME:
        msg = f"{what}: frame name of {len(frame)} characters; at most {MAX_FRAME_NAME}"
        raise ServiceError(msg)
    if "\x00" in frame or any("\ud800" <= c <= "\udfff" for c in frame):
        msg = f"{what}: frame name {frame!r} holds a NUL or a lone UTF-16 surrogate"
        raise ServiceError(msg)


def install_tf_republisher(
    graph: Graph,
    max_rate: Callable[[], float] | None = None,
    settings: ServerSettings | None = None,
) -> TfRepublisher:
    """Serve tf2_web_republisher on ``graph``; call the result's ``tick(now)`` every step.

    ``max_rate`` gives the fastest rate a request is served at (the simulation rate);
    ``settings`` the budgets of TF requests (default: the defaults).
    """
    return TfRepublisher(graph, max_rate, settings)
