"""tf2_web_republisher, emulated: the transforms web TF clients ask for, from /tf and /tf_static.

roslibjs' ``TFClient`` (1.x, ``groovyCompatibility: false``) and roslibpy's ``TFClient`` call the
service ``/republish_tfs`` (``tf2_web_republisher_interfaces/srv/RepublishTFs``) and subscribe to
the topic it names (``tf2_web_republisher/TFArray``); roslibjs 2.x ``ROS2TFClient`` sends goals to
the action ``/tf2_web_republisher`` (``tf2_web_republisher_interfaces/action/TFSubscription``)
and reads the feedback. Either way simbridge sends, at ``rate`` Hz, each requested
``target_frame <- source_frame`` transform (a ``geometry_msgs/TransformStamped``: header frame
the target, child the source) whenever it moved by more than ``trans_thres`` metres or
``angular_thres`` radians since it was last sent (always the first time).

Frame names are compared without a leading ``/`` (REP-105 names as roslibjs strips them). The
transform tree is the latest transform of each child frame on /tf and /tf_static; a transform
between frames is composed through their common ancestor. A republished topic with no
subscriber for ``timeout`` is removed, as the real node does.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from simbridge.errors import ServiceError
from simbridge.graph.actions import CANCELED, Goal
from simbridge.graph.topics import Peer, Topic


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = ["REPUBLISHER_NODE", "TfBuffer", "TfRepublisher", "install_tf_republisher"]

REPUBLISHER_NODE = "/tf2_web_republisher"
_ACTION_TYPE = "tf2_web_republisher_interfaces/action/TFSubscription"
_SERVICE_TYPE = "tf2_web_republisher_interfaces/srv/RepublishTFs"
_TOPIC_TYPE = "tf2_web_republisher/msg/TFArray"

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
    topic: Topic | None = None
    timeout: float = 10.0
    last_subscribed: float = -math.inf
    listened: bool = False


def _moved(old: Pose, new: Pose, trans: float, angle: float) -> bool:
    d = math.dist(old[0], new[0])
    dot = abs(sum(a * b for a, b in zip(old[1], new[1], strict=True)))
    turned = 2.0 * math.acos(min(1.0, dot))
    return d > trans or turned > angle


class TfRepublisher:
    """Serves the tf2_web_republisher action and service from the graph's /tf and /tf_static."""

    def __init__(self, graph: Graph) -> None:
        #: The graph it reads TF from and sends on.
        self.graph = graph
        #: The transform tree.
        self.buffer = TfBuffer()
        #: Active requests.
        self.requests: list[_Request] = []
        self._topics = itertools.count(1)
        self._listening = False
        graph.actions.add_server(REPUBLISHER_NODE, _ACTION_TYPE, REPUBLISHER_NODE, self)
        graph.add_service("/republish_tfs", _SERVICE_TYPE, REPUBLISHER_NODE, self._republish)

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
                topic = self.graph.topics.topics[name]
                topic.internal = [(n, c) for n, c in topic.internal if c != self._on_tf]

    def _add(self, request: _Request) -> None:
        self.requests.append(request)
        self._listen(True)

    def _remove(self, request: _Request) -> None:
        if request in self.requests:
            self.requests.remove(request)
        if not self.requests:
            self._listen(False)

    @staticmethod
    def _request(values: Any) -> _Request:
        rate = float(values.get("rate") or 10.0)
        return _Request(
            [str(f) for f in values.get("source_frames", [])],
            str(values.get("target_frame", "")),
            float(values.get("angular_thres", 0.0)),
            float(values.get("trans_thres", 0.0)),
            1.0 / max(min(rate, 100.0), 0.1),
        )

    # -- action (ROS2TFClient) -------------------------------------------------------------

    def goal(self, goal: Goal) -> None:
        """Start sending feedback for a TFSubscription goal."""
        request = self._request(goal.args)
        request.goal = goal
        self._add(request)

    def cancel(self, goal: Goal) -> None:
        """Stop a TFSubscription goal: it ends canceled (status 5)."""
        for request in [r for r in self.requests if r.goal is goal]:
            self._remove(request)
        goal.finish(CANCELED, {})

    # -- service (TFClient, roslibpy) ------------------------------------------------------

    def _republish(self, values: Any) -> dict[str, Any]:
        if not isinstance(values, dict):
            msg = "republish_tfs: expected a RepublishTFs request object"
            raise ServiceError(msg)
        request = self._request(values)
        timeout = values.get("timeout") or {}
        seconds = float(timeout.get("sec", 0)) + float(timeout.get("nanosec", 0)) / 1e9
        request.timeout = seconds if seconds > 0 else 10.0
        name = f"/tf_repub_{next(self._topics)}"
        request.topic = self.graph.advertise(name, _TOPIC_TYPE, REPUBLISHER_NODE)
        self._add(request)
        return {"topic_name": name}

    # -- sending ------------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Send what is due (call once per simulation step)."""
        for request in list(self.requests):
            if request.goal is not None and request.goal.done:
                self._remove(request)
                continue
            if request.topic is not None and self._expired(request, now):
                continue
            if now < request.next_due:
                continue
            request.next_due = max(request.next_due + request.period, now)
            if request.topic is not None:
                listening = bool(request.topic.subscriptions)
                if listening and not request.listened:
                    request.sent.clear()  # a (new) subscriber gets every transform once
                request.listened = listening
                if not listening:
                    continue
            transforms = self._changed(request)
            if not transforms:
                continue
            if request.goal is not None:
                request.goal.feedback({"transforms": transforms})
            elif request.topic is not None:
                self.graph.publish(request.topic, {"transforms": transforms}, now)

    def _expired(self, request: _Request, now: float) -> bool:
        topic = request.topic
        assert topic is not None
        if topic.subscriptions or request.last_subscribed == -math.inf:
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
            pose = self.buffer.lookup(request.target_frame, frame)
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


def install_tf_republisher(graph: Graph) -> TfRepublisher:
    """Serve tf2_web_republisher on ``graph``; call the result's ``tick(now)`` every step."""
    return TfRepublisher(graph)
