from __future__ import annotations

import json
import random
from typing import Any

import pytest

from simbridge.errors import ServiceError
from simbridge.graph import Graph
from simbridge.robot.tutorials import MAX_GOALS, TutorialNodes, install_tutorials
from tests.helpers import RecordingPeer, rosbridge_of


@pytest.fixture
def graph() -> Graph:
    return Graph()


@pytest.fixture
def nodes(graph: Graph) -> TutorialNodes:
    nodes = install_tutorials(graph)
    graph.watch(nodes)
    return nodes


def op(peer: RecordingPeer, graph: Graph, now: float = 0.0, **fields: Any) -> None:
    rosbridge_of(graph).receive(peer, json.dumps(fields), now)


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
    rosbridge_of(graph).remove_peer(c)
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
    run(nodes, 0.3, 2.3)
    (result,) = [m["msg"] for m in c.take() if m["topic"] == "/fibonacci/result"]
    assert result["result"] == {"sequence": [0, 1, 1, 2]} and result["status"]["status"] == 3


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


def _ros1_goal(peer: RecordingPeer, graph: Graph, order: int, now: float) -> None:
    for name in ("/fibonacci/feedback", "/fibonacci/result"):
        op(peer, graph, now, op="subscribe", topic=name)
    goal = {"goal_id": {"id": "g"}, "goal": {"order": order}}
    op(
        peer,
        graph,
        now,
        op="publish",
        topic="/fibonacci/goal",
        msg=goal,
        type="actionlib_tutorials/FibonacciActionGoal",
    )


def _timed(
    peer: RecordingPeer, nodes: TutorialNodes, ticks: list[float]
) -> list[tuple[float, str, Any]]:
    """Tick at each of ``ticks``; return (tick time, topic, msg) of each message sent."""
    out = []
    for now in ticks:
        nodes.tick(now)
        out += [(now, m["topic"], m["msg"]) for m in peer.take()]
    return out


def test_actionlib_fibonacci_sends_order_feedbacks_then_order_plus_two_numbers(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """As actionlib_tutorials' fibonacci_server (i = 1..order): order 7, 7 feedbacks, 9 numbers.

    The last feedback is [0, 1, 1, 2, 3, 5, 8, 13, 21], and the result is that sequence.
    """
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    _ros1_goal(c, graph, 7, 0.0)
    got = [(m["topic"], m["msg"]) for m in c.take()]
    got += [(topic, m) for _when, topic, m in _timed(c, nodes, _grid(0.05, 7.5))]
    feedback = [m["feedback"]["sequence"] for topic, m in got if topic == "/fibonacci/feedback"]
    (result,) = [m for topic, m in got if topic == "/fibonacci/result"]
    fib = [0, 1, 1, 2, 3, 5, 8, 13, 21]
    assert feedback == [fib[: n + 3] for n in range(7)]
    assert result["result"] == {"sequence": fib} and result["status"]["status"] == 3


def _grid(start: float, end: float, jitter: float = 0.0) -> list[float]:
    """The server loop's tick times: every 50 ms from ``start``, each up to ``jitter`` late."""
    rng = random.Random(28)
    n = round((end - start) / 0.05) + 1
    return [round(start + 0.05 * k + rng.uniform(0.0, jitter), 9) for k in range(n)]


def test_fibonacci_steps_keep_a_fixed_1hz_schedule_whatever_the_tick_jitter(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """As ros::Rate and rclcpp::Rate, step k is due at start + k s.

    Ticks a little late (the server loop's, up to 10 ms here) never push the later steps back.
    """
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    _ros1_goal(c, graph, 7, 0.0)
    c.take()  # the first feedback, at once
    steps = [when for when, _topic, _msg in _timed(c, nodes, _grid(0.05, 7.5, jitter=0.01))]
    assert len(steps) == 7  # six more feedbacks, then the result
    for k, when in enumerate(steps, start=1):
        assert k <= when < k + 0.061, f"step {k} at {when:.3f} s"


def _ros2_goal(peer: RecordingPeer, graph: Graph, goal_id: str, action_type: str) -> None:
    op(
        peer,
        graph,
        op="send_action_goal",
        action="/fibonacci",
        id=goal_id,
        action_type=action_type,
        args={"order": 2},
        feedback=True,
    )


def test_fibonacci_feedback_names_the_field_of_the_type_the_goal_was_sent_with(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """example_interfaces' feedback is ``sequence``, action_tutorials_interfaces' another.

    action_tutorials_interfaces (the type of the tutorials up to Jazzy) names it
    ``partial_sequence``; both results are ``sequence``.
    """
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    _ros2_goal(c, graph, "ex", "example_interfaces/action/Fibonacci")
    _ros2_goal(c, graph, "tut", "action_tutorials_interfaces/Fibonacci")
    run(nodes, 0.05, 1.0)
    got = {(m["id"], m["op"]): m["values"] for m in c.take()}
    assert got == {
        ("ex", "action_feedback"): {"sequence": [0, 1, 1]},
        ("tut", "action_feedback"): {"partial_sequence": [0, 1, 1]},
        ("ex", "action_result"): {"sequence": [0, 1, 1]},
        ("tut", "action_result"): {"sequence": [0, 1, 1]},
    }


def test_fibonacci_refuses_a_goal_of_another_action_type_naming_the_types_it_serves(
    graph: Graph, nodes: TutorialNodes
) -> None:
    c = RecordingPeer(graph)
    _ros2_goal(c, graph, "x", "my_pkg/action/Countdown")
    (refused,) = c.take()
    assert refused["op"] == "action_result" and refused["result"] is False
    assert "my_pkg/action/Countdown" in refused["values"]
    assert "example_interfaces/action/Fibonacci" in refused["values"]
    assert nodes.runs == []


def test_every_ros2_tutorial_node_declares_a_settable_bool_use_sim_time(
    graph: Graph, nodes: TutorialNodes
) -> None:
    """As rclcpp's and rclpy's TimeSource declare it on every node: false, bool only."""
    ros2_nodes = ["/add_two_ints_server", "/fibonacci_action_server", "/listener", "/talker"]
    assert sorted(graph.params.nodes) == ros2_nodes
    for node in ros2_nodes:
        assert graph.params.names(node) == ["use_sim_time"]
        assert graph.params.get(node, "use_sim_time") is False
    graph.params.set("/add_two_ints_server", {"use_sim_time": True})
    assert graph.params.get("/add_two_ints_server", "use_sim_time") is True
    assert graph.params.get("/talker", "use_sim_time") is False  # each node has its own
    with pytest.raises(ServiceError, match="use_sim_time"):
        graph.params.set("/talker", {"use_sim_time": "yes"})
    assert graph.params.get("/talker", "use_sim_time") is False


def test_fibonacci_after_a_stall_restarts_its_schedule_instead_of_catching_up(
    graph: Graph, nodes: TutorialNodes
) -> None:
    c = RecordingPeer(graph)
    nodes.tick(0.0)
    _ros1_goal(c, graph, 7, 0.0)
    c.take()
    assert len(_timed(c, nodes, [3.5, 3.55, 4.45])) == 1  # the loop stalled 3.5 s: one step
    assert len(_timed(c, nodes, [4.5])) == 1
