"""rosbridge's action ops on the graph's action table (protocol sections 2.10-2.15).

Each op's admission check and its handler are here, one hop from each other:

* ``advertise_action`` (2.10): the client serves the action (scope and advertisement budget;
  an action the server provides itself, such as ``/tf2_web_republisher``, cannot be taken
  over: it would break for everyone, and be gone when that client left); goals from any peer
  reach it as ``send_action_goal`` with a server-chosen id ``action_goal:<action>:<n>`` and
  ``feedback: true`` (:class:`ClientServer`), cancels as ``cancel_action_goal`` with that id;
* ``unadvertise_action`` (2.11): its goals in flight end, status 6;
* ``send_action_goal`` (2.12): not another robot's action, an ``action_type`` of at most
  :data:`~simbridge.msgs.registry.MAX_TYPE_LENGTH` characters, a goal that fits a known action
  type (completed with defaults; ``args`` as a list are zipped onto the fields), within the
  client's ``max_pending_goals`` and the server's ``global_pending_goals``; a goal to a
  client-served action with no result after ``max_goal_timeout`` is aborted;
* ``action_feedback`` (2.13) and ``action_result`` (2.14) of a goal this client serves, checked
  against the action's types, go to the goal's sender under the sender's own id
  (:class:`ClientGoal`);
* ``cancel_action_goal`` (2.15) of the sender's own goal, forwarded to its server; the
  server's final ``action_result`` (status 5) ends the goal.

Every goal is answered with an ``action_result``:

* no such action, or a goal that does not fit its type: ``result: false``, ``status: 0`` and the
  reason (rosbridge 2.1 hangs here, #1139);
* the server's ``action_result`` with ``result: true``: status 4 and 5 are passed on, anything
  else becomes 6 (as rosbridge's goal handle does);
* the server's ``action_result`` with ``result: false``, or the server unadvertising or
  disconnecting, or the goal timing out: ``result: false``, ``status: 6`` and the reason.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Protocol

from simbridge.errors import ConversionError, ProtocolError, TypeNotFoundError
from simbridge.graph.actions import ABORTED, CANCELED, SUCCEEDED, UNKNOWN, Action, Goal
from simbridge.graph.graph import Graph
from simbridge.graph.topics import BRIDGE_NODE
from simbridge.msgs import normalize_type, positional_args
from simbridge.msgs.registry import MAX_TYPE_LENGTH
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.admission import Admission, Check, Typed
from simbridge.rosbridge.encoding import json_frame
from simbridge.rosbridge.ops import OpId, Refusal
from simbridge.rosbridge.session import Effect, Provided, Session
from simbridge.rosbridge.subscribers import Client


__all__ = [
    "ActionOps",
    "ClientGoal",
    "ClientServer",
    "GoalRequest",
    "GoalUpdate",
    "goal_id",
]

logger = logging.getLogger(__name__)

_PREFIX = "action_goal:"


def goal_id(goal: Goal) -> str:
    """Return the id a client action server knows ``goal`` by (``action_goal:<action>:<n>``)."""
    return f"{_PREFIX}{goal.action.name}:{goal.id}"


def failed(action: str, op_id: OpId | None, reason: str) -> dict[str, Any]:
    """Return the ``action_result`` of a goal that was not accepted (status 0, unknown)."""
    body: dict[str, Any] = {
        "op": "action_result",
        "action": action,
        "values": reason,
        "status": UNKNOWN,
        "result": False,
    }
    if op_id is not None:
        body["id"] = op_id
    return body


class ClientGoal:
    """The caller side of a rosbridge client's goal: ``action_feedback`` and ``action_result``."""

    __slots__ = ("feedback_wanted", "op_id", "peer", "written")

    def __init__(self, peer: Client, op_id: OpId | None, written: str, feedback: bool) -> None:
        self.peer = peer
        #: The client's id of the goal (echoed in the replies).
        self.op_id = op_id
        #: The action name as the client wrote it (echoed in the replies).
        self.written = written
        self.feedback_wanted = feedback

    def feedback(self, values: Any) -> None:
        """Send ``action_feedback`` (if the client asked for feedback)."""
        if not self.feedback_wanted:
            return
        body: dict[str, Any] = {"op": "action_feedback", "action": self.written, "values": values}
        if self.op_id is not None:
            body["id"] = self.op_id
        self.peer.send(json_frame(body))

    def result(self, status: int, values: Any, ok: bool) -> None:
        """Send the ``action_result``."""
        body: dict[str, Any] = {
            "op": "action_result",
            "action": self.written,
            "values": values,
            "status": status,
            "result": ok,
        }
        if self.op_id is not None:
            body["id"] = self.op_id
        self.peer.send(json_frame(body))


class ClientServer:
    """An action a rosbridge client serves: goals and cancels sent to it as ops."""

    __slots__ = ("name", "peer", "written", "written_type")

    def __init__(self, peer: Client, name: str, written: str, written_type: str) -> None:
        self.peer = peer
        self.name = name
        #: The name and type as the client wrote them in ``advertise_action`` (roslibjs
        #: routes goals by the name).
        self.written = written or name
        self.written_type = written_type

    def goal(self, goal: Goal) -> None:
        """Send the goal as ``send_action_goal``; its message is not kept once sent."""
        body = {
            "op": "send_action_goal",
            "id": goal_id(goal),
            "action": self.written,
            "action_type": self.written_type,
            "args": goal.args,
            "feedback": True,
        }
        self.peer.send(json_frame(body))
        goal.args = None  # sent: a 900 kB goal is not kept while it runs

    def cancel(self, goal: Goal) -> None:
        """Send ``cancel_action_goal``."""
        body = {"op": "cancel_action_goal", "id": goal_id(goal), "action": self.written}
        self.peer.send(json_frame(body))


@dataclass(frozen=True, slots=True)
class GoalRequest:
    """An admitted ``send_action_goal``: the action and the goal message, validated."""

    op: o.SendActionGoal
    action: Action
    #: The complete goal message when the action type is known, else ``args`` as sent.
    message: Any


@dataclass(frozen=True, slots=True)
class GoalUpdate:
    """An admitted ``action_feedback`` or ``action_result`` of a goal the client serves."""

    goal: Goal
    op: o.ActionFeedback | o.ActionResult
    #: The feedback or result, validated and completed when the action type is known (a
    #: failed result's reason as sent).
    values: Any


#: A handler of one admitted op: ``(peer, admitted, now)``.
Handler = Callable[[Client, Any, float], None]


class Front(Protocol):
    """What the action ops use of their front end, :class:`~simbridge.rosbridge.front.Rosbridge`."""

    graph: Graph
    admission: Admission

    def apply(self, peer: Client, effects: Iterable[Effect]) -> None:
        """Carry out the effects a session returned for its client ``peer``."""


class ActionOps:
    """The action ops of rosbridge clients on one graph (see the module doc)."""

    def __init__(self, front: Front) -> None:
        self.front = front
        self.graph = front.graph
        self.actions = front.graph.actions

    def checks(self) -> dict[type, Check]:
        """Return the admission checks of the action ops, by op class."""
        return {
            o.AdvertiseAction: self._admit_advertise,
            o.SendActionGoal: self._admit_goal,
            o.ActionFeedback: self._admit_feedback,
            o.ActionResult: self._admit_result,
        }

    def handlers(self) -> dict[type, Handler]:
        """Return the handlers of the action ops, by op class."""
        return {
            o.AdvertiseAction: self._advertise,
            o.UnadvertiseAction: self._unadvertise,
            o.SendActionGoal: self._send_goal,
            o.ActionFeedback: self._feedback,
            o.ActionResult: self._result,
            o.CancelActionGoal: self._cancel,
        }

    # -- advertise_action, unadvertise_action (2.10, 2.11) ----------------------------------

    def _admit_advertise(
        self, peer: Client, session: Session, op: o.AdvertiseAction, now: float
    ) -> Typed:
        name = op.name
        if self.graph.access.guarded:
            new = not session.provides("action", name)
            self.front.admission.may_own(session, "advertise_action", name, new)
        existing = self.actions.actions.get(name)
        if existing is not None and existing.provider is None:
            msg = (
                f"advertise_action {name}: refused, the server provides this action itself; "
                "choose another name"
            )
            raise ProtocolError(msg)
        try:
            return Typed(op, normalize_type(op.type, "action"))
        except TypeNotFoundError as err:
            raise ProtocolError(f"advertise_action: {err}") from None

    def _advertise(self, peer: Client, admitted: Typed, now: float) -> None:
        op, type_name = admitted.op, admitted.type
        assert type_name is not None
        effects = peer.session.provide("action", op.name, type_name, op.action, op.type)
        self.front.apply(peer, effects)  # Provided: :meth:`provided`

    def _unadvertise(self, peer: Client, op: o.UnadvertiseAction, now: float) -> None:
        self.front.apply(peer, peer.session.withdraw("action", op.name))  # :meth:`withdrawn`

    def provided(self, peer: Client, effect: Provided) -> None:
        """Install an action the client advertised (its session's :class:`Provided` effect)."""
        name = effect.name
        server = ClientServer(peer, name, effect.written, effect.written_type)

        def lost() -> None:  # another provider took the name: the client no longer has it
            peer.session.disown("action", name)

        self.actions.provide(
            peer,
            name,
            effect.type,
            BRIDGE_NODE,
            server,
            written_type=effect.written_type,
            lost=lost,
        )

    def withdrawn(self, peer: Client, name: str) -> None:
        """Remove an action the client no longer serves (its goals end, status 6)."""
        self.actions.withdraw(peer, name)

    # -- send_action_goal (2.12) --------------------------------------------------------------

    def _admit_goal(
        self, peer: Client, session: Session, op: o.SendActionGoal, now: float
    ) -> GoalRequest:
        rules = self.graph.access
        if rules.guarded and not rules.may_reach(session.access, op.name):
            msg = f"action {op.name} belongs to another robot; this connection may not use it"
            raise Refusal(msg, op="send_action_goal", target=op.action, op_id=op.id)
        if len(op.action_type) > MAX_TYPE_LENGTH:  # a goal keeps it while it runs
            msg = (
                f"send_action_goal {op.name}: refused, its action_type is "
                f"{len(op.action_type)} characters long: at most {MAX_TYPE_LENGTH}, e.g. "
                "'example_interfaces/action/Fibonacci'"
            )
            raise Refusal(msg, op="send_action_goal", target=op.action, op_id=op.id)
        action = self.actions.actions.get(op.name)
        if action is None:
            msg = f"Action {op.name} does not exist (no server advertised it)"
            raise ProtocolError(msg)
        return GoalRequest(op, action, self._goal_message(action, op.args))

    def _goal_message(self, action: Action, args: Any) -> Any:
        registry = self.graph.registry
        try:
            goal_type = registry.action(action.type)[0]
        except TypeNotFoundError:
            return args if args is not None else {}
        try:
            if args is None:
                args = {}
            elif isinstance(args, list):
                names = [f.name for f in registry.spec(goal_type).fields]
                args = positional_args(args, names, f"goal of {action.type}")
            return self.graph.converter.from_json(goal_type, args)
        except ConversionError as err:
            msg = f"invalid goal for {action.type}: {err}"
            raise ProtocolError(msg) from None

    def _send_goal(self, peer: Client, request: GoalRequest, now: float) -> None:
        op = request.op
        session = peer.session
        session.start_goal(op.name, op.id)  # raises Refusal past the client's budgets
        self.actions.submit(
            peer,
            request.action,
            request.message,
            ClientGoal(peer, op.id, op.action, op.feedback),
            sent_type=op.action_type,
            release=session.end_goal,
            timeout=session.limits.goal_timeout,
            now=now,
        )

    @staticmethod
    def refused(peer: Client, action: str, op_id: OpId | None, reason: str) -> None:
        """Answer a goal that was not accepted: ``action_result`` false, status 0."""
        peer.send(json_frame(failed(action, op_id, reason)))

    # -- action_feedback, action_result (2.13, 2.14) ------------------------------------------

    def _served_goal(self, peer: Client, op_id: Any, what: str) -> Goal:
        goal = None
        if isinstance(op_id, str) and op_id.startswith(_PREFIX):
            number = op_id.rpartition(":")[2]
            if number.isdigit():
                goal = self.actions.goals.get(int(number))
        if goal is None or goal.action.provider is not peer or goal_id(goal) != op_id:
            msg = f"{what} for unknown or finished goal id {op_id!r}"
            raise ProtocolError(msg)
        return goal

    def _complete(self, goal: Goal, part: int, values: Any, what: str) -> Any:
        """Check and complete feedback (part 2) or result (part 1) values of a known type."""
        try:
            name = self.graph.registry.action(goal.action.type)[part]
        except TypeNotFoundError:
            return values
        try:
            return self.graph.converter.from_json(name, {} if values is None else values)
        except ConversionError as err:
            msg = f"{what} for {goal.action.name}: {err}"
            raise ProtocolError(msg) from None

    def _admit_feedback(
        self, peer: Client, session: Session, op: o.ActionFeedback, now: float
    ) -> GoalUpdate:
        goal = self._served_goal(peer, op.id, "action_feedback")
        return GoalUpdate(goal, op, self._complete(goal, 2, op.values, "action_feedback"))

    def _admit_result(
        self, peer: Client, session: Session, op: o.ActionResult, now: float
    ) -> GoalUpdate:
        goal = self._served_goal(peer, op.id, "action_result")
        if op.result is False:  # a failure: its reason goes to the caller as it is
            return GoalUpdate(goal, op, op.values)
        return GoalUpdate(goal, op, self._complete(goal, 1, op.values, "action_result"))

    def _feedback(self, peer: Client, update: GoalUpdate, now: float) -> None:
        update.goal.feedback(update.values)

    def _result(self, peer: Client, update: GoalUpdate, now: float) -> None:
        op = update.op
        assert isinstance(op, o.ActionResult)
        goal, values = update.goal, update.values
        if op.result is False:
            reason = values if values is not None else "goal aborted by its action server"
            goal.finish(ABORTED, reason, ok=False)
            return
        goal.finish(op.status if op.status in (SUCCEEDED, CANCELED) else ABORTED, values)

    # -- cancel_action_goal (2.15) -------------------------------------------------------------

    def _cancel(self, peer: Client, op: o.CancelActionGoal, now: float) -> None:
        for goal in self.actions.goals.values():
            client = goal.client
            if (
                goal.caller is peer
                and isinstance(client, ClientGoal)
                and client.op_id == op.id
                and goal.action.name == op.name
            ):
                self.actions.cancel(goal)
                return
        # already finished or never sent: nothing to cancel (as rosbridge)
