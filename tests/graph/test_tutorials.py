from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.graph import Graph
from simbridge.graph.tutorials import MAX_GOALS, TutorialNodes, install_tutorials
from tests.helpers import RecordingPeer


@pytest.fixture
def graph() -> Graph:
    return Graph()


@pytest.fixture
def nodes(graph: Graph) -> TutorialNodes:
    return install_tutorials(graph)


def op(peer: RecordingPeer, graph: Graph, now: float = 0.0, **fields: Any) -> None:
    graph.receive(peer, json.dumps(fields), now)


def run(nodes: TutorialNodes, start: float, end: float, dt: float = 0.05) -> None:
    """Tick at start, start + dt, ... up to end (on a 50 ms grid, as the server loop)."""
    for i in range(round((end - start) / dt) + 1):
        nodes.tick(round(start + i * dt, 9))


def test_talker_says_hello_world_n_once_a_second_and_the_listener_logs_it(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """demo_nodes_cpp: "Hello World: N" at 1 Hz; the listener logs "I heard: [...]" on /rosout."""
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/chatter")
    op(c, graph, op="subscribe", topic="/rosout")
    run(nodes, 0.0, 3.0)
    got = c.take()
    chatter = [m["msg"]["data"] for m in got if m["topic"] == "/chatter"]
    heard = [m["msg"] for m in got if m["topic"] == "/rosout"]
    assert chatter == ["Hello World: 1", "Hello World: 2", "Hello World: 3"]
    assert [h["msg"] for h in heard] == [f"I heard: [{t}]" for t in chatter]
    assert {h["name"] for h in heard} == {"listener"} and heard[0]["level"] == 20


def test_listener_hears_clients_too(graph: Graph, nodes: TutorialNodes) -> None:
    """A client's publication on /chatter is logged by the listener."""
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/rosout")
    op(c, graph, op="publish", topic="/chatter", msg={"data": "hi from a page"})
    assert [m["msg"]["msg"] for m in c.take()] == ["I heard: [hi from a page]"]


def test_talker_is_quiet_while_a_client_advertises_chatter(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """A student's own talker is heard alone; the built-in one resumes after it unadvertises."""
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/chatter")
    op(c, graph, op="advertise", topic="/chatter", type="std_msgs/String")
    run(nodes, 0.0, 2.0)
    assert c.take() == []
    op(c, graph, op="unadvertise", topic="/chatter")
    run(nodes, 2.05, 3.0)
    assert [m["msg"]["data"] for m in c.take()] == ["Hello World: 1"]


def test_add_two_ints_sums_and_refuses_an_int64_overflow(
    graph: Graph, nodes: TutorialNodes
) -> None:
    c = RecordingPeer(graph)
    op(c, graph, op="call_service", service="/add_two_ints", id="1", args={"a": 2, "b": 40})
    op(c, graph, op="call_service", service="/add_two_ints", id="2", args=[2**62, 2**62])
    ok, overflow = c.take()
    assert (ok["result"], ok["values"]) == (True, {"sum": 42})
    assert overflow["result"] is False and "int64" in overflow["values"]


def test_fibonacci_goal_gets_one_feedback_a_second_then_order_plus_one_numbers(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """action_tutorials: order 4 -> feedback [0,1,1], [0,1,1,2], [0,1,1,2,3]; result after 3 s."""
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    op(
        c,
        graph,
        op="send_action_goal",
        action="/fibonacci",
        id="g",
        action_type="example_interfaces/action/Fibonacci",
        args={"order": 4},
        feedback=True,
    )
    run(nodes, 0.05, 2.95)
    feedback = c.take()
    assert [f["values"]["sequence"] for f in feedback] == [[0, 1, 1], [0, 1, 1, 2], [0, 1, 1, 2, 3]]
    run(nodes, 3.0, 3.1)
    (result,) = c.take()
    assert result["op"] == "action_result" and result["id"] == "g"
    assert (result["status"], result["values"]) == (4, {"sequence": [0, 1, 1, 2, 3]})


def test_fibonacci_cancel_ends_canceled_with_the_sequence_so_far(
    graph: Graph, nodes: TutorialNodes
) -> None:
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    op(
        c,
        graph,
        op="send_action_goal",
        action="/fibonacci",
        id="g",
        action_type="example_interfaces/action/Fibonacci",
        args={"order": 10},
    )
    run(nodes, 0.05, 1.5)
    op(c, graph, op="cancel_action_goal", action="/fibonacci", id="g")
    (result,) = c.take()
    assert (result["status"], result["values"]) == (5, {"sequence": [0, 1, 1, 2]})
    assert nodes.runs == []


def test_fibonacci_refuses_an_order_that_overflows_and_too_many_goals(
    graph: Graph, nodes: TutorialNodes
) -> None:
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    op(
        c,
        graph,
        op="send_action_goal",
        action="/fibonacci",
        id="big",
        action_type="example_interfaces/action/Fibonacci",
        args={"order": 47},
    )
    (big,) = c.take()
    assert big["result"] is False and "too large" in big["values"]
    for i in range(MAX_GOALS + 1):
        op(
            c,
            graph,
            op="send_action_goal",
            action="/fibonacci",
            id=str(i),
            action_type="example_interfaces/action/Fibonacci",
            args={"order": 40},
        )
    (refused,) = c.take()
    assert refused["id"] == str(MAX_GOALS) and "at most" in refused["values"]
    graph.remove_peer(c)
    assert nodes.runs == []


def test_actionlib_fibonacci_speaks_ros1_topics_and_status_numbers(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """ROS 1 goal (secs/nsecs stamp) -> ACTIVE in /status, feedback, result SUCCEEDED (3)."""
    c = RecordingPeer(graph)
    for name in ("/fibonacci/status", "/fibonacci/feedback", "/fibonacci/result"):
        op(c, graph, op="subscribe", topic=name)
    op(
        c,
        graph,
        op="advertise",
        topic="/fibonacci/goal",
        type="actionlib_tutorials/FibonacciActionGoal",
    )
    nodes.tick(0.0)
    c.take()
    goal = {"goal_id": {"stamp": {"secs": 0, "nsecs": 0}, "id": "goal_1"}, "goal": {"order": 2}}
    op(c, graph, op="publish", topic="/fibonacci/goal", msg=goal)
    nodes.tick(0.25)
    got = c.take()
    (feedback,) = [m["msg"] for m in got if m["topic"] == "/fibonacci/feedback"]
    (status,) = [m["msg"] for m in got if m["topic"] == "/fibonacci/status"]
    assert feedback["feedback"] == {"sequence": [0, 1, 1]}
    assert feedback["status"]["goal_id"]["id"] == "goal_1" and feedback["status"]["status"] == 1
    assert status["status_list"][0]["status"] == 1
    assert set(status["status_list"][0]["goal_id"]["stamp"]) == {"sec", "nanosec"}
    run(nodes, 0.3, 1.3)
    (result,) = [m["msg"] for m in c.take() if m["topic"] == "/fibonacci/result"]
    assert result["result"] == {"sequence": [0, 1, 1]} and result["status"]["status"] == 3


def test_actionlib_cancel_preempts_only_the_senders_own_goals(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """An empty GoalID cancels every goal of its sender, none of another client's."""
    a, b = RecordingPeer(graph, "a"), RecordingPeer(graph, "b")
    for peer in (a, b):
        op(peer, graph, op="subscribe", topic="/fibonacci/result")
        goal = {"goal_id": {"id": f"goal_{peer.label}"}, "goal": {"order": 20}}
        op(
            peer,
            graph,
            op="publish",
            topic="/fibonacci/goal",
            msg=goal,
            type="actionlib_tutorials/FibonacciActionGoal",
        )
    op(a, graph, op="publish", topic="/fibonacci/cancel", msg={}, type="actionlib_msgs/GoalID")
    (result,) = [m["msg"] for m in a.take() if m["topic"] == "/fibonacci/result"]
    assert result["status"]["status"] == 2 and result["status"]["goal_id"]["id"] == "goal_a"
    assert [r.al_goal.goal_id["id"] for r in nodes.runs if r.al_goal] == ["goal_b"]
