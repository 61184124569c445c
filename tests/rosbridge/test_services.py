"""rosbridge's service ops on the wire: call_service, advertise_service, service_response."""

from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.app.settings import ServerSettings
from simbridge.errors import ProtocolError, ServiceError
from simbridge.graph import Graph
from simbridge.rosbridge import Refusal, ops as o
from simbridge.rosbridge.services import Call, Response
from tests.helpers import RecordingPeer, graph_for, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    return Graph()


def op(peer: RecordingPeer, graph: Graph, now: float = 0.0, **fields: Any) -> None:
    rosbridge_of(graph).receive(peer, json.dumps(fields), now)


def send(peer: RecordingPeer, graph: Graph, now: float = 0.0, **fields: Any) -> list[Any]:
    op(peer, graph, now, **fields)
    return peer.take()


def test_in_process_service_answers_with_values_and_the_request_id(graph: Graph) -> None:
    """Result true, values the handler's object, id and service echoed as sent."""
    graph.add_service("/add", "example_interfaces/srv/AddTwoInts", "/n", lambda a: {"sum": 3})
    c = RecordingPeer(graph)
    op(c, graph, op="call_service", service="add", id="call:1", args={"a": 1, "b": 2})
    assert c.take() == [
        {
            "op": "service_response",
            "service": "add",
            "values": {"sum": 3},
            "result": True,
            "id": "call:1",
        }
    ]


def test_service_error_becomes_result_false_with_the_reason(graph: Graph) -> None:
    """A handler raising ServiceError answers result false with its text."""

    def fail(args: Any) -> dict[str, Any]:
        raise ServiceError("no can do")

    graph.add_service("/fail", "std_srvs/srv/Trigger", "/n", fail)
    c = RecordingPeer(graph)
    op(c, graph, op="call_service", service="/fail")
    (reply,) = c.take()
    assert (reply["result"], reply["values"]) == (False, "no can do")
    assert "id" not in reply


def test_handler_bug_is_answered_not_crashed(graph: Graph) -> None:
    """An unexpected exception in a handler still answers the call."""
    graph.add_service("/bug", "std_srvs/srv/Empty", "/n", lambda a: 1 / 0)  # type: ignore[arg-type,return-value]
    c = RecordingPeer(graph)
    op(c, graph, op="call_service", service="/bug", id=7)
    (reply,) = c.take()
    assert reply["result"] is False and reply["id"] == 7


def test_client_provided_service_round_trip(graph: Graph) -> None:
    """Calls are forwarded to the provider and its reply routed back by id."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(
        provider,
        graph,
        op="advertise_service",
        service="/sum",
        type="example_interfaces/AddTwoInts",
    )
    op(caller, graph, op="call_service", service="/sum", id="x", args={"a": 1, "b": 2})
    (request,) = provider.take()
    assert request["op"] == "call_service" and request["args"] == {"a": 1, "b": 2}
    op(
        provider,
        graph,
        op="service_response",
        service="/sum",
        id=request["id"],
        values={"sum": 3},
        result=True,
    )
    assert caller.take() == [
        {
            "op": "service_response",
            "service": "/sum",
            "values": {"sum": 3},
            "result": True,
            "id": "x",
        }
    ]


@pytest.mark.parametrize(
    ("reply", "ok", "values"),
    [
        ({"values": {"sum": 3}}, True, {"sum": 3}),  # roslibjs: callback returned nothing
        ({"values": {"sum": 3}, "result": None}, True, {"sum": 3}),  # roslibpy: returned None
        ({"result": True}, True, {}),
        ({"result": False}, False, "service provider reported failure"),  # roslibjs 2.1 throw
        ({"result": False, "values": "boom"}, False, "boom"),  # roslibjs 2.1 advertiseAsync
        ({}, False, "service provider sent no result object (values: null)"),
        # rosbridge reads values whatever result says (roslibpy's own test returns False)
        ({"values": {"sum": 42}, "result": False}, True, {"sum": 42}),
        (
            {"values": [1, 2], "result": True},
            False,
            "service provider sent no result object (values: [1, 2])",
        ),
    ],
)
def test_every_client_reply_shape_is_answered(
    graph: Graph, reply: dict[str, Any], ok: bool, values: Any
) -> None:
    """Replies without result, with result null or without object values never hang."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(provider, graph, op="advertise_service", service="/s", type="my_pkg/srv/Sum")
    op(caller, graph, op="call_service", service="/s", id="x")
    (request,) = provider.take()
    op(provider, graph, op="service_response", service="/s", id=request["id"], **reply)
    (answer,) = caller.take()
    assert (answer["result"], answer["values"]) == (ok, values)


def test_call_times_out_when_the_provider_never_answers(graph: Graph) -> None:
    """Timeout 0.5 s: tick past the deadline answers result false."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(provider, graph, op="advertise_service", service="/slow", type="std_srvs/Trigger")
    op(caller, graph, 10.0, op="call_service", service="/slow", id="x", timeout=0.5)
    graph.tick(10.4)
    assert caller.take() == []
    graph.tick(10.6)
    (answer,) = caller.take()
    assert answer["result"] is False and "timed out" in answer["values"]


def test_timeout_0_waits_the_maximum_not_forever_and_calls_are_budgeted() -> None:
    """A timeout of 0 (rosbridge: forever) waits max_call_timeout; calls are budgeted.

    Past max_pending_calls a call fails at once; expired and dropped calls give the budget back.
    """
    graph = graph_for(ServerSettings(max_call_timeout=2.0, max_pending_calls=2))
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(provider, graph, op="advertise_service", service="/slow", type="std_srvs/Trigger")
    for k in range(3):
        op(caller, graph, 10.0, op="call_service", service="/slow", id=k, timeout=0)
    (refused,) = caller.take()
    assert refused["id"] == 2 and "max_pending_calls" in refused["values"]
    graph.tick(11.9)
    assert caller.take() == [] and caller.session.pending_calls == 2
    graph.tick(12.1)
    assert [m["id"] for m in caller.take()] == [0, 1]
    assert caller.session.pending_calls == 0 == rosbridge_of(graph).pool.used["pending_calls"]
    op(caller, graph, 13.0, op="call_service", service="/slow", id="late")
    rosbridge_of(graph).remove_peer(caller)
    assert not graph.services.pending and rosbridge_of(graph).pool.used["pending_calls"] == 0


def test_provider_disconnect_fails_pending_calls(graph: Graph) -> None:
    """A provider that leaves: its pending calls are answered with failure."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(provider, graph, op="advertise_service", service="/s", type="std_srvs/Trigger")
    op(caller, graph, op="call_service", service="/s", id="x")
    rosbridge_of(graph).remove_peer(provider)
    (answer,) = caller.take()
    assert answer["result"] is False and "unadvertised" in answer["values"]
    op(caller, graph, op="call_service", service="/s", id="y")
    assert "does not exist" in caller.take()[0]["values"]


def test_service_response_for_unknown_id_is_a_status_error(graph: Graph) -> None:
    """A stray reply is reported to its sender only."""
    stray = RecordingPeer(graph)
    op(stray, graph, op="service_response", service="/s", id="nope", result=True)
    assert stray.take()[0]["op"] == "status"


def test_known_service_type_completes_requests_and_responses(graph: Graph) -> None:
    """AddTwoInts: list args zipped onto (a, b); a partial reply gets its defaults filled."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(
        provider,
        graph,
        op="advertise_service",
        service="/add",
        type="example_interfaces/AddTwoInts",
    )
    op(caller, graph, op="call_service", service="add", args=[2], id=7)
    (request,) = provider.take()
    assert request["args"] == {"a": 2, "b": 0}
    op(provider, graph, op="service_response", service="/add", id=request["id"], values={})
    (answer,) = caller.take()
    assert answer == {
        "op": "service_response",
        "service": "add",
        "values": {"sum": 0},
        "result": True,
        "id": 7,
    }


def test_invalid_request_of_a_known_type_is_refused_before_the_provider(graph: Graph) -> None:
    """A string for an int64 field: result false naming the field; the provider sees nothing."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(
        provider,
        graph,
        op="advertise_service",
        service="/add",
        type="example_interfaces/AddTwoInts",
    )
    op(caller, graph, op="call_service", service="/add", args={"a": "one"}, id=1)
    assert provider.take() == []
    (answer,) = caller.take()
    assert answer["result"] is False and "a must be an integer" in answer["values"]


def test_unknown_service_type_passes_list_args_through_unchanged(graph: Graph) -> None:
    """No definition: no validation, no default filling."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(provider, graph, op="advertise_service", service="/x", type="my_pkg/Thing")
    op(caller, graph, op="call_service", service="/x", args=[1, "two"], id=1)
    (request,) = provider.take()
    assert request["args"] == [1, "two"]


def test_responses_are_fragmented_for_clients_that_ask(graph: Graph) -> None:
    """call_service with fragment_size: the reply comes in fragments that join to the response."""
    graph.add_service("/sum", "example_interfaces/srv/AddTwoInts", "/n", lambda a: {"sum": 3})
    caller = RecordingPeer(graph, "c")
    op(caller, graph, op="call_service", service="/sum", args=[1, 2], id="x", fragment_size=20)
    pieces = caller.take()
    assert len(pieces) > 1 and all(p["op"] == "fragment" for p in pieces)
    assert {p["total"] for p in pieces} == {len(pieces)}
    whole = json.loads("".join(p["data"] for p in sorted(pieces, key=lambda p: p["num"])))
    assert whole["op"] == "service_response" and whole["id"] == "x"


def test_more_list_args_than_request_fields_is_refused_naming_the_fields(graph: Graph) -> None:
    """AddTwoInts has (a, b): [1, 2, 3] is refused before the provider, result false."""
    provider, caller = RecordingPeer(graph, "p"), RecordingPeer(graph, "c")
    op(
        provider,
        graph,
        op="advertise_service",
        service="/add",
        type="example_interfaces/AddTwoInts",
    )
    op(caller, graph, op="call_service", service="/add", args=[1, 2, 3], id=8)
    assert provider.take() == []
    (answer,) = caller.take()
    assert answer["result"] is False
    assert answer["values"] == (
        "request of example_interfaces/srv/AddTwoInts has 2 fields (a, b), got 3 positional args"
    )


def test_a_call_is_admitted_with_its_service_and_its_request_validated() -> None:
    """The service table receives a complete request: list args zipped, defaults filled."""
    graph = Graph()
    peer = RecordingPeer(graph)
    graph.add_service("/add", "example_interfaces/srv/AddTwoInts", "/n", lambda r: {"sum": 0})
    call = rosbridge_of(graph).admission.admit(peer, o.CallService("add", args=[1]), 0.0)
    assert isinstance(call, Call) and call.service is graph.services.services["/add"]
    assert call.request == {"a": 1, "b": 0}


def test_a_call_with_a_bad_request_or_to_no_service_is_refused_before_any_table() -> None:
    """Refused in admission: the provider never hears of it, nothing waits, the caller is told."""
    graph = Graph()
    provider, caller = RecordingPeer(graph), RecordingPeer(graph)
    advertise = {"op": "advertise_service", "service": "/add"}
    send(provider, graph, **advertise, type="example_interfaces/AddTwoInts")
    with pytest.raises(Refusal, match=r"Message type .* does not have a field c") as refused:
        rosbridge_of(graph).admission.admit(
            caller, o.CallService("/add", args={"c": 1}, id="x"), 0.0
        )
    assert (refused.value.op, refused.value.target, refused.value.op_id) == (
        "call_service",
        "/add",
        "x",
    )
    (answer,) = send(caller, graph, op="call_service", service="/add", args={"c": 1}, id="x")
    assert answer["op"] == "service_response" and answer["result"] is False
    (answer,) = send(caller, graph, op="call_service", service="/none", id="y")
    assert answer["values"] == "Service /none does not exist" and answer["result"] is False
    assert provider.take() == [] and graph.services.pending == {}
    assert caller.session.pending_calls == 0


def test_a_providers_answers_are_admitted_validated_for_the_calls_it_serves() -> None:
    """service_response: read and checked before routing."""
    graph = Graph()
    provider, caller, other = RecordingPeer(graph), RecordingPeer(graph), RecordingPeer(graph)
    op(
        provider,
        graph,
        op="advertise_service",
        service="/add",
        type="example_interfaces/AddTwoInts",
    )
    op(caller, graph, op="call_service", service="/add", args={"a": 1, "b": 2}, id="c")
    (forwarded,) = provider.take()
    answer = o.ServiceResponse("/add", values={}, id=forwarded["id"], result=True)
    with pytest.raises(ProtocolError, match="from a client that does not provide it"):
        rosbridge_of(graph).admission.admit(other, answer, 0.0)
    response = rosbridge_of(graph).admission.admit(provider, answer, 0.0)
    assert isinstance(response, Response) and response.ok and response.values == {"sum": 0}
    bad = o.ServiceResponse("/add", values={"total": 3}, id=forwarded["id"], result=True)
    response = rosbridge_of(graph).admission.admit(provider, bad, 0.0)
    assert isinstance(response, Response) and not response.ok
    assert response.values.startswith("service provider sent an invalid response")
    assert caller.take() == [] and len(graph.services.pending) == 1  # nothing routed yet
