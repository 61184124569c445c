"""The graph's action table, protocol-neutral: servers, goals, their callers, a rule a test.

The servers and callers here are what a front end or an in-process node gives the table (the
:class:`ActionServer` and :class:`GoalClient` protocols), recording what they are handed.
"""

from __future__ import annotations

from typing import Any

import pytest

from simbridge.errors import ServiceError
from simbridge.graph import Graph
from simbridge.graph.access import Access
from simbridge.graph.actions import (
    ABORTED,
    CANCELED,
    CANCELING,
    EXECUTING,
    SUCCEEDED,
    Goal,
)
from simbridge.graph.services import caller


FIB = "example_interfaces/action/Fibonacci"


class Peer:
    """A peer of some front end: who sent a goal, who provides an action."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.access = Access()


class Server:
    """An action server that records the goals and cancels it is handed."""

    def __init__(self) -> None:
        self.goals: list[Goal] = []
        self.cancels: list[Goal] = []

    def goal(self, goal: Goal) -> None:
        self.goals.append(goal)

    def cancel(self, goal: Goal) -> None:
        self.cancels.append(goal)


class Client:
    """A goal's caller side that records its feedback and its result."""

    def __init__(self) -> None:
        self.feedbacks: list[Any] = []
        self.results: list[tuple[int, Any, bool]] = []
        self.released = 0

    def feedback(self, values: Any) -> None:
        self.feedbacks.append(values)

    def result(self, status: int, values: Any, ok: bool) -> None:
        self.results.append((status, values, ok))

    def release(self) -> None:
        self.released += 1


@pytest.fixture
def graph() -> Graph:
    return Graph()


def send(graph: Graph, peer: Peer, name: str = "/fib", **kw: Any) -> tuple[Goal, Client]:
    client = Client()
    goal = graph.actions.submit(
        peer,  # type: ignore[arg-type]
        graph.actions.actions[name],
        {"order": 3},
        client,
        release=client.release,
        **kw,
    )
    return goal, client


def cancel_goal(graph: Graph, peer: Peer, request: Any, name: str = "/fib") -> Any:
    """Call ``<name>/_action/cancel_goal`` as ``peer`` (as a front end's call does)."""
    handler = graph.services.services[f"{name}/_action/cancel_goal"].handler
    assert handler is not None
    token = caller.set(peer)  # type: ignore[arg-type]
    try:
        return handler(request)
    finally:
        caller.reset(token)


def test_a_goal_reaches_its_server_and_its_answers_reach_its_caller_once(graph: Graph) -> None:
    server = Server()
    graph.actions.add_server("/fib", FIB, "/tutorial", server)
    goal, client = send(graph, Peer("c"), sent_type="x/Y")
    assert server.goals == [goal] and goal.args == {"order": 3} and goal.sent_type == "x/Y"
    assert goal.status == EXECUTING and len(goal.uuid) == 16 and graph.actions.goals
    goal.feedback({"sequence": [0]})
    goal.finish(SUCCEEDED, {"sequence": [0, 1]})
    goal.finish(ABORTED, "again", ok=False)
    goal.feedback({"sequence": [9]})
    assert client.feedbacks == [{"sequence": [0]}]
    assert client.results == [(SUCCEEDED, {"sequence": [0, 1]}, True)]
    assert client.released == 1 and goal.done and not graph.actions.goals


def test_a_goal_keeps_the_uuid_its_sender_chose(graph: Graph) -> None:
    graph.actions.add_server("/fib", FIB, "/tutorial", Server())
    goal, _ = send(graph, Peer("c"), goal_uuid=bytes(range(16)))
    assert goal.uuid == bytes(range(16))


def test_a_provider_replaced_by_another_loses_the_name_and_its_goals_fail(graph: Graph) -> None:
    first, second = Peer("a"), Peer("b")
    lost: list[str] = []
    graph.actions.provide(first, "/fib", FIB, "/n", Server(), lost=lambda: lost.append("a"))  # type: ignore[arg-type]
    graph.actions.provide(first, "/fib", FIB, "/n", Server(), lost=lambda: lost.append("a"))  # type: ignore[arg-type]
    assert lost == []  # re-provided by the same peer: still its own
    goal, client = send(graph, Peer("c"))
    graph.actions.provide(second, "/fib", FIB, "/n", Server())  # type: ignore[arg-type]
    assert lost == ["a"] and graph.actions.actions["/fib"].provider is second
    ((status, reason, ok),) = client.results
    assert (status, ok) == (ABORTED, False) and "re-advertised" in reason and goal.done


def test_only_its_provider_withdraws_an_action_and_its_goals_fail(graph: Graph) -> None:
    provider = Peer("p")
    graph.actions.provide(provider, "/fib", FIB, "/n", Server())  # type: ignore[arg-type]
    _, client = send(graph, Peer("c"))
    assert not graph.actions.withdraw(Peer("other"), "/fib")  # type: ignore[arg-type]
    assert graph.actions.withdraw(provider, "/fib")  # type: ignore[arg-type]
    ((status, reason, ok),) = client.results
    assert (status, ok) == (ABORTED, False) and "unadvertised" in reason
    assert "/fib" not in graph.actions.actions
    assert "/fib/_action/cancel_goal" not in graph.services.services
    assert not graph.actions.withdraw(provider, "/fib")  # type: ignore[arg-type]


def test_a_caller_that_leaves_ends_its_goals_unanswered_and_servers_cancel(graph: Graph) -> None:
    server = Server()
    graph.actions.add_server("/fib", FIB, "/tutorial", server)
    leaving, staying = Peer("l"), Peer("s")
    gone, gone_client = send(graph, leaving)
    kept, _ = send(graph, staying)
    graph.actions.drop_peer(leaving)  # type: ignore[arg-type]
    assert server.cancels == [gone] and gone.done and gone_client.results == []
    assert gone_client.released == 1 and list(graph.actions.goals.values()) == [kept]


def test_a_goal_to_a_peers_action_times_out_and_its_server_is_told(graph: Graph) -> None:
    server = Server()
    graph.actions.provide(Peer("p"), "/fib", FIB, "/n", server)  # type: ignore[arg-type]
    goal, client = send(graph, Peer("c"), timeout=30.0, now=10.0)
    graph.actions.expire(39.0)
    assert client.results == []
    graph.actions.expire(40.0)
    ((status, reason, ok),) = client.results
    assert (status, ok) == (ABORTED, False) and "within 30 s" in reason
    assert server.cancels == [goal] and client.released == 1 and not graph.actions.deadlines


def test_a_goal_to_an_in_process_server_never_times_out(graph: Graph) -> None:
    graph.actions.add_server("/fib", FIB, "/tutorial", Server())
    goal, client = send(graph, Peer("c"), timeout=1.0, now=0.0)
    graph.actions.expire(1e9)
    assert not goal.done and client.results == [] and not graph.actions.deadlines


def test_cancel_asks_the_server_once_and_the_goal_is_canceling(graph: Graph) -> None:
    server = Server()
    graph.actions.add_server("/fib", FIB, "/tutorial", server)
    goal, client = send(graph, Peer("c"))
    graph.actions.cancel(goal)
    graph.actions.cancel(goal)
    assert goal.status == CANCELING and server.cancels == [goal]
    goal.finish(CANCELED, {"sequence": []})
    graph.actions.cancel(goal)
    assert server.cancels == [goal] and client.results[0][0] == CANCELED


def test_cancel_goal_service_cancels_all_by_stamp_or_one_of_the_callers_own(graph: Graph) -> None:
    server = Server()
    graph.actions.add_server("/fib", FIB, "/tutorial", server)
    me, other = Peer("me"), Peer("other")
    first, _ = send(graph, me)
    second, _ = send(graph, me)
    theirs, _ = send(graph, other)
    zero = {"goal_info": {"goal_id": {"uuid": bytes(16)}, "stamp": {"sec": 0, "nanosec": 0}}}
    reply = cancel_goal(graph, me, zero)
    assert reply["return_code"] == 0
    assert [g["goal_id"]["uuid"] for g in reply["goals_canceling"]] == [first.uuid, second.uuid]
    assert server.cancels == [first, second] and theirs.status == EXECUTING
    unknown = {"goal_info": {"goal_id": {"uuid": bytes([1] * 16)}}}
    assert cancel_goal(graph, me, unknown) == {"return_code": 2, "goals_canceling": []}
    with pytest.raises(ServiceError, match="another client"):
        cancel_goal(graph, me, {"goal_info": {"goal_id": {"uuid": list(theirs.uuid)}}})
    one = {"goal_info": {"goal_id": {"uuid": theirs.uuid}}}
    assert len(cancel_goal(graph, other, one)["goals_canceling"]) == 1
    later, _ = send(graph, me)
    sec, nanosec = first.stamp
    early = {"goal_info": {"stamp": {"sec": sec - 1, "nanosec": nanosec}}}
    assert cancel_goal(graph, me, early)["goals_canceling"] == [] and later.status == EXECUTING
    with pytest.raises(ServiceError, match="GoalInfo"):
        cancel_goal(graph, me, {"goal_info": {"goal_id": {"uuid": "x"}}})
