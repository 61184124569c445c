"""The graph's service table, protocol-neutral: calls answered through ``done``, exactly once."""

from __future__ import annotations

from typing import Any

import pytest

from simbridge.errors import ServiceError
from simbridge.graph import Graph
from simbridge.graph.access import Access
from simbridge.graph.services import PendingCall, ServiceTable, caller, typed_calls
from simbridge.msgs import Converter, TypeRegistry


class Peer:
    """A front end's peer as the graph sees it: a label and an access."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.access = Access(scope=label)


class Answers:
    """A caller's ``done``: every answer it got, and how often its budget was released."""

    def __init__(self) -> None:
        self.got: list[tuple[bool, Any]] = []
        self.released = 0

    def done(self, ok: bool, values: Any) -> None:
        self.got.append((ok, values))

    def release(self) -> None:
        self.released += 1


class Provider:
    """A provider's front end: the calls it was forwarded, and the names it lost."""

    def __init__(self, table: ServiceTable, label: str = "provider") -> None:
        self.peer = Peer(label)
        self.table = table
        self.calls: list[tuple[PendingCall, Any]] = []
        self.lost: list[str] = []

    def provide(self, name: str, type_name: str = "example_interfaces/srv/AddTwoInts") -> Any:
        return self.table.provide(self.peer, name, type_name, self.forward, lost=self.lost.append)

    def forward(self, call: PendingCall, request: Any) -> None:
        self.calls.append((call, request))


@pytest.fixture
def table() -> ServiceTable:
    return ServiceTable()


def test_a_handler_answers_at_once_and_reads_who_calls(table: ServiceTable) -> None:
    """done(True, the handler's values), once; the caller context var holds the peer."""
    seen: list[Any] = []

    def add(request: Any) -> dict[str, Any]:
        peer = caller.get()
        seen.append(peer.access.scope if peer is not None else None)
        return {"sum": request["a"] + request["b"]}

    service = table.add("/add", "example_interfaces/srv/AddTwoInts", "/n", add)
    answers = Answers()
    pending = table.call(Peer("r1"), service, {"a": 1, "b": 2}, 0.0, answers.done)
    assert pending is None and answers.got == [(True, {"sum": 3})] and seen == ["r1"]
    assert caller.get() is None and table.pending == {}


def test_a_handlers_service_error_or_bug_is_a_failed_answer(table: ServiceTable) -> None:
    """ServiceError: its text; any other exception: a sentence naming the service."""

    def refuse(request: Any) -> dict[str, Any]:
        raise ServiceError("no can do")

    def bug(request: Any) -> dict[str, Any]:
        return {"x": 1 / 0}

    answers = Answers()
    for name, handler in (("/refuse", refuse), ("/bug", bug)):
        service = table.add(name, "std_srvs/srv/Trigger", "/n", handler)
        table.call(Peer("c"), service, {}, 0.0, answers.done)
    assert answers.got[0] == (False, "no can do")
    assert answers.got[1][0] is False and answers.got[1][1].startswith("service /bug failed:")


def test_a_provided_service_is_forwarded_and_answered_once(table: ServiceTable) -> None:
    """forward(call, request); respond answers done once and releases the caller's budget."""
    provider = Provider(table)
    service = provider.provide("/sum")
    answers = Answers()
    peer = Peer("c")
    pending = table.call(peer, service, {"a": 1}, 5.0, answers.done, release=answers.release)
    ((call, request),) = provider.calls
    assert call is pending and request == {"a": 1} and call.caller is peer
    assert call.id.startswith("service_request:/sum:") and table.pending == {call.id: call}
    assert answers.got == []
    assert table.respond(call, {"sum": 1}, ok=True)
    assert answers.got == [(True, {"sum": 1})] and answers.released == 1
    assert not table.respond(call, {"sum": 2}, ok=True)  # a second answer goes nowhere
    assert answers.got == [(True, {"sum": 1})] and answers.released == 1


def test_a_call_not_answered_by_its_deadline_times_out_on_the_tick() -> None:
    """Graph.tick past the deadline: done(False, timed out); before it, nothing."""
    graph = Graph()
    provider = Provider(graph.services)
    service = provider.provide("/slow")
    answers = Answers()
    graph.services.call(Peer("c"), service, {}, 10.5, answers.done, release=answers.release)
    graph.tick(10.4)
    assert answers.got == [] and answers.released == 0
    graph.tick(10.6)
    assert answers.got == [(False, "service /slow timed out waiting for its provider")]
    assert answers.released == 1 and graph.services.pending == {}
    (call, _request) = provider.calls[0]
    assert not graph.services.respond(call, {}, ok=True) and len(answers.got) == 1


def test_a_withdrawn_service_fails_its_waiting_calls(table: ServiceTable) -> None:
    provider = Provider(table)
    service = provider.provide("/s")
    answers = Answers()
    table.call(Peer("c"), service, {}, 5.0, answers.done, release=answers.release)
    assert not table.withdraw(Peer("other"), "/s")  # only its provider withdraws it
    assert table.withdraw(provider.peer, "/s")
    assert answers.got == [(False, "service /s was unadvertised by its provider")]
    assert answers.released == 1 and "/s" not in table.services
    with pytest.raises(ServiceError, match="Service /s does not exist"):
        table.lookup("/s")


def test_a_provider_that_loses_the_name_is_told_and_its_calls_fail(table: ServiceTable) -> None:
    """Another provider takes the name: lost(name) for the first; the same one again: no."""
    first, second = Provider(table, "first"), Provider(table, "second")
    service = first.provide("/s")
    answers = Answers()
    table.call(Peer("c"), service, {}, 5.0, answers.done)
    first.provide("/s")  # the same provider again: nothing lost
    assert first.lost == [] and answers.got[0][0] is False
    assert "re-advertised" in answers.got[0][1]
    second.provide("/s")
    assert first.lost == ["/s"] and table.services["/s"].provider is second.peer
    assert not table.withdraw(first.peer, "/s")


def test_a_peer_that_leaves_takes_its_calls_and_services(table: ServiceTable) -> None:
    """drop_peer: a caller's calls end unanswered (budget released); a provider's fail."""
    provider = Provider(table)
    service = provider.provide("/s")
    gone, staying = Answers(), Answers()
    leaving = Peer("leaving")
    table.call(leaving, service, {}, 5.0, gone.done, release=gone.release)
    table.call(Peer("c"), service, {}, 5.0, staying.done, release=staying.release)
    table.drop_peer(leaving)
    assert gone.got == [] and gone.released == 1 and len(table.pending) == 1
    table.drop_peer(provider.peer)
    assert staying.got == [(False, "service /s was unadvertised by its provider")]
    assert staying.released == 1 and table.services == {} and table.pending == {}


def test_a_forwarder_that_raises_fails_that_call_only(table: ServiceTable) -> None:
    def broken(call: PendingCall, request: Any) -> None:
        raise RuntimeError("wire down")

    service = table.provide(Peer("p"), "/s", "std_srvs/srv/Trigger", broken)
    answers = Answers()
    table.call(Peer("c"), service, {}, 5.0, answers.done, release=answers.release)
    assert answers.got == [(False, "service /s failed: wire down")]
    assert answers.released == 1 and table.pending == {}


def test_typed_calls_complete_requests_and_responses_of_known_types() -> None:
    """List args zipped onto the fields, defaults filled; an unknown type passes unchanged."""
    registry = TypeRegistry()
    prepare, finish = typed_calls(registry, Converter(registry, lambda: (0, 0)))
    assert prepare("example_interfaces/srv/AddTwoInts", [2]) == {"a": 2, "b": 0}
    assert finish("example_interfaces/srv/AddTwoInts", {}) == {"sum": 0}
    assert prepare("my_pkg/srv/Thing", [1, "two"]) is None
    assert finish("my_pkg/srv/Thing", [1]) == [1]
    with pytest.raises(ServiceError, match="a must be an integer"):
        prepare("example_interfaces/srv/AddTwoInts", {"a": "one"})
