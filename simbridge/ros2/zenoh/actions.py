"""ROS 2 actions over Zenoh, both ways, as rcl_action composes them on rmw_zenoh.

rmw_zenoh has no actions of its own: rcl_action makes an action ``/NAME`` of type
``pkg/action/Foo`` from three services and two topics, and rmw_zenoh declares each as it declares
any service or topic (``docs/design.md``, "Actions"):

* ``/NAME/_action/send_goal`` (``pkg/action/Foo_SendGoal``: ``goal_id`` and ``goal`` in,
  ``accepted`` and ``stamp`` out);
* ``/NAME/_action/cancel_goal`` (``action_msgs/srv/CancelGoal``);
* ``/NAME/_action/get_result`` (``pkg/action/Foo_GetResult``: ``goal_id`` in, ``status`` and
  ``result`` out, answered once the goal has ended: rmw_zenoh's client queries never time out);
* ``/NAME/_action/feedback`` (``pkg/action/Foo_FeedbackMessage``: ``goal_id`` and ``feedback``);
* ``/NAME/_action/status`` (``action_msgs/msg/GoalStatusArray``, transient local, depth 1).

The bridge works on the graph's action table (:mod:`simbridge.graph.actions`) with canonical
messages, CDR in and out: no rosbridge op, frame or JSON on its path.

**Outward** (:class:`ActionBridge`, owned by :class:`simbridge.ros2.zenoh.link.ZenohLink`): every
action of simbridge's graph (in-process servers such as ``/fibonacci`` and
``/tf2_web_republisher``, and actions rosbridge clients advertise) is declared so. A ROS 2
client's ``send_goal`` becomes a goal of the table (:meth:`ActionTable.submit
<simbridge.graph.actions.ActionTable.submit>`) under the client's own goal id, sent by the link's
peer (the ROS 2 side, as the guard's role for ROS 2 peers admits it) with a :class:`_Served` as
its caller side: its feedback goes out on the feedback topic, its result to ``get_result``, and
``cancel_goal`` is the graph's own cancel service. ROS 2 clients' goals in flight are counted
against ``max_pending_goals`` (at most :data:`MAX_GOALS` per action), and a goal to an action a
client serves is aborted after ``max_goal_timeout``. Finished results stay available for
:data:`RESULT_KEEP` seconds (rcl_action's default ``result_timeout``), at most
:data:`RESULT_HISTORY` per action.

**Inward**: an action another rmw_zenoh process serves (its ``send_goal`` token) joins the
graph's action table as provided by the link's peer, served by a :class:`_RemoteAction`, so
rosapi lists it and rosbridge clients send goals, get feedback and results, and cancel; goals
become ``send_goal`` and ``get_result`` queries, cancels ``cancel_goal`` queries, and the feedback
topic is subscribed while the action exists.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any, Protocol

from simbridge.errors import SimbridgeError, TypeNotFoundError
from simbridge.graph.actions import ABORTED, CANCELED, SUCCEEDED, UNKNOWN, Action, Goal
from simbridge.ros2.names import DEFAULT_QOS, LATCHED_QOS, Entity, Qos
from simbridge.ros2.zenoh.attachment import Attachment


if TYPE_CHECKING:
    from collections import Counter

    from simbridge.app.settings import ServerSettings
    from simbridge.graph import Graph, Peer
    from simbridge.msgs.cdr import CdrWriter


__all__ = [
    "CANCEL_TYPE",
    "MAX_GOALS",
    "RESULT_HISTORY",
    "RESULT_KEEP",
    "STATUS_TYPE",
    "ActionBridge",
    "ActionLink",
    "split_action",
]

logger = logging.getLogger(__name__)

STATUS_TYPE = "action_msgs/msg/GoalStatusArray"
CANCEL_TYPE = "action_msgs/srv/CancelGoal"
_INFIX = "/_action/"
#: Seconds a finished goal's result stays available to ``get_result`` (rcl_action's default).
RESULT_KEEP = 900.0
#: Finished goals kept per action at most (a client sending many goals cannot grow it).
RESULT_HISTORY = 100
#: Goals of ROS 2 clients in flight at once, per action.
MAX_GOALS = 64
#: ``get_result`` queries waiting on one goal at most.
MAX_WAITERS = 8
#: Seconds a ``send_goal`` or ``cancel_goal`` query to another process waits for its reply.
CALL_TIMEOUT = 10.0
#: Seconds a ``get_result`` query to another process waits (as long as any goal runs).
RESULT_TIMEOUT = 7 * 24 * 3600.0


class ActionLink(Protocol):
    """What the bridge uses of its :class:`~simbridge.ros2.zenoh.link.ZenohLink` (public API).

    Named here as a protocol so that the two modules do not import each other.
    """

    #: The graph mapped onto ROS 2.
    graph: Graph
    #: The server's settings (the goals' budgets).
    settings: ServerSettings
    #: The link's counters (``bad_payloads``, ``unknown_types``, ...).
    stats: Counter[str]
    #: Writes canonical messages as CDR.
    cdr: CdrWriter

    @property
    def peer(self) -> Peer:
        """The ROS 2 side as one peer of the graph (its access is the ROS 2 peers' role)."""

    def now(self) -> float:
        """Return the event loop's monotonic time (the graph's ``now``)."""

    def decode(self, type_name: str, payload: bytes) -> Any:
        """Return the canonical message of CDR bytes (raises whatever the reader raises)."""

    def reply(self, query: Any, response_type: str, msg: Any, attachment: Attachment) -> None:
        """Reply to a query from ROS 2 with a canonical response message."""

    def fail(self, query: Any, text: str) -> None:
        """Reply to a query from ROS 2 with an error."""

    def publish(self, node: str, name: str, payload: bytes) -> bool:
        """Publish CDR bytes on the publisher of ``name`` declared under ``node``, if any."""

    def subscribe(
        self, name: str, type_name: str, take: Callable[[bytes], None]
    ) -> Callable[[], None] | None:
        """Subscribe to the remote publishers of ``name``; return the undeclare (None: failed).

        Samples reach ``take`` on the event loop, within the link's inbox budgets.
        """

    def query(
        self,
        entity: Entity,
        request_type: str,
        request: Any,
        timeout: float,
        on_reply: Callable[[bytes], None],
        on_error: Callable[[str], None],
    ) -> None:
        """Send a canonical request to a remote service; call back on the event loop."""

    def log(self, key: str, text: str) -> None:
        """Log a warning at most once in a while per ``key``."""

    def note(self, key: str, text: str) -> None:
        """Count a name clash; log it once."""


def split_action(name: str) -> tuple[str, str] | None:
    """Split ``/NAME/_action/PART`` into (``/NAME``, ``PART``); None for any other name."""
    head, sep, part = name.rpartition(_INFIX)
    if not sep or not head or "/" in part:
        return None
    return head, part


class _Served:
    """A goal a ROS 2 client sent to an action of this process: the goal's caller side."""

    __slots__ = ("bridge", "ended", "goal", "message", "name", "status", "uuid", "waiters")

    def __init__(self, bridge: ActionBridge, name: str, goal_uuid: bytes) -> None:
        self.bridge = bridge
        self.name = name
        self.uuid = goal_uuid
        self.goal: Goal | None = None
        self.status = UNKNOWN
        #: The result message (canonical) once the goal has ended (None: the default).
        self.message: Any = None
        self.ended = math.inf
        #: ``get_result`` queries waiting for the end: (query, request attachment).
        self.waiters: list[tuple[Any, Attachment]] = []

    @property
    def done(self) -> bool:
        return self.ended != math.inf

    def feedback(self, values: Any) -> None:
        """Publish the feedback on ``NAME/_action/feedback``."""
        self.bridge._feedback(self, values)

    def result(self, status: int, values: Any, ok: bool) -> None:
        """Keep the result for ``get_result`` and answer those waiting."""
        self.bridge._ended(self, status, values, ok)


class _RemoteAction:
    """An action another ROS 2 process serves, as the graph's server of it (goals -> queries)."""

    __slots__ = ("bridge", "name", "node", "parts", "type", "unsubscribe")

    def __init__(self, bridge: ActionBridge, name: str, type_name: str, node: str) -> None:
        self.bridge = bridge
        self.name = name
        self.type = type_name
        self.node = node
        #: The remote entities: "send_goal", "get_result", "cancel_goal", "feedback".
        self.parts: dict[str, Entity] = {}
        self.unsubscribe: Callable[[], None] | None = None

    def goal(self, goal: Goal) -> None:
        """Send the goal as a ``send_goal`` query, then wait for it with ``get_result``."""
        self.bridge._send_remote(self, goal)

    def cancel(self, goal: Goal) -> None:
        """Send a ``cancel_goal`` query for the goal."""
        self.bridge._cancel_remote(self, goal)


class ActionBridge:
    """Actions between simbridge's graph and the ROS 2 graph (see the module doc)."""

    def __init__(self, link: ActionLink) -> None:
        self.link = link
        self.graph = link.graph
        #: Outward: goals of ROS 2 clients, by (action, goal UUID).
        self._served: dict[tuple[str, bytes], _Served] = {}
        #: Goals of ROS 2 clients in flight (against ``max_pending_goals``).
        self.pending = 0
        #: Inward: remote actions in the graph, by name.
        self.imported: dict[str, _RemoteAction] = {}

    # -- outward: declarations ------------------------------------------------------------

    def wanted(self) -> dict[tuple[str, str, str], tuple[str, str, Qos]]:
        """Return the entities of the graph's own actions: (kind, node, name) -> (kind, type, QoS).

        ``cancel_goal`` is not here: it is in the graph's service table already.
        """
        want: dict[tuple[str, str, str], tuple[str, str, Qos]] = {}
        registry = self.graph.registry
        ros2 = self.link.peer
        for action in self.graph.actions.actions.values():
            if action.provider is ros2:
                continue  # another process's action, in the graph
            try:
                send_goal, get_result, feedback = registry.action_wire(action.type)
            except TypeNotFoundError:
                continue  # a client's action of a type simbridge does not know
            base = action.name + _INFIX
            node = action.node
            want[("SS", node, base + "send_goal")] = ("SS", send_goal, DEFAULT_QOS)
            want[("SS", node, base + "get_result")] = ("SS", get_result, DEFAULT_QOS)
            want[("MP", node, base + "feedback")] = ("MP", feedback, DEFAULT_QOS)
            want[("MP", node, base + "status")] = ("MP", STATUS_TYPE, LATCHED_QOS)
        return want

    def exports_service(self, name: str) -> bool:
        """Return whether a graph service should be declared (not a remote action's cancel)."""
        parts = split_action(name)
        return parts is None or parts[0] not in self.imported

    def handles(self, name: str) -> bool:
        """Return whether a query on service ``name`` is one of the action's own."""
        parts = split_action(name)
        return parts is not None and parts[1] in ("send_goal", "get_result")

    # -- outward: queries from ROS 2 ----------------------------------------------------------

    def on_query(self, name: str, type_name: str, query: Any, attachment: Attachment) -> None:
        """Answer a ``send_goal`` or ``get_result`` query (the event loop)."""
        parts = split_action(name)
        assert parts is not None
        action_name, part = parts
        link = self.link
        action = self.graph.actions.actions.get(action_name)
        if action is None:
            link.fail(query, f"action {action_name} does not exist (any more)")
            return
        request_type, response_type = self.graph.registry.service(type_name)
        if type_name not in self._wire(action.type):
            link.fail(query, f"action {action_name} is of type {action.type} now")
            return
        try:
            payload = bytes(query.payload.to_bytes()) if query.payload is not None else b""
            request = link.decode(request_type, payload)
            goal_id = bytes(request["goal_id"]["uuid"])
        except Exception as err:  # whatever the network sent: reported, never raised
            link.stats["bad_payloads"] += 1
            link.fail(query, f"{name}: request is not CDR of {request_type}: {err}")
            return
        if part == "send_goal":
            self._send_goal(action, request["goal"], goal_id, query, response_type, attachment)
        else:
            self._get_result(action, goal_id, query, response_type, attachment)

    def _wire(self, action_type: str) -> tuple[str, ...]:
        try:
            return self.graph.registry.action_wire(action_type)
        except TypeNotFoundError:
            return ()

    def _send_goal(
        self,
        action: Action,
        message: Any,
        goal_id: bytes,
        query: Any,
        response_type: str,
        attachment: Attachment,
    ) -> None:
        name = action.name
        link = self.link

        def answer(accepted: bool, stamp: tuple[int, int] = (0, 0)) -> None:
            msg = {"accepted": accepted, "stamp": {"sec": stamp[0], "nanosec": stamp[1]}}
            link.reply(query, response_type, msg, attachment)

        settings = link.settings
        # the graph's rule for a goal (not another robot's action), for the ROS 2 peers' role
        refusal = self.graph.access.reach_refusal(link.peer.access, name)
        if refusal is None and (name, goal_id) in self._served:
            refusal = f"goal id {goal_id.hex()} is in use"
        elif refusal is None and self.pending >= settings.max_pending_goals:
            refusal = (
                f"{settings.max_pending_goals} goals of ROS 2 clients in flight already (the "
                "server's max_pending_goals)"
            )
        elif refusal is None and (
            sum(1 for s in self._served.values() if s.name == name and not s.done) >= MAX_GOALS
        ):
            refusal = f"{MAX_GOALS} goals of ROS 2 clients in flight already"
        if refusal is not None:
            link.log(f"goal {name}", f"Zenoh: goal for {name} rejected: {refusal}")
            answer(False)
            return
        served = _Served(self, name, goal_id)
        self._served[(name, goal_id)] = served
        self.pending += 1
        # the message is canonical and complete: CDR of the goal type; a goal to an action a
        # client serves is aborted after max_goal_timeout (one that never answered held ROS 2's
        # goals for ever)
        goal = self.graph.actions.submit(
            link.peer,
            action,
            message,
            served,
            goal_uuid=goal_id,
            release=self._release,
            timeout=settings.max_goal_timeout,
            now=link.now(),
        )
        served.goal = goal
        if not served.done:
            served.status = goal.status
        answer(True, goal.stamp)
        self.publish_status(name)

    def _release(self) -> None:
        self.pending -= 1

    def _get_result(
        self, action: Action, goal_id: bytes, query: Any, response_type: str, attachment: Attachment
    ) -> None:
        served = self._served.get((action.name, goal_id))
        if served is None:  # as rcl_action: an unknown goal's result is status UNKNOWN
            self._answer_result(action.type, UNKNOWN, None, query, response_type, attachment)
            return
        if served.done:
            self._answer_result(
                action.type, served.status, served.message, query, response_type, attachment
            )
            return
        if len(served.waiters) >= MAX_WAITERS:
            text = f"{MAX_WAITERS} get_result calls wait for this goal already"
            self.link.fail(query, text)
            return
        served.waiters.append((query, attachment))

    def _answer_result(
        self,
        action_type: str,
        status: int,
        result: Any,
        query: Any,
        response_type: str,
        attachment: Attachment,
    ) -> None:
        if result is None:
            result = self.graph.converter.default(self.graph.registry.action(action_type)[1])
        self.link.reply(query, response_type, {"status": status, "result": result}, attachment)

    def _complete(self, type_name: str, values: Any) -> Any:
        """Return ``values`` with the fields a server left out at their defaults."""
        if not isinstance(values, dict):
            return self.graph.converter.default(type_name)
        fields = self.graph.registry.spec(type_name).fields
        if all(f.name in values for f in fields):
            return values
        return {**self.graph.converter.default(type_name), **values}

    # -- outward: the graph's answers to ROS 2 goals ----------------------------------------

    def _feedback(self, served: _Served, values: Any) -> None:
        goal = served.goal
        if goal is None or served.done:
            return
        action = goal.action
        registry = self.graph.registry
        try:
            feedback_type = registry.action(action.type)[2]
            message_type = registry.action_wire(action.type)[2]
            msg = {
                "goal_id": {"uuid": served.uuid},
                "feedback": self._complete(feedback_type, values),
            }
            payload = self.link.cdr.serialize(message_type, msg)
        except Exception as err:  # feedback its CDR type cannot hold: skipped, said once
            self.link.log(f"feedback {action.name}", f"Zenoh: {action.name} feedback: {err}")
            return
        self.link.publish(action.node, action.name + _INFIX + "feedback", payload)

    def _ended(self, served: _Served, status: int, values: Any, ok: bool) -> None:
        if not ok or status not in (SUCCEEDED, CANCELED, ABORTED):
            status = ABORTED
        action = served.goal.action if served.goal is not None else None
        result = None
        if ok and action is not None:
            try:
                result_type = self.graph.registry.action(action.type)[1]
                result = self._complete(result_type, values)
                self.link.cdr.serialize(result_type, result)  # checked once, for every waiter
            except Exception as err:  # a result its CDR type cannot hold: the goal aborted
                self.link.log(f"result {served.name}", f"Zenoh: {served.name}: {err}")
                status, result = ABORTED, None
        served.status, served.message = status, result
        served.ended = time.monotonic()
        if action is not None:
            response_type = self.graph.registry.action_wire(action.type)[1] + "_Response"
            for query, attachment in served.waiters:
                self._answer_result(action.type, status, result, query, response_type, attachment)
        served.waiters.clear()
        self._prune(served.name)
        self.publish_status(served.name)

    def publish_status(self, name: str) -> None:
        """Publish ``NAME/_action/status``: every goal in flight and the ROS 2 goals kept."""
        action = self.graph.actions.actions.get(name)
        if action is None:
            return
        listed: dict[bytes, dict[str, Any]] = {}
        for served in self._served.values():
            if served.name == name and served.goal is not None:
                status = served.status if served.done else served.goal.status
                listed[served.uuid] = _status(served.uuid, served.goal.stamp, status)
        for goal in self.graph.actions.goals.values():
            if goal.action is action:
                listed[goal.uuid] = _status(goal.uuid, goal.stamp, goal.status)
        msg = {"status_list": list(listed.values())}
        try:
            payload = self.link.cdr.serialize(STATUS_TYPE, msg)
        except SimbridgeError as err:
            self.link.log(f"status {name}", f"Zenoh: {name} status: {err}")
            return
        self.link.publish(action.node, name + _INFIX + "status", payload)

    def cancelled(self, service: str) -> None:
        """The graph answered a ``cancel_goal`` call from ROS 2: publish the new statuses."""
        parts = split_action(service)
        if parts is not None:
            self.publish_status(parts[0])

    def _prune(self, name: str) -> None:
        ended = sorted(
            (s.ended, key) for key, s in self._served.items() if s.name == name and s.done
        )
        now = time.monotonic()
        for index, (when, key) in enumerate(ended):
            if now - when > RESULT_KEEP or index < len(ended) - RESULT_HISTORY:
                del self._served[key]

    def tick(self) -> None:
        """Forget results kept past :data:`RESULT_KEEP`."""
        now = time.monotonic()
        for key in [k for k, s in self._served.items() if now - s.ended > RESULT_KEEP]:
            del self._served[key]

    # -- inward -----------------------------------------------------------------------------

    def import_remote(self, entities: list[Entity]) -> None:
        """Make the graph hold exactly the remote actions the tokens show (their send_goal)."""
        found: dict[str, dict[str, Entity]] = {}
        for entity in entities:
            split = split_action(entity.name)
            if split is None:
                continue
            name, part = split
            kind = {"SS": ("send_goal", "get_result", "cancel_goal"), "MP": ("feedback",)}
            if part in kind.get(entity.kind, ()):
                found.setdefault(name, {}).setdefault(part, entity)
        actions = self.graph.actions
        link = self.link
        for name in [n for n in self.imported if "send_goal" not in found.get(n, {})]:
            self._drop(self.imported.pop(name))
        for name, parts in found.items():
            if name in self.imported or "send_goal" not in parts:
                continue
            entity = parts["send_goal"]
            type_name = entity.type.removesuffix("_SendGoal")
            if type_name == entity.type or "get_result" not in parts:
                continue
            if type_name not in self.graph.registry.actions:
                link.log(
                    f"type {type_name}",
                    f"Zenoh: action {name} of {entity.node_fqn} has type {type_name}, unknown "
                    "here: not bridged",
                )
                link.stats["unknown_types"] += 1
                continue
            existing = actions.actions.get(name)
            if existing is not None:
                link.note(
                    f"clash {name}",
                    f"Zenoh: action {name} of {entity.node_fqn} (session {entity.zid}) not "
                    f"bridged: {existing.node} here serves it already",
                )
                continue
            remote = _RemoteAction(self, name, type_name, entity.node_fqn)
            remote.parts = parts
            actions.provide(
                link.peer,
                name,
                type_name,
                entity.node_fqn,
                remote,
                lost=partial(self._lost, name),
            )
            self._subscribe_feedback(remote)
            self.imported[name] = remote
        for name, remote in self.imported.items():
            remote.parts.update(found.get(name, {}))

    def _lost(self, name: str) -> None:
        """A client took the name of a remote action over: it is no longer bridged."""
        remote = self.imported.pop(name, None)
        if remote is not None and remote.unsubscribe is not None:
            _quietly(remote.unsubscribe)
            remote.unsubscribe = None

    def _drop(self, remote: _RemoteAction) -> None:
        if remote.unsubscribe is not None:
            _quietly(remote.unsubscribe)
            remote.unsubscribe = None
        action = self.graph.actions.actions.get(remote.name)
        if action is not None and action.server is remote:
            # fails the goals in flight, with the reason, to their senders
            self.graph.actions.withdraw(self.link.peer, remote.name)

    def close(self) -> None:
        """Undeclare the feedback subscribers."""
        for remote in self.imported.values():
            if remote.unsubscribe is not None:
                _quietly(remote.unsubscribe)
                remote.unsubscribe = None

    def _subscribe_feedback(self, remote: _RemoteAction) -> None:
        message_type = self.graph.registry.action_wire(remote.type)[2]

        def take(payload: bytes) -> None:
            self._on_feedback(remote, payload)

        remote.unsubscribe = self.link.subscribe(
            remote.name + _INFIX + "feedback", message_type, take
        )

    def _on_feedback(self, remote: _RemoteAction, payload: bytes) -> None:
        message_type = self.graph.registry.action_wire(remote.type)[2]
        link = self.link
        try:
            msg = link.decode(message_type, payload)
            goal_id = bytes(msg["goal_id"]["uuid"])
        except Exception as err:  # whatever the network sent: reported, never raised
            link.stats["bad_payloads"] += 1
            text = f"Zenoh: {remote.name} feedback is not CDR of {message_type}: {err}"
            link.log(f"bad {remote.name}", text)
            return
        for goal in self.graph.actions.goals.values():
            if goal.action.server is remote and goal.uuid == goal_id:
                goal.feedback(msg["feedback"])
                return

    def _send_remote(self, remote: _RemoteAction, goal: Goal) -> None:
        """The graph sends a goal to a remote action: ``send_goal``, then ``get_result``."""
        send_goal, get_result, _ = self.graph.registry.action_wire(remote.type)

        def failed(text: str) -> None:
            goal.finish(ABORTED, text, ok=False)

        def result(data: bytes) -> None:
            reply = self.link.decode(f"{get_result}_Response", data)
            status = int(reply["status"])
            if status in (SUCCEEDED, CANCELED, ABORTED):
                goal.finish(status, reply["result"])
            else:
                text = f"the action server {remote.node} gave status {status} for the result"
                goal.finish(ABORTED, text, ok=False)

        def accepted(data: bytes) -> None:
            reply = self.link.decode(f"{send_goal}_Response", data)
            if not reply["accepted"]:
                goal.finish(UNKNOWN, f"goal rejected by the action server {remote.node}", ok=False)
                return
            request = {"goal_id": {"uuid": goal.uuid}}
            self._query(
                remote,
                "get_result",
                f"{get_result}_Request",
                request,
                result,
                failed,
                RESULT_TIMEOUT,
            )

        request = {"goal_id": {"uuid": goal.uuid}, "goal": goal.args}
        self._query(
            remote, "send_goal", f"{send_goal}_Request", request, accepted, failed, CALL_TIMEOUT
        )

    def _cancel_remote(self, remote: _RemoteAction, goal: Goal) -> None:
        """The graph cancels a goal of a remote action: a ``cancel_goal`` query."""
        request = {"goal_info": {"goal_id": {"uuid": goal.uuid}, "stamp": {"sec": 0, "nanosec": 0}}}

        def refused(text: str) -> None:
            self.link.log(f"cancel {remote.name}", f"Zenoh: cancel {remote.name}: {text}")

        self._query(
            remote,
            "cancel_goal",
            "action_msgs/srv/CancelGoal_Request",
            request,
            lambda data: None,
            refused,
            CALL_TIMEOUT,
        )

    def _query(
        self,
        remote: _RemoteAction,
        part: str,
        request_type: str,
        request: Any,
        on_reply: Callable[[bytes], None],
        on_error: Callable[[str], None],
        timeout: float,
    ) -> None:
        """Send one query to a part of a remote action; call back on the event loop."""
        entity = remote.parts.get(part)
        if entity is None:
            on_error(f"action {remote.name} has no {part} service (any more)")
            return
        self.link.query(entity, request_type, request, timeout, on_reply, on_error)


def _status(goal_id: bytes, stamp: tuple[int, int], status: int) -> dict[str, Any]:
    return {
        "goal_info": {
            "goal_id": {"uuid": goal_id},
            "stamp": {"sec": stamp[0], "nanosec": stamp[1]},
        },
        "status": status,
    }


def _quietly(action: Callable[[], Any]) -> None:
    try:
        action()
    except Exception as err:
        logger.debug("Zenoh: %s", err)
