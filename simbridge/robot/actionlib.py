"""ROS 1 actionlib servers in process: an action as five topics, for ROS 1-era clients.

roslibjs' ``ActionClient`` (and its default ``TFClient``) and roslibpy's ``ros1.actionlib`` speak
actionlib: the client publishes ``<server>/goal`` (``pkg/FooActionGoal``: ``goal_id`` and
``goal``) and ``<server>/cancel`` (``actionlib_msgs/GoalID``), and subscribes to
``<server>/status`` (``actionlib_msgs/GoalStatusArray``), ``<server>/feedback`` and
``<server>/result`` (``pkg/FooActionFeedback``/``Result``: a ``GoalStatus`` and the payload).
ROS 2 and rosbridge on ROS 2 have none of this; an :class:`ActionlibServer` serves it from
process, with the ROS 1 status numbers (:data:`ACTIVE`, :data:`PREEMPTED`, ...).

Differences from actionlib's ``SimpleActionServer``, chosen for a classroom of clients sharing
one server: every goal runs on its own (a new goal does not preempt another client's goal), a
client cancels only its own goals (an empty ``GoalID`` cancels all of them, a stamp those sent
up to that time), each client has at most :attr:`ActionlibServer.max_goals` goals in flight
(more are rejected, status 5, with the reason), and a client's goals end when it leaves.
``private`` servers (tf2_web_republisher) send feedback and results only to the goal's sender,
since other clients would drop them anyway.

``/status`` is published at 5 Hz (actionlib's default ``status_frequency``) while someone
listens, listing the goals in flight and those that ended in the last 5 seconds.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from simbridge.errors import ProtocolError
from simbridge.graph.graph import PeerWatcher
from simbridge.graph.topics import Peer, Topic


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = [
    "ABORTED",
    "ACTIVE",
    "PENDING",
    "PREEMPTED",
    "REJECTED",
    "SUCCEEDED",
    "ActionlibGoal",
    "ActionlibServer",
]

# actionlib_msgs/GoalStatus (ROS 1 numbering, not action_msgs')
PENDING, ACTIVE, PREEMPTED, SUCCEEDED, ABORTED, REJECTED = range(6)
PREEMPTING = 6

#: Seconds between /status messages (actionlib's status_frequency 5 Hz).
STATUS_PERIOD = 0.2
#: Seconds an ended goal stays in /status (actionlib's status_list_timeout).
STATUS_KEEP = 5.0
#: Ended goals kept for /status at most (a client ending goals fast cannot grow it).
STATUS_HISTORY = 50


@dataclass(eq=False, slots=True)
class ActionlibGoal:
    """One goal of an actionlib server."""

    server: ActionlibServer
    #: ``actionlib_msgs/GoalID`` as canonical dict (``stamp`` ``{sec, nanosec}``, ``id``).
    goal_id: dict[str, Any]
    #: The goal payload (canonical).
    goal: dict[str, Any]
    #: The client that sent it.
    peer: Peer | None
    status: int = ACTIVE
    text: str = ""
    #: When it ended (server ``now``), for the /status history.
    ended: float = math.inf
    #: Free slot for the executing node.
    state: dict[str, Any] = field(default_factory=dict)

    @property
    def done(self) -> bool:
        """Return whether the goal has ended."""
        return self.ended != math.inf

    def feedback(self, payload: dict[str, Any], now: float) -> None:
        """Publish ``<server>/feedback`` for this goal."""
        if self.done:
            return
        self.server.send(self, self.server.feedback_topic, "feedback", payload, now)

    def finish(self, status: int, payload: dict[str, Any], now: float, text: str = "") -> None:
        """End the goal with a ROS 1 status and publish ``<server>/result`` (once)."""
        if self.done:
            return
        self.status, self.text, self.ended = status, text, now
        self.server.send(self, self.server.result_topic, "result", payload, now)


class ActionlibServer(PeerWatcher):
    """Serves one actionlib action on ``<name>/{goal,cancel,status,feedback,result}``.

    Args:
        graph: the graph to serve on.
        name: the server name (``/fibonacci``).
        action: ``pkg/Name`` of the action (``actionlib_tutorials/Fibonacci``); its
            ``NameActionGoal`` etc. must be registered (:mod:`simbridge.msgs.interfaces`).
        node: the node that serves it (for rosapi).
        on_goal: called with each accepted goal (status ACTIVE) and ``now``.
        on_cancel: called with a goal its sender cancels; it should ``finish`` it (PREEMPTED).
        private: send feedback and results only to the goal's sender.
    """

    max_goals = 10

    def __init__(
        self,
        graph: Graph,
        name: str,
        action: str,
        node: str,
        on_goal: Callable[[ActionlibGoal, float], None],
        on_cancel: Callable[[ActionlibGoal, float], None],
        *,
        private: bool = False,
    ) -> None:
        pkg, short = action.split("/")
        self.graph = graph
        self.name = name
        self.node = node
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.private = private
        #: Goals in flight and recently ended, oldest first.
        self.goals: list[ActionlibGoal] = []
        self._ids = itertools.count(1)
        self._next_status = -math.inf
        self._now = 0.0
        self.status_topic = graph.advertise(
            f"{name}/status", "actionlib_msgs/msg/GoalStatusArray", node
        )
        self.feedback_topic = graph.advertise(
            f"{name}/feedback", f"{pkg}/msg/{short}ActionFeedback", node
        )
        self.result_topic = graph.advertise(
            f"{name}/result", f"{pkg}/msg/{short}ActionResult", node
        )
        graph.subscribe(f"{name}/goal", f"{pkg}/msg/{short}ActionGoal", node, self._on_goal)
        graph.subscribe(f"{name}/cancel", "actionlib_msgs/msg/GoalID", node, self._on_cancel)

    @property
    def now(self) -> float:
        """The ``now`` of the last :meth:`tick`."""
        return self._now

    # -- incoming ---------------------------------------------------------------------------

    def _on_goal(self, msg: Any, peer: Peer | None) -> None:
        goal_id = dict(msg["goal_id"])
        if not goal_id["id"]:
            goal_id["id"] = f"{self.node}-{next(self._ids)}"
        if goal_id["stamp"] == {"sec": 0, "nanosec": 0}:
            sec, nanosec = self.graph.stamp()
            goal_id["stamp"] = {"sec": sec, "nanosec": nanosec}
        goal = ActionlibGoal(self, goal_id, msg["goal"], peer)
        self.goals.append(goal)
        mine = [g for g in self.goals if g.peer is peer and not g.done]
        if len(mine) > self.max_goals:
            text = (
                f"{self.name}: at most {self.max_goals} goals in flight per client; "
                "cancel one or wait for a result"
            )
            goal.finish(REJECTED, {}, self._now, text)
            raise ProtocolError(text)
        self.on_goal(goal, self._now)

    def _on_cancel(self, msg: Any, peer: Peer | None) -> None:
        """Actionlib cancel policy, limited to the sender's own goals."""
        wanted, stamp = msg["id"], msg["stamp"]
        limit = (stamp["sec"], stamp["nanosec"])
        for goal in [g for g in self.goals if g.peer is peer and not g.done]:
            gs = goal.goal_id["stamp"]
            if wanted:
                hit = goal.goal_id["id"] == wanted
            else:
                hit = limit == (0, 0) or (gs["sec"], gs["nanosec"]) <= limit
            if hit:
                goal.status = PREEMPTING
                self.on_cancel(goal, self._now)

    def peer_left(self, peer: Peer) -> None:
        """Forget the goals of a client that left (their nodes see them as cancelled)."""
        for goal in [g for g in self.goals if g.peer is peer]:
            if not goal.done:
                goal.ended = self._now
                self.on_cancel(goal, self._now)
            self.goals.remove(goal)

    # -- outgoing ---------------------------------------------------------------------------

    def _status(self, goal: ActionlibGoal) -> dict[str, Any]:
        return {"goal_id": goal.goal_id, "status": goal.status, "text": goal.text}

    def _header(self) -> dict[str, Any]:
        sec, nanosec = self.graph.stamp()
        return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""}

    def send(
        self, goal: ActionlibGoal, topic: Topic, key: str, payload: dict[str, Any], now: float
    ) -> None:
        """Publish a feedback or result message of ``goal`` (to its sender only if private)."""
        msg = {"header": self._header(), "status": self._status(goal), key: payload}
        if not self.private or goal.peer is None:
            self.graph.publish(topic, msg, now)
            return
        if not topic.sinks:
            return
        topics = self.graph.topics
        topics.deliver_to(topic, topics.outgoing(topic, msg, self.graph.stamp()), now, [goal.peer])

    def tick(self, now: float) -> None:
        """Publish /status when due and forget goals that ended long enough ago."""
        self._now = now
        if now < self._next_status:
            return
        self._next_status = now + STATUS_PERIOD
        self.goals = [g for g in self.goals if now - g.ended < STATUS_KEEP]
        ended = [g for g in self.goals if g.done]
        for goal in ended[: max(0, len(ended) - STATUS_HISTORY)]:
            self.goals.remove(goal)
        if self.status_topic.sinks:
            status_list = [self._status(g) for g in self.goals]
            msg = {"header": self._header(), "status_list": status_list}
            self.graph.publish(self.status_topic, msg, now)
