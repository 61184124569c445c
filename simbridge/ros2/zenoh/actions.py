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

**Outward** (:class:`ActionBridge`, owned by :class:`simbridge.ros2.zenoh.link.ZenohLink`): every
action of simbridge's graph (in-process servers such as ``/fibonacci`` and
``/tf2_web_republisher``, and actions rosbridge clients advertise) is declared so; a ROS 2
client's goal becomes a goal of the graph's action table under the client's own goal id, its
feedback and result go back on the feedback topic and to ``get_result``, and ``cancel_goal`` is
the graph's own cancel service. Finished results stay available for
:data:`RESULT_KEEP` seconds (rcl_action's default ``result_timeout``), at most
:data:`RESULT_HISTORY` per action.

**Inward**: an action another rmw_zenoh process serves (its ``send_goal`` token) joins the
graph's action table, so rosapi lists it and rosbridge clients send goals, get feedback and
results, and cancel; goals become ``send_goal`` and ``get_result`` queries, cancels
``cancel_goal`` queries, and the feedback topic is subscribed while the action exists.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import orjson

from simbridge.errors import ConversionError, ProtocolError, SimbridgeError, TypeNotFoundError
from simbridge.graph.access import Access
from simbridge.graph.actions import ABORTED, CANCELED, SUCCEEDED, UNKNOWN, Action, Goal
from simbridge.ros2.names import DEFAULT_QOS, LATCHED_QOS, Entity, Qos, dds_type
from simbridge.ros2.zenoh.attachment import Attachment
from simbridge.rosbridge import Frame, Session


if TYPE_CHECKING:
    import asyncio
    from collections import Counter

    from simbridge.graph import Graph
    from simbridge.msgs.cdr import CdrWriter
    from simbridge.ros2.zenoh.config import ZenohOptions


class ZenohLink(Protocol):
    """What the bridge uses of :class:`simbridge.ros2.zenoh.link.ZenohLink`, which owns the bridge.

    Named here as a protocol so that the two modules do not import each other.
    """

    graph: Graph
    options: ZenohOptions
    cdr: CdrWriter
    stats: Counter[str]
    session: Any
    zenoh: Any
    zid: str
    _loop: asyncio.AbstractEventLoop | None
    _declared: dict[tuple[str, str, str], Any]
    _caller: Any
    rosbridge: Any

    def _decode(self, type_name: str, payload: bytes) -> Any: ...
    def _reply(self, query: Any, response_type: str, msg: Any, attachment: Attachment) -> None: ...
    def _fail_query(self, query: Any, text: str) -> None: ...
    def _put_bytes(self, entry: Any, payload: bytes, *, count: bool = False) -> bool: ...
    def _log(self, key: str, text: str) -> None: ...
    def _note(self, key: str, text: str) -> None: ...
    def hand_over(self, take: Any, name: str, payload: Any) -> None: ...
    def client_attachment(self, entity: Entity, sequence: int) -> bytes: ...
    def _query(
        self,
        entity: Entity,
        payload: bytes,
        attachment: bytes,
        timeout: float,
        done: Callable[[list[tuple[bool, bytes]]], None],
    ) -> None: ...


__all__ = [
    "CANCEL_TYPE",
    "RESULT_HISTORY",
    "RESULT_KEEP",
    "STATUS_TYPE",
    "ActionBridge",
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


def split_action(name: str) -> tuple[str, str] | None:
    """Split ``/NAME/_action/PART`` into (``/NAME``, ``PART``); None for any other name."""
    head, sep, part = name.rpartition(_INFIX)
    if not sep or not head or "/" in part:
        return None
    return head, part


@dataclass(eq=False, slots=True)
class _Served:
    """A goal a ROS 2 client sent to an action of this process."""

    action: str
    uuid: bytes
    goal: Goal | None = None
    status: int = UNKNOWN
    #: The result message (canonical) once the goal has ended.
    result: Any = None
    ended: float = math.inf
    #: ``get_result`` queries waiting for the end: (query, request attachment).
    waiters: list[tuple[Any, Attachment]] = field(default_factory=list)

    @property
    def done(self) -> bool:
        return self.ended != math.inf


class _ActionProvider:
    """The peer that serves a remote ROS 2 action to the graph (goals become queries)."""

    def __init__(self, bridge: ActionBridge, session: Session, name: str, type_name: str) -> None:
        self.bridge = bridge
        self.session = session
        self.name = name
        self.type = type_name
        #: The remote entities: "send_goal", "get_result", "cancel_goal", "feedback".
        self.parts: dict[str, Entity] = {}
        self.node = ""
        self.label = f"ROS 2 action {name} (Zenoh)"
        self.subscriber: Any = None

    @property
    def access(self) -> Access:
        """Who the peer is for the graph's rules (its session's access)."""
        return self.session.access

    def send(self, frame: Frame, key: object = None, limit: int = 0) -> None:
        self.bridge._provider_frame(self, orjson.loads(frame.data))


class ActionBridge:
    """Actions between simbridge's graph and the ROS 2 graph (see the module doc)."""

    def __init__(self, link: ZenohLink) -> None:
        self.link = link
        self.graph = link.graph
        #: Outward: goals of ROS 2 clients by the op id the graph answers under.
        self._served: dict[str, _Served] = {}
        self._by_uuid: dict[tuple[str, bytes], _Served] = {}
        self._ids = itertools.count(1)
        #: Inward: remote actions in the graph, by name.
        self.imported: dict[str, _ActionProvider] = {}
        self._calls = itertools.count(1)

    # -- outward: declarations ------------------------------------------------------------

    def wanted(self) -> dict[tuple[str, str, str], tuple[str, str, Qos]]:
        """Return the entities of the graph's own actions: (kind, node, name) -> (kind, type, QoS).

        ``cancel_goal`` is not here: it is in the graph's service table already.
        """
        want: dict[tuple[str, str, str], tuple[str, str, Qos]] = {}
        registry = self.graph.registry
        for action in self.graph.actions.actions.values():
            if isinstance(action.provider, _ActionProvider):
                continue
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
        action = self.graph.actions.actions.get(action_name)
        if action is None:
            self.link._fail_query(query, f"action {action_name} does not exist (any more)")
            return
        request_type, response_type = self.graph.registry.service(type_name)
        try:
            payload = bytes(query.payload.to_bytes()) if query.payload is not None else b""
            request = self.link._decode(request_type, payload)
            goal_id = bytes(request["goal_id"]["uuid"])
        except Exception as err:  # whatever the network sent: reported, never raised
            self.link.stats["bad_payloads"] += 1
            text = f"{name}: request is not CDR of {request_type}: {err}"
            self.link._fail_query(query, text)
            return
        if part == "send_goal":
            self._send_goal(action, request, goal_id, query, response_type, attachment)
        else:
            self._get_result(action, goal_id, query, response_type, attachment)

    def _send_goal(
        self,
        action: Action,
        request: Any,
        goal_id: bytes,
        query: Any,
        response_type: str,
        attachment: Attachment,
    ) -> None:
        name = action.name

        def answer(accepted: bool, stamp: tuple[int, int] = (0, 0)) -> None:
            msg = {"accepted": accepted, "stamp": {"sec": stamp[0], "nanosec": stamp[1]}}
            self.link._reply(query, response_type, msg, attachment)

        mine = [s for s in self._served.values() if s.action == name and not s.done]
        # the scope rule of a rosbridge client's send_action_goal, for the ROS 2 peers' role
        refusal = self.graph.access.reach_refusal(self.link._caller.access, name)
        if refusal is None and (name, goal_id) in self._by_uuid:
            refusal = f"goal id {goal_id.hex()} is in use"
        elif refusal is None and len(mine) >= MAX_GOALS:
            refusal = f"{MAX_GOALS} goals of ROS 2 clients in flight already"
        if refusal is not None:
            self.link._log(f"goal {name}", f"Zenoh: goal for {name} rejected: {refusal}")
            answer(False)
            return
        op_id = f"zenoh-goal:{next(self._ids)}"
        served = _Served(name, goal_id)
        self._served[op_id] = served
        self._by_uuid[(name, goal_id)] = served
        args = orjson.loads(_json(request["goal"]))
        try:
            admitted = self.link.rosbridge.admission.goal(name, args)  # the goal validated
        except ProtocolError as err:
            self._forget(op_id)
            self.link._log(f"goal {name}", f"Zenoh: goal for {name} rejected: {err}")
            answer(False)
            return
        loop = self.link._loop
        try:
            # counted as a rosbridge client's goal: against the ROS 2 peers' max_pending_goals
            # and global_pending_goals, and aborted after max_goal_timeout when a client serves
            # the action (one that never answered held ROS 2's goals for ever)
            outcome = self.graph.actions.submit(
                self.link._caller,
                admitted.action,
                admitted.message,
                op_id=op_id,
                written=name,
                feedback=True,
                goal_uuid=goal_id,
                now=loop.time() if loop is not None else 0.0,
            )
        except ProtocolError as err:
            self._forget(op_id)
            self.link._log(f"goal {name}", f"Zenoh: goal for {name} rejected: {err}")
            answer(False)
            return
        served.goal = outcome
        if not served.done:
            served.status = outcome.status
        answer(True, outcome.stamp)
        self.publish_status(name)

    def _get_result(
        self, action: Action, goal_id: bytes, query: Any, response_type: str, attachment: Attachment
    ) -> None:
        served = self._by_uuid.get((action.name, goal_id))
        if served is None:  # as rcl_action: an unknown goal's result is status UNKNOWN
            self._answer_result(action.type, UNKNOWN, None, query, response_type, attachment)
            return
        if served.done:
            self._answer_result(
                action.type, served.status, served.result, query, response_type, attachment
            )
            return
        if len(served.waiters) >= MAX_WAITERS:
            text = f"{MAX_WAITERS} get_result calls wait for this goal already"
            self.link._fail_query(query, text)
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
            result = self._default(self.graph.registry.action(action_type)[1])
        self.link._reply(query, response_type, {"status": status, "result": result}, attachment)

    def _default(self, type_name: str) -> Any:
        return self.graph.converter.from_json(type_name, {})

    # -- outward: the graph's answers to ROS 2 goals ----------------------------------------

    def goal_event(self, body: dict[str, Any]) -> None:
        """Handle an ``action_feedback`` or ``action_result`` the graph sent a ROS 2 goal."""
        served = self._served.get(str(body.get("id")))
        if served is None:
            return
        action = self.graph.actions.actions.get(served.action)
        if body.get("op") == "action_feedback":
            if action is not None and not served.done:
                self._feedback(action, served, body.get("values"))
            return
        ok = body.get("result") is not False
        status = int(body.get("status") or 0) if ok else ABORTED
        if status not in (SUCCEEDED, CANCELED, ABORTED):
            status = ABORTED
        result = None
        if ok and action is not None:
            try:
                result_type = self.graph.registry.action(action.type)[1]
                result = self.graph.converter.from_json(result_type, body.get("values") or {})
            except (ConversionError, TypeNotFoundError) as err:
                self.link._log(f"result {served.action}", f"Zenoh: {served.action}: {err}")
                status = ABORTED
        served.status, served.result = status, result
        served.ended = time.monotonic()
        if action is not None:
            response_type = self.graph.registry.action_wire(action.type)[1] + "_Response"
            for query, attachment in served.waiters:
                self._answer_result(action.type, status, result, query, response_type, attachment)
        served.waiters.clear()
        self._prune(served.action)
        self.publish_status(served.action)

    def _feedback(self, action: Action, served: _Served, values: Any) -> None:
        try:
            feedback_type = self.graph.registry.action(action.type)[2]
            message_type = self.graph.registry.action_wire(action.type)[2]
            msg = {
                "goal_id": {"uuid": served.uuid},
                "feedback": self.graph.converter.from_json(feedback_type, values or {}),
            }
            payload = self.link.cdr.serialize(message_type, msg)
        except SimbridgeError as err:
            self.link._log(f"feedback {action.name}", f"Zenoh: {action.name} feedback: {err}")
            return
        entry = self.link._declared.get(("MP", action.node, action.name + _INFIX + "feedback"))
        if entry is not None:
            self.link._put_bytes(entry, payload, count=True)

    def publish_status(self, name: str) -> None:
        """Publish ``NAME/_action/status``: every goal in flight and the ROS 2 goals kept."""
        action = self.graph.actions.actions.get(name)
        if action is None:
            return
        entry = self.link._declared.get(("MP", action.node, name + _INFIX + "status"))
        if entry is None:
            return
        listed: dict[bytes, dict[str, Any]] = {}
        for served in self._served.values():
            if served.action == name and served.goal is not None:
                status = served.status if served.done else served.goal.status
                listed[served.uuid] = _status(served.uuid, served.goal.stamp, status)
        for goal in self.graph.actions.goals.values():
            if goal.action is action:
                listed[goal.uuid] = _status(goal.uuid, goal.stamp, goal.status)
        msg = {"status_list": list(listed.values())}
        try:
            payload = self.link.cdr.serialize(STATUS_TYPE, msg)
        except SimbridgeError as err:
            self.link._log(f"status {name}", f"Zenoh: {name} status: {err}")
            return
        self.link._put_bytes(entry, payload, count=True)

    def cancelled(self, service: str) -> None:
        """The graph answered a ``cancel_goal`` call from ROS 2: publish the new statuses."""
        parts = split_action(service)
        if parts is not None:
            self.publish_status(parts[0])

    def _prune(self, name: str) -> None:
        ended = sorted(
            (s.ended, op) for op, s in self._served.items() if s.action == name and s.done
        )
        now = time.monotonic()
        for index, (when, op) in enumerate(ended):
            if now - when > RESULT_KEEP or index < len(ended) - RESULT_HISTORY:
                self._forget(op)

    def _forget(self, op_id: str) -> None:
        served = self._served.pop(op_id, None)
        if served is not None:
            self._by_uuid.pop((served.action, served.uuid), None)

    def tick(self) -> None:
        """Forget results kept past :data:`RESULT_KEEP`."""
        now = time.monotonic()
        for op_id in [k for k, s in self._served.items() if now - s.ended > RESULT_KEEP]:
            self._forget(op_id)

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
                self.link._log(
                    f"type {type_name}",
                    f"Zenoh: action {name} of {entity.node_fqn} has type {type_name}, unknown "
                    "here: not bridged",
                )
                self.link.stats["unknown_types"] += 1
                continue
            existing = actions.actions.get(name)
            if existing is not None:
                self.link._note(
                    f"clash {name}",
                    f"Zenoh: action {name} of {entity.node_fqn} (session {entity.zid}) not "
                    f"bridged: {existing.node} here serves it already",
                )
                continue
            provider = _ActionProvider(self, self.link.rosbridge.new_session(), name, type_name)
            provider.parts = parts
            provider.node = entity.node_fqn
            actions.add_provider(name, type_name, entity.node_fqn, provider)
            self._subscribe_feedback(provider)
            self.imported[name] = provider
        for name, provider in self.imported.items():
            provider.parts.update(found.get(name, {}))

    def _drop(self, provider: _ActionProvider) -> None:
        if provider.subscriber is not None:
            _quietly(provider.subscriber.undeclare)
        # fails the goals in flight, with the reason, to their senders
        self.graph.actions.remove(provider, provider.name)

    def close(self) -> None:
        """Undeclare the feedback subscribers."""
        for provider in self.imported.values():
            if provider.subscriber is not None:
                _quietly(provider.subscriber.undeclare)
                provider.subscriber = None

    def _subscribe_feedback(self, provider: _ActionProvider) -> None:
        link = self.link
        message_type = self.graph.registry.action_wire(provider.type)[2]
        keyexpr = (
            f"{link.options.domain}/{(provider.name + _INFIX + 'feedback').strip('/')}/"
            f"{dds_type(message_type)}/*"
        )

        def take(name: str, payload: bytes) -> None:
            self._on_feedback(provider, payload)

        def on_sample(sample: Any) -> None:  # a Zenoh thread: through the link's budgets
            link.hand_over(take, provider.name, sample.payload)

        try:
            provider.subscriber = link.session.declare_subscriber(
                keyexpr, on_sample, allowed_origin=link.zenoh.Locality.REMOTE
            )
        except Exception as err:
            link._log(f"sub {keyexpr}", f"Zenoh: cannot subscribe to {keyexpr}: {err}")

    def _on_feedback(self, provider: _ActionProvider, payload: bytes) -> None:
        message_type = self.graph.registry.action_wire(provider.type)[2]
        try:
            msg = self.link._decode(message_type, payload)
            goal_id = bytes(msg["goal_id"]["uuid"])
        except Exception as err:  # whatever the network sent: reported, never raised
            self.link.stats["bad_payloads"] += 1
            text = f"Zenoh: {provider.name} feedback is not CDR of {message_type}: {err}"
            self.link._log(f"bad {provider.name}", text)
            return
        goal = self._remote_goal(provider, goal_id)
        if goal is not None:
            goal.feedback(msg["feedback"])

    def _remote_goal(self, provider: _ActionProvider, goal_id: bytes) -> Goal | None:
        for goal in self.graph.actions.goals.values():
            if goal.action.provider is provider and goal.uuid == goal_id:
                return goal
        return None

    def _provider_frame(self, provider: _ActionProvider, body: dict[str, Any]) -> None:
        """The graph sends a goal or a cancel to a remote action: make it a query."""
        goal = self.graph.actions.goals.get(str(body.get("id")))
        if goal is None or goal.action.provider is not provider:
            return
        registry = self.graph.registry
        send_goal, get_result, _ = registry.action_wire(provider.type)
        if body.get("op") == "send_action_goal":
            request = {"goal_id": {"uuid": goal.uuid}, "goal": goal.args}

            def accepted(payload: bytes) -> None:
                reply = self.link._decode(f"{send_goal}_Response", payload)
                if not reply["accepted"]:
                    text = f"goal rejected by the action server {provider.node}"
                    goal.finish(UNKNOWN, text, result=False)
                    return
                self._query(
                    provider,
                    "get_result",
                    f"{get_result}_Request",
                    {"goal_id": {"uuid": goal.uuid}},
                    lambda data: self._result(provider, goal, f"{get_result}_Response", data),
                    lambda text: goal.finish(ABORTED, text, result=False),
                    RESULT_TIMEOUT,
                )

            self._query(
                provider,
                "send_goal",
                f"{send_goal}_Request",
                request,
                accepted,
                lambda text: goal.finish(ABORTED, text, result=False),
                CALL_TIMEOUT,
            )
        elif body.get("op") == "cancel_action_goal":
            request = {
                "goal_info": {"goal_id": {"uuid": goal.uuid}, "stamp": {"sec": 0, "nanosec": 0}}
            }

            def refused(text: str) -> None:
                self.link._log(f"cancel {provider.name}", f"Zenoh: cancel {provider.name}: {text}")

            self._query(
                provider,
                "cancel_goal",
                "action_msgs/srv/CancelGoal_Request",
                request,
                lambda data: None,
                refused,
                CALL_TIMEOUT,
            )

    def _result(self, provider: _ActionProvider, goal: Goal, type_name: str, data: bytes) -> None:
        reply = self.link._decode(type_name, data)
        status = int(reply["status"])
        if status in (SUCCEEDED, CANCELED, ABORTED):
            goal.finish(status, reply["result"])
        else:
            text = f"the action server {provider.node} gave status {status} for the result"
            goal.finish(ABORTED, text, result=False)

    def _query(
        self,
        provider: _ActionProvider,
        part: str,
        request_type: str,
        request: Any,
        on_reply: Callable[[bytes], None],
        on_error: Callable[[str], None],
        timeout: float,
    ) -> None:
        """Send one query to a part of a remote action; call back on the event loop."""
        link = self.link
        entity = provider.parts.get(part)
        if entity is None or link.session is None:
            on_error(f"action {provider.name} has no {part} service (any more)")
            return
        try:
            payload = link.cdr.serialize(request_type, request)
        except SimbridgeError as err:
            on_error(str(err))
            return
        attachment = link.client_attachment(entity, next(self._calls))

        def done(replies: list[tuple[bool, bytes]]) -> None:  # the event loop
            if not replies:
                on_error(f"{entity.name} gave no reply (its node may have gone)")
                return
            ok, data = replies[0]
            if not ok:
                on_error(data.decode(errors="replace") or f"{entity.name} reported an error")
                return
            try:
                on_reply(data)
            except Exception as err:  # whatever the network sent: reported, never raised
                link.stats["bad_payloads"] += 1
                on_error(f"{entity.name}: reply is not what its type says: {err}")

        try:
            link._query(entity, payload, attachment, timeout, done)
        except Exception as err:
            on_error(f"query failed: {err}")


def _status(goal_id: bytes, stamp: tuple[int, int], status: int) -> dict[str, Any]:
    return {
        "goal_info": {
            "goal_id": {"uuid": goal_id},
            "stamp": {"sec": stamp[0], "nanosec": stamp[1]},
        },
        "status": status,
    }


def _json(value: Any) -> bytes:
    from simbridge.rosbridge.encoding import encode_json

    return encode_json(value)


def _quietly(action: Callable[[], Any]) -> None:
    try:
        action()
    except Exception as err:
        logger.debug("Zenoh: %s", err)
