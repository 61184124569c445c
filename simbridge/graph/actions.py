"""ROS 2 actions between clients (and in-process action servers), with ROS 2 status codes.

A client serves an action with ``advertise_action``; goals from any client (``send_action_goal``)
are forwarded to it as ``send_action_goal`` with a server-chosen id
``action_goal:<action>:<n>`` and ``feedback: true``; its ``action_feedback`` and
``action_result`` go back to the goal's sender under the sender's own id (protocol reference
sections 2.10-2.15). ``cancel_action_goal`` from the sender is forwarded as
``cancel_action_goal`` with the server id; the server's final ``action_result`` (status 5) ends
the goal.

Status codes are ``action_msgs/msg/GoalStatus``: 0 unknown, 1 accepted, 2 executing,
3 canceling, 4 succeeded, 5 canceled, 6 aborted. Every goal is answered:

* no such action, or a goal that does not fit a known action type (admission decides, see
  :meth:`Admission.goal <simbridge.rosbridge.admission.Admission.goal>`): ``action_result`` with
  ``result: false``, ``status: 0`` and the reason (rosbridge 2.1 hangs here, #1139);
* the server's ``action_result`` with ``result: true``: status 4 and 5 are passed on, anything
  else becomes 6 (as rosbridge's goal handle does);
* the server's ``action_result`` with ``result: false``, or the server unadvertising or
  disconnecting: ``result: false``, ``status: 6`` and the reason.

Each action also gets the hidden service ``<action>/_action/cancel_goal``
(``action_msgs/srv/CancelGoal``): an all-zero ``goal_info`` cancels every goal of the action
(roslibjs 2.1 ``Action.cancelAllGoals``), a zero id with a stamp cancels the goals accepted up to
that time, else the goal with that UUID. A client reaches only the goals it sent: "every goal"
means every goal of its own, and another client's goal UUID is refused with the reason.

A client may not advertise an action the server provides itself (``/tf2_web_republisher``):
that would take it over for everyone, and it would be gone when that client left.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import uuid
from dataclasses import dataclass
from typing import Any, Protocol

from simbridge.errors import ServiceError
from simbridge.graph.services import ServiceTable, caller
from simbridge.graph.topics import BRIDGE_NODE, Peer
from simbridge.msgs import Converter, TypeRegistry, normalize_type
from simbridge.rosbridge import OpId, Provided, json_frame, ops as o


__all__ = [
    "ABORTED",
    "CANCELED",
    "CANCELING",
    "EXECUTING",
    "SUCCEEDED",
    "Action",
    "ActionHost",
    "ActionServer",
    "ActionTable",
    "Goal",
]

logger = logging.getLogger(__name__)

UNKNOWN, ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = range(7)


class ActionServer(Protocol):
    """An in-process action server."""

    def goal(self, goal: Goal) -> None:
        """Start executing ``goal`` (call :meth:`Goal.feedback` / :meth:`Goal.finish` later)."""

    def cancel(self, goal: Goal) -> None:
        """Cancel ``goal`` (finish it with status 5 when done)."""


@dataclass(eq=False, slots=True)
class Action:
    """One action: served by a client (``provider``) or in process (``server``)."""

    name: str
    #: Canonical ``pkg/action/Type``.
    type: str
    #: The type as the server advertised it (sent on with each goal).
    written_type: str
    node: str
    provider: Peer | None = None
    server: ActionServer | None = None
    #: The name as the server wrote it in ``advertise_action`` (roslibjs routes goals by it).
    written: str = ""


@dataclass(eq=False, slots=True)
class Goal:
    """A goal in flight."""

    server_id: str
    action: Action
    caller: Peer
    caller_id: OpId | None
    #: The action name as the caller wrote it (echoed in replies).
    written: str
    want_feedback: bool
    #: The goal message (complete when the action type is known).
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
    #: The goal counts against its caller's pending-goal budget (a rosbridge client's goal).
    counted: bool = False

    def feedback(self, values: Any) -> None:
        """Send feedback to the goal's sender (if it asked for feedback)."""
        if self.done or not self.want_feedback:
            return
        body: dict[str, Any] = {"op": "action_feedback", "action": self.written, "values": values}
        if self.caller_id is not None:
            body["id"] = self.caller_id
        self.caller.send(json_frame(body))

    def finish(self, status: int, values: Any, *, result: bool = True) -> None:
        """End the goal: send the ``action_result`` to its sender (once)."""
        if self.done:
            return
        self.done = True
        self.status = status
        self.table.goals.pop(self.server_id, None)
        if self.counted:
            self.caller.session.end_goal()
        body: dict[str, Any] = {
            "op": "action_result",
            "action": self.written,
            "values": values,
            "status": status,
            "result": result,
        }
        if self.caller_id is not None:
            body["id"] = self.caller_id
        self.caller.send(json_frame(body))


class ActionHost(Protocol):
    """What the action table needs of its graph (a :class:`~simbridge.graph.graph.Graph`)."""

    #: In-process nodes: name -> description.
    nodes: dict[str, str]
    #: Where an action's cancel service lives.
    services: ServiceTable
    #: Interface definitions.
    registry: TypeRegistry
    #: Validation of client payloads.
    converter: Converter

    def stamp(self) -> tuple[int, int]:
        """Return the header stamp for now, as (sec, nanosec)."""


class ActionTable:
    """Every action of the graph and the goals in flight."""

    def __init__(self, graph: ActionHost) -> None:
        #: The graph (services table, converter, clock).
        self.graph = graph
        #: Actions by absolute name.
        self.actions: dict[str, Action] = {}
        #: Goals in flight by server id.
        self.goals: dict[str, Goal] = {}
        #: When counted goals to client-served actions time out: (deadline, server id), a heap.
        self.deadlines: list[tuple[float, str]] = []
        self._counter = itertools.count(1)

    # -- declaration ------------------------------------------------------------------------

    def add_server(self, name: str, type_name: str, node: str, server: ActionServer) -> Action:
        """Declare an in-process action server."""
        self.graph.nodes.setdefault(node, "")
        action = Action(name, normalize_type(type_name, "action"), type_name, node, server=server)
        self._install(action)
        return action

    def _install(self, action: Action) -> None:
        old = self.actions.get(action.name)
        if old is not None:
            self._fail_goals(old, f"action {action.name} was re-advertised by another server")
            if old.provider is not None and old.provider is not action.provider:
                old.provider.session.disown("action", action.name)
        self.actions[action.name] = action

        def cancel_goal(request: Any) -> dict[str, Any]:
            return self._cancel_service(action, request)

        self.graph.services.add(
            f"{action.name}/_action/cancel_goal",
            "action_msgs/srv/CancelGoal",
            action.node,
            cancel_goal,
        )

    def add_provider(self, name: str, type_name: str, node: str, provider: Peer) -> Action:
        """Declare an action served by ``provider`` outside the protocol (another ROS 2 process).

        Goals reach the provider as ``send_action_goal`` and ``cancel_action_goal`` frames, as
        they reach a client that advertised the action; it answers through
        :meth:`Goal.feedback` and :meth:`Goal.finish`. :meth:`remove` withdraws it.
        """
        canonical = normalize_type(type_name, "action")
        action = Action(name, canonical, canonical, node, provider=provider)
        self._install(action)
        return action

    def provided(self, peer: Peer, effect: Provided) -> Action:
        """Install an action a client advertised (its session's :class:`Provided` effect)."""
        action = Action(
            effect.name,
            effect.type,
            effect.written_type,
            BRIDGE_NODE,
            provider=peer,
            written=effect.written,
        )
        self._install(action)
        return action

    def remove(self, peer: Peer, name: str) -> bool:
        """Remove ``peer``'s action ``name``; return whether it served it."""
        action = self.actions.get(name)
        if action is None or action.provider is not peer:
            return False
        del self.actions[name]
        self.graph.services.services.pop(f"{name}/_action/cancel_goal", None)
        self._fail_goals(action, f"action {name} was unadvertised by its server")
        return True

    def drop_peer(self, peer: Peer) -> None:
        """Forget the goals of a client that left (cancelled).

        Its actions go with its session's effects (:meth:`Graph.remove_peer
        <simbridge.graph.graph.Graph.remove_peer>`).
        """
        for goal in [g for g in self.goals.values() if g.caller is peer]:
            goal.done = True
            del self.goals[goal.server_id]
            if goal.counted:
                peer.session.end_goal()
            self._forward_cancel(goal)

    def _fail_goals(self, action: Action, reason: str) -> None:
        for goal in [g for g in self.goals.values() if g.action is action]:
            goal.finish(ABORTED, reason, result=False)

    # -- goals --------------------------------------------------------------------------------

    def fail(self, peer: Peer, action: str, op_id: OpId | None, reason: str) -> None:
        """Answer a goal that was not accepted: ``action_result`` false, status 0 (unknown)."""
        body: dict[str, Any] = {
            "op": "action_result",
            "action": action,
            "values": reason,
            "status": UNKNOWN,
            "result": False,
        }
        if op_id is not None:
            body["id"] = op_id
        peer.send(json_frame(body))

    def submit(
        self,
        peer: Peer,
        action: Action,
        message: Any,
        *,
        op_id: OpId | None,
        written: str,
        feedback: bool,
        goal_uuid: bytes | None = None,
        sent_type: str = "",
        now: float | None = None,
    ) -> Goal:
        """Send an admitted goal of ``peer`` (``message`` validated) to ``action``.

        ``goal_uuid`` is the goal's id when the sender chose one (a ROS 2 client does);
        ``sent_type`` the action type it named (``send_action_goal``'s ``action_type``). Given
        ``now`` (a rosbridge client's goal), the goal counts against the sender's pending-goal
        budget until it ends, and a goal to an action that a client serves is aborted when it
        has no result after the sender's ``goal_timeout``. Its message is not kept once it went
        to a client's server (only an in-process server reads it later).

        Raises:
            Refusal: the sender's pending-goal budget is spent (nothing was sent).
        """
        name = action.name
        if now is not None:
            peer.session.start_goal(name, op_id)
        server_id = f"action_goal:{name}:{next(self._counter)}"
        goal = Goal(
            server_id,
            action,
            peer,
            op_id,
            written,
            feedback,
            message,
            goal_uuid or uuid.uuid4().bytes,
            self.graph.stamp(),
            self,
            sent_type=sent_type,
            counted=now is not None,
        )
        self.goals[server_id] = goal
        if action.server is not None:
            action.server.goal(goal)
            return goal
        assert action.provider is not None
        if now is not None:
            heap = self.deadlines
            if len(heap) > 2 * len(self.goals) + 64:  # goals that ended early: drop them
                heap[:] = [entry for entry in heap if entry[1] in self.goals]
                heapq.heapify(heap)
            heapq.heappush(heap, (now + peer.session.limits.goal_timeout, server_id))
        action.provider.send(
            json_frame(
                {
                    "op": "send_action_goal",
                    "id": server_id,
                    "action": action.written or name,
                    "action_type": action.written_type,
                    "args": message,
                    "feedback": True,
                }
            )
        )
        goal.args = None  # sent: a 900 kB goal is not kept while it runs
        return goal

    def expire(self, now: float) -> None:
        """Abort the goals to client-served actions that have had no result in time.

        The sender gets a failed ``action_result`` (status 6) naming the limit; the server gets
        a ``cancel_action_goal``.
        """
        heap = self.deadlines
        while heap and heap[0][0] <= now:
            _deadline, server_id = heapq.heappop(heap)
            goal = self.goals.get(server_id)
            if goal is None:
                continue  # finished before its deadline
            limit = goal.caller.session.limits.goal_timeout
            goal.finish(
                ABORTED,
                f"goal of {goal.action.name} timed out: its action server gave no result within "
                f"{limit:g} s (the server's max_goal_timeout)",
                result=False,
            )
            self._forward_cancel(goal)
        if not self.goals:
            heap.clear()

    def _find_own(self, peer: Peer, op_id: OpId | None, name: str) -> Goal | None:
        for goal in self.goals.values():
            if goal.caller is peer and goal.caller_id == op_id and goal.action.name == name:
                return goal
        return None

    def cancel_own(self, peer: Peer, op_id: OpId | None, name: str) -> None:
        """Cancel the goal ``peer`` sent to action ``name`` under its id ``op_id``, if any."""
        goal = self._find_own(peer, op_id, name)
        if goal is None:
            return  # already finished or never sent: nothing to cancel (as rosbridge)
        self.cancel_goal(goal)

    def cancel_goal(self, goal: Goal) -> None:
        """Ask the goal's server to cancel it."""
        if goal.done or goal.status == CANCELING:
            return
        goal.status = CANCELING
        self._forward_cancel(goal)

    def _forward_cancel(self, goal: Goal) -> None:
        action = goal.action
        if action.server is not None:
            action.server.cancel(goal)
        elif action.provider is not None:
            action.provider.send(
                json_frame(
                    {
                        "op": "cancel_action_goal",
                        "id": goal.server_id,
                        "action": action.written or action.name,
                    }
                )
            )

    def result(self, goal: Goal, op: o.ActionResult, values: Any) -> None:
        """End ``goal`` with its server's admitted ``action_result`` (``values`` validated)."""
        if op.result is False:
            reason = values if values is not None else "goal aborted by its action server"
            goal.finish(ABORTED, reason, result=False)
            return
        status = op.status if op.status in (SUCCEEDED, CANCELED) else ABORTED
        goal.finish(status, values)

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
        if calling is not None:  # a client cancels its own goals only, never another's
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
            self.cancel_goal(goal)
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
