"""rosbridge's action ops (protocol sections 2.10-2.15): the wire of simbridge.rosbridge.actions."""

from __future__ import annotations

import base64
import json
from typing import Any

import pytest

from simbridge.app.settings import ServerSettings
from simbridge.errors import ProtocolError
from simbridge.graph import Graph
from simbridge.graph.rosapi import install_rosapi
from simbridge.rosbridge import ops as o
from simbridge.rosbridge.actions import GoalRequest, GoalUpdate, goal_id
from tests.helpers import RecordingPeer, graph_for, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    g = Graph()
    install_rosapi(g)
    return g


def op(peer: RecordingPeer, graph: Graph, **body: Any) -> None:
    rosbridge_of(graph).receive(peer, json.dumps(body), 0.0)


def served(graph: Graph) -> tuple[RecordingPeer, RecordingPeer]:
    server, caller = RecordingPeer(graph, "s"), RecordingPeer(graph, "c")
    op(server, graph, op="advertise_action", action="fib", type="example_interfaces/Fibonacci")
    return server, caller


def test_goal_feedback_and_result_are_routed_by_id(graph: Graph) -> None:
    """Goal completed with defaults; feedback and result reach the caller under its id."""
    server, caller = served(graph)
    op(
        caller,
        graph,
        op="send_action_goal",
        action="/fib",
        action_type="x/Y",
        args={},
        id="g",
        feedback=True,
    )
    (goal,) = server.take()
    assert goal["op"] == "send_action_goal" and goal["args"] == {"order": 0}
    assert goal["action"] == "fib" and goal["feedback"] is True
    op(server, graph, op="action_feedback", action="fib", id=goal["id"], values={"sequence": [0]})
    op(
        server,
        graph,
        op="action_result",
        action="fib",
        id=goal["id"],
        values={},
        status=4,
        result=True,
    )
    feedback, result = caller.take()
    assert feedback == {
        "op": "action_feedback",
        "action": "/fib",
        "values": {"sequence": [0]},
        "id": "g",
    }
    assert result == {
        "op": "action_result",
        "action": "/fib",
        "values": {"sequence": []},
        "status": 4,
        "result": True,
        "id": "g",
    }


def test_failures_are_answered_with_status(graph: Graph) -> None:
    """Unknown action and bad goal: status 0; server gone: status 6, result false."""
    server, caller = served(graph)
    op(caller, graph, op="send_action_goal", action="/nope", action_type="a/B", id=1)
    op(
        caller,
        graph,
        op="send_action_goal",
        action="/fib",
        action_type="a/B",
        args={"order": "x"},
        id=2,
    )
    missing, bad = caller.take()
    assert (missing["status"], missing["result"], missing["id"]) == (0, False, 1)
    assert "does not exist" in missing["values"] and "order" in bad["values"]
    op(caller, graph, op="send_action_goal", action="/fib", action_type="a/B", id=3)
    rosbridge_of(graph).remove_peer(server)
    (gone,) = caller.take()
    assert (gone["status"], gone["result"]) == (6, False) and "unadvertised" in gone["values"]


def test_cancel_goal_service_cancels_all_or_one(graph: Graph) -> None:
    """action_msgs CancelGoal: zero goal_info cancels every goal; a UUID just that goal."""
    server, caller = served(graph)
    for n in (1, 2):
        op(caller, graph, op="send_action_goal", action="/fib", action_type="a/B", id=n)
    server.take()
    op(caller, graph, op="call_service", service="/fib/_action/cancel_goal", args={})
    (reply,) = caller.take()
    assert "id" not in reply and reply["values"]["return_code"] == 0
    canceling = reply["values"]["goals_canceling"]
    assert len(canceling) == 2 and len(base64.b64decode(canceling[0]["goal_id"]["uuid"])) == 16
    assert [m["op"] for m in server.take()] == ["cancel_action_goal"] * 2
    uuid_text = canceling[1]["goal_id"]["uuid"]
    wrong = {"goal_info": {"goal_id": {"uuid": [1] * 16}}}
    op(caller, graph, op="call_service", service="/fib/_action/cancel_goal", args=wrong, id="w")
    assert caller.take()[0]["values"]["return_code"] == 2
    one = {"goal_info": {"goal_id": {"uuid": uuid_text}}}
    op(caller, graph, op="call_service", service="/fib/_action/cancel_goal", args=one, id="o")
    assert len(caller.take()[0]["values"]["goals_canceling"]) == 1


def test_caller_leaving_cancels_its_goals(graph: Graph) -> None:
    """A disconnected caller's goals are cancelled at the server."""
    server, caller = served(graph)
    op(caller, graph, op="send_action_goal", action="/fib", action_type="a/B", id=1)
    (goal,) = server.take()
    rosbridge_of(graph).remove_peer(caller)
    (cancel,) = server.take()
    assert cancel == {"op": "cancel_action_goal", "id": goal["id"], "action": "fib"}
    assert graph.actions.goals == {}


def test_unadvertise_action_fails_goals_and_removes_cancel_goal(graph: Graph) -> None:
    """unadvertise_action: goals in flight fail (status 6), the hidden service goes away."""
    server, caller = served(graph)
    op(caller, graph, op="send_action_goal", action="/fib", action_type="a/B", id=1)
    op(server, graph, op="unadvertise_action", action="fib")
    (result,) = caller.take()
    assert (result["status"], result["result"]) == (6, False)
    assert "/fib" not in graph.actions.actions
    assert "/fib/_action/cancel_goal" not in graph.services.services
    op(server, graph, op="unadvertise_action", action="fib")
    assert "not advertised" in server.take()[-1]["msg"]


def test_unknown_action_type_passes_goals_and_results_through(graph: Graph) -> None:
    """No definition: the goal (even a list) and the result values travel unchanged."""
    server, caller = RecordingPeer(graph, "s"), RecordingPeer(graph, "c")
    op(server, graph, op="advertise_action", action="/x", type="my_pkg/action/Thing")
    op(
        caller,
        graph,
        op="send_action_goal",
        action="/x",
        action_type="my_pkg/Thing",
        args=[1],
        id=1,
    )
    (goal,) = server.take()
    assert goal["args"] == [1] and goal["action_type"] == "my_pkg/action/Thing"
    op(
        server,
        graph,
        op="action_result",
        action="/x",
        id=goal["id"],
        values={"any": 1},
        status=4,
        result=True,
    )
    assert caller.take()[0]["values"] == {"any": 1}


def test_goal_list_args_follow_the_same_positional_rule_as_calls(graph: Graph) -> None:
    """[5] is {order: 5}; [5, 6] has a value for no field: refused to the caller only."""
    server, caller = served(graph)
    send = {"op": "send_action_goal", "action": "/fib", "action_type": "x/Y", "id": "g"}
    op(caller, graph, **send, args=[5])
    (goal,) = server.take()
    assert goal["args"] == {"order": 5}
    op(caller, graph, **send, args=[5, 6])
    assert server.take() == []
    (refused,) = caller.take()
    assert (
        refused["result"] is False
        and "1 fields (order), got 2 positional args" in refused["values"]
    )


def test_goals_are_counted_per_client_and_their_arguments_are_not_kept() -> None:
    """Past max_pending_goals a goal fails by name; results give the budget back."""
    graph = graph_for(ServerSettings(max_pending_goals=2))
    server, caller = served(graph)
    for k in range(3):
        goal = {"op": "send_action_goal", "action": "/fib", "action_type": "x/Y", "id": f"g{k}"}
        rosbridge_of(graph).receive(caller, json.dumps(goal), 0.0)
    (refused,) = caller.take()
    assert refused["id"] == "g2" and refused["result"] is False
    assert "max_pending_goals" in refused["values"]
    assert caller.session.pending_goals == 2 == rosbridge_of(graph).pool.used["pending_goals"]
    assert all(g.args is None for g in graph.actions.goals.values())  # sent on, not kept
    first = server.take()[0]
    result = {"op": "action_result", "action": "fib", "id": first["id"], "values": {}}
    rosbridge_of(graph).receive(server, json.dumps(result | {"status": 4, "result": True}), 0.0)
    assert caller.session.pending_goals == 1
    rosbridge_of(graph).remove_peer(caller)
    assert rosbridge_of(graph).pool.used["pending_goals"] == 0 and not graph.actions.goals


def test_a_goal_without_result_times_out_and_is_cancelled() -> None:
    """A client-served goal with no result after max_goal_timeout: aborted, server told."""
    graph = graph_for(ServerSettings(max_goal_timeout=30.0))
    server, caller = served(graph)
    goal = {"op": "send_action_goal", "action": "/fib", "action_type": "x/Y", "id": "g"}
    rosbridge_of(graph).receive(caller, json.dumps(goal), 10.0)
    (sent,) = server.take()
    graph.tick(39.0)
    assert not caller.take()
    graph.tick(40.0)
    (result,) = caller.take()
    assert result["id"] == "g" and result["result"] is False and result["status"] == 6
    assert "max_goal_timeout" in result["values"]
    (cancel,) = server.take()
    assert cancel == {"op": "cancel_action_goal", "id": sent["id"], "action": "fib"}
    assert caller.session.pending_goals == 0 and not graph.actions.deadlines


def test_a_goal_is_admitted_with_its_action_and_its_message_validated(graph: Graph) -> None:
    """send_action_goal's check: the action found, list args zipped, a bad goal refused."""
    server, client = served(graph)
    send = o.SendActionGoal("fib", "example_interfaces/Fibonacci", args=[5], id="g")
    goal = rosbridge_of(graph).admission.admit(client, send, 0.0)
    assert isinstance(goal, GoalRequest) and goal.action is graph.actions.actions["/fib"]
    assert goal.message == {"order": 5} and goal.op is send
    bad = {"op": "send_action_goal", "action": "fib", "action_type": "x/Y", "id": "b"}
    op(client, graph, **bad, args={"order": "many"})
    (answer,) = client.take()
    assert answer["op"] == "action_result" and answer["status"] == 0
    assert answer["values"].startswith("invalid goal for example_interfaces/action/Fibonacci")
    assert server.take() == [] and graph.actions.goals == {}


def test_a_servers_feedback_is_admitted_only_for_its_own_goal_and_validated(graph: Graph) -> None:
    """action_feedback's check: the goal it serves, by the id it was sent, values of its type."""
    server, caller = served(graph)
    other = RecordingPeer(graph, "o")
    goal = {"op": "send_action_goal", "action": "fib", "action_type": "x/Y", "args": {"order": 2}}
    op(caller, graph, **goal, id="g")
    (sent,) = server.take()
    (running,) = graph.actions.goals.values()
    assert sent["id"] == goal_id(running) == f"action_goal:/fib:{running.id}"
    feedback = o.ActionFeedback("/fib", values={"sequence": [0]}, id=sent["id"])
    update = rosbridge_of(graph).admission.admit(server, feedback, 0.0)
    assert isinstance(update, GoalUpdate) and update.values == {"sequence": [0]}
    wrong = o.ActionFeedback("/fib", values={"order": 1}, id=sent["id"])
    with pytest.raises(ProtocolError, match="action_feedback for /fib"):
        rosbridge_of(graph).admission.admit(server, wrong, 0.0)
    for peer, op_id in ((other, sent["id"]), (server, "action_goal:/fib:x"), (server, 7)):
        stray = o.ActionFeedback("/fib", values={"sequence": [0]}, id=op_id)
        with pytest.raises(ProtocolError, match="unknown or finished goal id"):
            rosbridge_of(graph).admission.admit(peer, stray, 0.0)


def test_cancel_action_goal_reaches_only_the_senders_own_goal(graph: Graph) -> None:
    """cancel_action_goal: by the sender's id; another client's same id cancels nothing."""
    server, caller = served(graph)
    other = RecordingPeer(graph, "o")
    send = {"op": "send_action_goal", "action": "/fib", "action_type": "x/Y", "id": "g"}
    op(caller, graph, **send)
    (sent,) = server.take()
    op(other, graph, op="cancel_action_goal", action="/fib", id="g")
    assert server.take() == []
    op(caller, graph, op="cancel_action_goal", action="/fib", id="g")
    op(caller, graph, op="cancel_action_goal", action="/fib", id="g")  # once is enough
    assert server.take() == [{"op": "cancel_action_goal", "id": sent["id"], "action": "fib"}]
    result = {"op": "action_result", "action": "fib", "id": sent["id"], "values": {}}
    op(server, graph, **result, status=5, result=True)
    assert caller.take()[0]["status"] == 5


def test_a_client_cannot_advertise_an_action_the_server_provides(graph: Graph) -> None:
    """advertise_action over an in-process action: refused by name, the action stays."""
    from simbridge.robot.tutorials import TutorialNodes

    TutorialNodes(graph)
    client = RecordingPeer(graph, "c")
    op(
        client,
        graph,
        op="advertise_action",
        action="/fibonacci",
        type="example_interfaces/Fibonacci",
    )
    (refused,) = client.take()
    assert "the server provides this action itself" in refused["msg"]
    assert graph.actions.actions["/fibonacci"].provider is None


def test_another_client_taking_over_an_action_fails_its_goals_and_disowns_it(graph: Graph) -> None:
    """A second advertise_action of a name: the first server's goals end 6, it no longer owns it."""
    first, caller = served(graph)
    op(caller, graph, op="send_action_goal", action="/fib", action_type="x/Y", id="g")
    first.take()
    second = RecordingPeer(graph, "t")
    op(second, graph, op="advertise_action", action="fib", type="example_interfaces/Fibonacci")
    (ended,) = caller.take()
    assert (ended["status"], ended["result"]) == (6, False) and "re-advertised" in ended["values"]
    assert not first.session.provides("action", "/fib")
    assert graph.actions.actions["/fib"].provider is second
    op(first, graph, op="unadvertise_action", action="fib")  # not its own any more
    assert "/fib" in graph.actions.actions
