from __future__ import annotations

import json
from typing import Any

from simbridge.graph import Graph
from simbridge.robot.actionlib import (
    ACTIVE,
    PREEMPTED,
    REJECTED,
    STATUS_HISTORY,
    SUCCEEDED,
    ActionlibGoal,
    ActionlibServer,
)
from simbridge.robot.tfrepublisher import install_tf_republisher
from tests.helpers import RecordingPeer, rosbridge_of


GOAL_TYPE = "actionlib_tutorials/FibonacciActionGoal"


class Echo:
    """An actionlib node that keeps its goals until the test ends them."""

    def __init__(self, graph: Graph, *, private: bool = False) -> None:
        self.goals: list[ActionlibGoal] = []
        self.cancelled: list[ActionlibGoal] = []
        self.server = ActionlibServer(
            graph,
            "/fib",
            "actionlib_tutorials/Fibonacci",
            "/fib",
            self.goal,
            self.cancel,
            private=private,
        )
        graph.watch(self.server)

    def goal(self, goal: ActionlibGoal, now: float) -> None:
        self.goals.append(goal)

    def cancel(self, goal: ActionlibGoal, now: float) -> None:
        self.cancelled.append(goal)
        goal.finish(PREEMPTED, {}, now)


def op(peer: RecordingPeer, graph: Graph, **fields: Any) -> None:
    rosbridge_of(graph).receive(peer, json.dumps(fields), 0.0)


def send_goal(peer: RecordingPeer, graph: Graph, goal_id: str, **stamp: int) -> None:
    msg = {"goal_id": {"id": goal_id, "stamp": stamp}, "goal": {"order": 1}}
    op(peer, graph, op="publish", topic="/fib/goal", type=GOAL_TYPE, msg=msg)


def on(peer: RecordingPeer, topic: str) -> list[Any]:
    return [m["msg"] for m in peer.take() if m.get("topic") == topic]


def test_goal_gets_an_id_and_stamp_when_it_has_none_and_status_lists_it() -> None:
    """An empty goal id and a zero stamp are filled in (actionlib does); /status at 5 Hz."""
    graph = Graph(wall_clock_ns=lambda: 7_000_000_000)
    node = Echo(graph)
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/fib/status")
    send_goal(c, graph, "")
    (goal,) = node.goals
    assert goal.goal_id["id"] and goal.goal_id["stamp"] == {"sec": 7, "nanosec": 0}
    node.server.tick(0.0)
    node.server.tick(0.1)  # not due yet
    node.server.tick(0.2)
    first, second = on(c, "/fib/status")
    assert first["status_list"] == [{"goal_id": goal.goal_id, "status": ACTIVE, "text": ""}]
    assert second == first | {"header": second["header"]}


def test_status_is_not_published_to_nobody_and_ended_goals_leave_it() -> None:
    """No subscriber, no /status; an ended goal stays 5 s, at most STATUS_HISTORY of them."""
    graph = Graph()
    node = Echo(graph)
    c = RecordingPeer(graph)
    for i in range(STATUS_HISTORY + 5):
        send_goal(c, graph, f"g{i}")
        node.goals[-1].finish(SUCCEEDED, {"sequence": [0, 1]}, 0.0)
    node.server.tick(0.0)
    assert c.take() == []
    assert len(node.server.goals) == STATUS_HISTORY
    op(c, graph, op="subscribe", topic="/fib/status")
    node.server.tick(5.0)
    assert on(c, "/fib/status")[0]["status_list"] == []


def test_more_goals_than_the_budget_are_rejected_with_the_reason() -> None:
    graph = Graph()
    node = Echo(graph)
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/fib/result")
    for i in range(ActionlibServer.max_goals):
        send_goal(c, graph, f"g{i}")
    assert on(c, "/fib/result") == []
    send_goal(c, graph, "one-too-many")
    got = c.take()
    (result,) = [m["msg"] for m in got if m["op"] == "publish"]
    (error,) = [m for m in got if m["op"] == "status"]
    assert result["status"]["status"] == REJECTED and "at most" in result["status"]["text"]
    assert "at most 10 goals" in error["msg"]
    assert len(node.goals) == ActionlibServer.max_goals


def test_cancel_by_stamp_takes_the_goals_sent_up_to_then() -> None:
    graph = Graph()
    node = Echo(graph)
    c = RecordingPeer(graph)
    send_goal(c, graph, "early", sec=10)
    send_goal(c, graph, "late", sec=20)
    op(c, graph, op="publish", topic="/fib/cancel", msg={"stamp": {"secs": 15}})
    assert [g.goal_id["id"] for g in node.cancelled] == ["early"]


def test_private_feedback_and_results_reach_only_the_goals_sender() -> None:
    graph = Graph()
    node = Echo(graph, private=True)
    a, b = RecordingPeer(graph, "a"), RecordingPeer(graph, "b")
    for peer in (a, b):
        op(peer, graph, op="subscribe", topic="/fib/feedback")
    send_goal(a, graph, "mine")
    node.goals[0].feedback({"sequence": [0, 1, 1]}, 0.0)
    assert [m["feedback"] for m in on(a, "/fib/feedback")] == [{"sequence": [0, 1, 1]}]
    assert b.take() == []


def test_a_leaving_client_s_goals_are_cancelled_and_forgotten() -> None:
    graph = Graph()
    node = Echo(graph)
    c = RecordingPeer(graph)
    send_goal(c, graph, "g")
    rosbridge_of(graph).remove_peer(c)
    assert [g.goal_id["id"] for g in node.cancelled] == ["g"] and node.server.goals == []


def test_tf_republisher_actionlib_goal_gets_transforms_and_a_cancel_preempts() -> None:
    """The default TFClient's goal: feedback with the requested transform; cancel -> status 2."""
    graph = Graph()
    tf = install_tf_republisher(graph)
    graph.watch(tf)
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/tf2_web_republisher/feedback")
    op(c, graph, op="subscribe", topic="/tf2_web_republisher/result")
    tf_msg = {
        "transforms": [
            {
                "header": {"frame_id": "world"},
                "child_frame_id": "turtle1",
                "transform": {"translation": {"x": 1.0}, "rotation": {"w": 1.0}},
            }
        ]
    }
    goal = {
        "goal_id": {"id": "goal_1", "stamp": {"secs": 0, "nsecs": 0}},
        "goal": {"source_frames": ["turtle1"], "target_frame": "world", "rate": 10.0},
    }
    op(
        c,
        graph,
        op="publish",
        topic="/tf2_web_republisher/goal",
        msg=goal,
        type="tf2_web_republisher/TFSubscriptionActionGoal",
    )
    op(c, graph, op="publish", topic="/tf_static", msg=tf_msg, type="tf2_msgs/msg/TFMessage")
    tf.tick(0.0)
    (feedback,) = on(c, "/tf2_web_republisher/feedback")
    (transform,) = feedback["feedback"]["transforms"]
    assert transform["child_frame_id"] == "turtle1"
    assert transform["transform"]["translation"]["x"] == 1.0
    op(
        c,
        graph,
        op="publish",
        topic="/tf2_web_republisher/cancel",
        msg={"id": "goal_1"},
        type="actionlib_msgs/GoalID",
    )
    (result,) = on(c, "/tf2_web_republisher/result")
    assert result["status"]["status"] == PREEMPTED and tf.requests == []


def test_tf_republisher_actionlib_goal_over_a_bound_is_rejected_with_the_reason() -> None:
    """The TF budgets apply to the default TFClient's goals too: status 5 and why."""
    graph = Graph()
    install_tf_republisher(graph)
    c = RecordingPeer(graph)
    op(c, graph, op="subscribe", topic="/tf2_web_republisher/result")
    goal = {
        "goal_id": {"id": "goal_1"},
        "goal": {"source_frames": [f"f{i}" for i in range(101)], "target_frame": "world"},
    }
    op(
        c,
        graph,
        op="publish",
        topic="/tf2_web_republisher/goal",
        msg=goal,
        type="tf2_web_republisher/TFSubscriptionActionGoal",
    )
    (result,) = on(c, "/tf2_web_republisher/result")
    assert result["status"]["status"] == REJECTED and "at most 100" in result["status"]["text"]
