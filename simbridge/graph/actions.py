"""ROS 2 actions of the graph: who serves them, the goals in flight, ROS 2 status codes.

An action is served in process (:meth:`ActionTable.add_server`: ``/fibonacci``,
``/tf2_web_republisher``) or by a peer of a front end (:meth:`ActionTable.provide`: an action a
rosbridge client advertised, one another ROS 2 process serves); either way its server is an
:class:`ActionServer`: it is handed each goal and each cancel, and answers through
:meth:`Goal.feedback` and :meth:`Goal.finish`. A goal is sent by a peer of any front end
(:meth:`ActionTable.submit`) with its :class:`GoalClient`, the caller side: where the goal's
feedback and result go, in the caller's own wire. Messages are canonical both ways; what is
validated, and how a refusal is told, is the front end's.

Status codes are ``action_msgs/msg/GoalStatus``: 0 unknown, 1 accepted, 2 executing,
3 canceling, 4 succeeded, 5 canceled, 6 aborted. Every goal ends once, with a status: the
server's, or 6 with the reason when its server goes (withdrawn, taken over by another
provider) or, for a goal to a peer's action submitted with a ``timeout``, when no result came
in time (the server is then told to cancel it). A caller that leaves (:meth:`drop_peer`) ends
its goals without an answer; their servers are told to cancel them.

Each action also gets the hidden service ``<action>/_action/cancel_goal``
(``action_msgs/srv/CancelGoal``): an all-zero ``goal_info`` cancels every goal of the action
(roslibjs 2.1 ``Action.cancelAllGoals``), a zero id with a stamp cancels the goals accepted up to
that time, else the goal with that UUID. A peer reaches only the goals it sent: "every goal"
means every goal of its own, and another peer's goal UUID is refused with the reason.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from simbridge.errors import ServiceError
from simbridge.graph.services import ServiceTable, caller
from simbridge.graph.topics import Peer
from simbridge.msgs import normalize_type


__all__ = [
    "ABORTED",
    "ACCEPTED",
    "CANCELED",
    "CANCELING",
    "EXECUTING",
    "SUCCEEDED",
    "UNKNOWN",
    "Action",
    "ActionHost",
    "ActionServer",
    "ActionTable",
    "Goal",
    "GoalClient",
]

logger = logging.getLogger(__name__)

UNKNOWN, ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = range(7)


class ActionServer(Protocol):
    """What serves an action: an in-process node, or a front end for one of its peers."""

    def goal(self, goal: Goal) -> None:
        """Start executing ``goal`` (call :meth:`Goal.feedback` / :meth:`Goal.finish` later)."""

    def cancel(self, goal: Goal) -> None:
        """Cancel ``goal`` (finish it with status 5 when done); it may have ended already."""


class GoalClient(Protocol):
    """The caller side of one goal: where its front end takes the feedback and the result."""

    def feedback(self, values: Any) -> None:
        """The server sent feedback (a canonical feedback message, or as its server sent it)."""

    def result(self, status: int, values: Any, ok: bool) -> None:
        """The goal ended with ``status`` (4, 5, 6, or 0 when not accepted), once.

        ``ok``: ``values`` is the result message; else it is the reason (a text) the goal
        failed.
        """


@dataclass(eq=False, slots=True)
class Action:
    """One action and its server."""

    name: str
    #: Canonical ``pkg/action/Type``.
    type: str
    #: The type as its provider wrote it.
    written_type: str
    node: str
    server: ActionServer
    #: The peer that provides it (``None``: served in process); only it may withdraw it.
    provider: Peer | None = None
    #: Called when another provider takes the name over (the provider no longer serves it).
    lost: Callable[[], None] | None = None


@dataclass(eq=False, slots=True)
class Goal:
    """A goal in flight."""

    #: Unique in the graph (a front end's goal ids are made of it).
    id: int
    action: Action
    #: The peer that sent it.
    caller: Peer
    #: Where its feedback and result go.
    client: GoalClient
    #: The goal message (canonical when the action type is known). A server that sends it on
    #: to another process may drop it (``None``): a 900 kB goal is not kept while it runs.
    args: Any
    uuid: bytes
    #: When it was accepted: (sec, nanosec).
    stamp: tuple[int, int]
    table: ActionTable
    status: int = EXECUTING
    done: bool = False
    #: The action type the sender named (``""``: none), as written; an in-process server may
    #: serve several types under one name and answer in the one the goal was sent with.
    sent_type: str = ""
    #: Called once when the goal leaves the table, however it ends (the caller's budget).
    release: Callable[[], None] | None = None
    #: Seconds a peer's server has to give a result (``None``: no limit).
    timeout: float | None = None

    def feedback(self, values: Any) -> None:
        """Send feedback to the goal's caller (while the goal runs)."""
        if not self.done:
            self.client.feedback(values)

    def finish(self, status: int, values: Any, *, ok: bool = True) -> None:
        """End the goal with ``status`` and tell its caller (once).

        ``ok=False``: ``values`` is the reason it failed (a text).
        """
        if self.done:
            return
        self.table.end(self, status)
        self.client.result(status, values, ok)


class ActionHost(Protocol):
    """What the action table needs of its graph (a :class:`~simbridge.graph.graph.Graph`)."""

    #: In-process nodes: name -> description.
    nodes: dict[str, str]
    #: Where an action's cancel service lives.
    services: ServiceTable

    def stamp(self) -> tuple[int, int]:
        """Return the header stamp for now, as (sec, nanosec)."""


class ActionTable:
    """Every action of the graph and the goals in flight."""

    def __init__(self, graph: ActionHost) -> None:
        #: The graph (services table, clock).
        self.graph = graph
        #: Actions by absolute name.
        self.actions: dict[str, Action] = {}
        #: Goals in flight by id.
        self.goals: dict[int, Goal] = {}
        #: When goals to peers' actions time out: (deadline, goal id), a heap.
        self.deadlines: list[tuple[float, int]] = []
        self._ids = itertools.count(1)

    # -- declaration ------------------------------------------------------------------------

    def add_server(self, name: str, type_name: str, node: str, server: ActionServer) -> Action:
        """Declare an action served in process."""
        self.graph.nodes.setdefault(node, "")
        action = Action(name, normalize_type(type_name, "action"), type_name, node, server)
        self._install(action)
        return action

    def provide(
        self,
        peer: Peer,
        name: str,
        type_name: str,
        node: str,
        server: ActionServer,
        *,
        written_type: str = "",
        lost: Callable[[], None] | None = None,
    ) -> Action:
        """Declare action ``name`` (canonical ``type_name``) served by ``peer`` through ``server``.

        It replaces whoever served the name (their goals end, status 6; a peer that provided it
        is told through its ``lost``). :meth:`withdraw` takes it back.
        """
        action = Action(name, type_name, written_type or type_name, node, server, peer, lost)
        self._install(action)
        return action

    def _install(self, action: Action) -> None:
        old = self.actions.get(action.name)
        if old is not None:
            self._fail_goals(old, f"action {action.name} was re-advertised by another server")
            if old.lost is not None and old.provider is not action.provider:
                old.lost()
        self.actions[action.name] = action

        def cancel_goal(request: Any) -> dict[str, Any]:
            return self._cancel_service(action, request)

        self.graph.services.add(
            f"{action.name}/_action/cancel_goal",
            "action_msgs/srv/CancelGoal",
            action.node,
            cancel_goal,
        )

    def withdraw(self, peer: Peer, name: str) -> bool:
        """Remove ``peer``'s action ``name`` (its goals end, status 6); whether it served it."""
        action = self.actions.get(name)
        if action is None or action.provider is not peer:
            return False
        del self.actions[name]
        self.graph.services.services.pop(f"{name}/_action/cancel_goal", None)
        self._fail_goals(action, f"action {name} was unadvertised by its server")
        return True

    def drop_peer(self, peer: Peer) -> None:
        """End the goals of a peer that left, unanswered; their servers are told to cancel.

        The actions it provided are its front end's to withdraw.
        """
        for goal in [g for g in self.goals.values() if g.caller is peer]:
            self.end(goal, CANCELED)
            goal.action.server.cancel(goal)

    def _fail_goals(self, action: Action, reason: str) -> None:
        for goal in [g for g in self.goals.values() if g.action is action]:
            goal.finish(ABORTED, reason, ok=False)

    # -- goals --------------------------------------------------------------------------------

    def submit(
        self,
        peer: Peer,
        action: Action,
        message: Any,
        client: GoalClient,
        *,
        goal_uuid: bytes | None = None,
        sent_type: str = "",
        release: Callable[[], None] | None = None,
        timeout: float | None = None,
        now: float = 0.0,
    ) -> Goal:
        """Send ``peer``'s goal ``message`` to ``action``; its answers go to ``client``.

        The front end admitted it (``message`` is complete when the action type is known).
        ``goal_uuid``: the goal's id when the sender chose one (a ROS 2 client does), else a
        random one; ``sent_type``: the action type it named; ``release``: called once when the
        goal leaves the table; ``timeout``: seconds after ``now`` at which a goal to a peer's
        action with no result is aborted (status 6, its server told to cancel).
        """
        goal = Goal(
            next(self._ids),
            action,
            peer,
            client,
            message,
            goal_uuid or uuid.uuid4().bytes,
            self.graph.stamp(),
            self,
            sent_type=sent_type,
            release=release,
            timeout=timeout,
        )
        self.goals[goal.id] = goal
        if timeout is not None and action.provider is not None:
            heap = self.deadlines
            if len(heap) > 2 * len(self.goals) + 64:  # goals that ended early: drop them
                heap[:] = [entry for entry in heap if entry[1] in self.goals]
                heapq.heapify(heap)
            heapq.heappush(heap, (now + timeout, goal.id))
        action.server.goal(goal)
        return goal

    def end(self, goal: Goal, status: int) -> None:
        """Take ``goal`` out of the table with ``status``, unanswered (see :meth:`Goal.finish`)."""
        if goal.done:
            return
        goal.done = True
        goal.status = status
        self.goals.pop(goal.id, None)
        if goal.release is not None:
            goal.release()

    def expire(self, now: float) -> None:
        """Abort the goals to peers' actions that have had no result in time.

        The caller gets status 6 naming the limit; the server is told to cancel.
        """
        heap = self.deadlines
        while heap and heap[0][0] <= now:
            _deadline, goal_id = heapq.heappop(heap)
            goal = self.goals.get(goal_id)
            if goal is None:
                continue  # finished before its deadline
            goal.finish(
                ABORTED,
                f"goal of {goal.action.name} timed out: its action server gave no result within "
                f"{goal.timeout:g} s (the server's max_goal_timeout)",
                ok=False,
            )
            goal.action.server.cancel(goal)
        if not self.goals:
            heap.clear()

    def cancel(self, goal: Goal) -> None:
        """Ask the goal's server to cancel it (status 3 until it ends)."""
        if goal.done or goal.status == CANCELING:
            return
        goal.status = CANCELING
        goal.action.server.cancel(goal)

    # -- action_msgs/srv/CancelGoal -------------------------------------------------------------

    def _cancel_service(self, action: Action, request: Any) -> dict[str, Any]:
        info = request.get("goal_info", {}) if isinstance(request, dict) else {}
        goal_id = info.get("goal_id", {}).get("uuid", bytes(16))
        stamp = info.get("stamp", {"sec": 0, "nanosec": 0})
        if isinstance(goal_id, list):
            goal_id = bytes(goal_id)
        if not isinstance(goal_id, bytes | bytearray) or not isinstance(stamp, dict):
            msg = "cancel_goal: goal_info must be an action_msgs/GoalInfo"
            raise ServiceError(msg)
        limit = (stamp.get("sec", 0), stamp.get("nanosec", 0))
        goals = [g for g in self.goals.values() if g.action is action]
        calling = caller.get()
        if calling is not None:  # a peer cancels its own goals only, never another's
            if any(goal_id) and any(
                g.uuid == bytes(goal_id) and g.caller is not calling for g in goals
            ):
                msg = (
                    f"cancel_goal: goal {bytes(goal_id).hex()} of {action.name} was sent by "
                    "another client; a client may cancel only its own goals"
                )
                raise ServiceError(msg)
            goals = [g for g in goals if g.caller is calling]
        if any(goal_id):
            chosen = [g for g in goals if g.uuid == bytes(goal_id)]
        elif limit != (0, 0):
            chosen = [g for g in goals if g.stamp <= limit]
        else:
            chosen = goals
        if any(goal_id) and not chosen:
            return {"return_code": 2, "goals_canceling": []}
        for goal in chosen:
            self.cancel(goal)
        return {
            "return_code": 0,
            "goals_canceling": [
                {
                    "goal_id": {"uuid": g.uuid},
                    "stamp": {"sec": g.stamp[0], "nanosec": g.stamp[1]},
                }
                for g in chosen
            ],
        }
