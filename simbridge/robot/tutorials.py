"""The ROS tutorial nodes, in process: what every roslibjs/roslibpy example talks to.

Started by ``simbridge --demo-nodes`` or ``demo_nodes: true`` in the world file, they behave as
ROS 2's ``demo_nodes_cpp``, ``action_tutorials_cpp`` and ROS 1's ``actionlib_tutorials``:

* ``/talker`` publishes ``std_msgs/msg/String`` ``"Hello World: N"`` (N = 1, 2, ...) on
  ``/chatter`` once a second. It is a stand-in: while a client advertises ``/chatter`` (a
  student's own talker, roslibpy's hello-world example) it stays quiet, so that the client's
  listeners hear that talker alone; it resumes when no client publishes there any more;
* ``/listener`` subscribes to ``/chatter`` and logs ``I heard: [text]`` (info, on ``/rosout``);
* ``/add_two_ints_server`` serves ``/add_two_ints`` (``example_interfaces/srv/AddTwoInts``);
* ``/fibonacci_action_server`` serves the ROS 2 action ``/fibonacci`` as action_tutorials_cpp
  does (``for i in 1 .. order - 1``): the sequence starts ``[0, 1]`` and grows by one number a
  second, each sent as feedback; the result is ``order + 1`` numbers (at least 2). A cancelled
  goal ends canceled with the sequence so far. It answers goals of
  ``example_interfaces/action/Fibonacci`` (feedback ``sequence``, the tutorials' type since
  Kilted) and ``action_tutorials_interfaces/action/Fibonacci`` (feedback ``partial_sequence``,
  up to Jazzy), each in the feedback field of the type the goal was sent with; a goal of any
  other type is refused, naming the two;
* ``/fibonacci`` serves it as actionlib_tutorials' ROS 1 ``fibonacci_server`` does
  (``for i in 1 .. order``: ``order`` feedbacks, ``order + 2`` numbers), as a ROS 1 actionlib
  server (``actionlib_tutorials/Fibonacci`` on ``/fibonacci/goal`` ... ``/result``, see
  :mod:`simbridge.robot.actionlib`) for ROS 1-era clients (roslibjs ``ActionClient``, roslibpy
  ``ros1.actionlib``).

Both step on a fixed 1 Hz schedule, as ``ros::Rate`` and ``rclcpp::Rate`` do: step k is due k
seconds after the goal, whenever the tick before it ran (after a stall of more than a period
the schedule starts again from then: the missed steps are not run back to back). An order
whose sequence does not fit the ``int32[]`` of the result is refused (above 46 for ROS 2,
above 45 for actionlib), and each client has at most :data:`MAX_GOALS` goals running per
action.

The four ROS 2 nodes declare ``use_sim_time`` (bool, false), as rclcpp's and rclpy's time source
does on every node: rosapi's ``get_param``/``set_param`` (``/talker:use_sim_time``) and each
node's ``rcl_interfaces`` services read and set it. Nothing of theirs follows it, as nothing of
the tutorials' own nodes does (their timers and rates are wall-clock). The ROS 1 node
``/fibonacci`` has none: ROS 1 nodes keep theirs on the global parameter server.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from simbridge.errors import ServiceError, TypeNotFoundError
from simbridge.graph.actions import ABORTED, CANCELED, SUCCEEDED, Goal
from simbridge.graph.graph import PeerWatcher
from simbridge.graph.params import ParamNode
from simbridge.graph.topics import Peer
from simbridge.msgs import normalize_type
from simbridge.robot.actionlib import (
    PREEMPTED,
    REJECTED,
    SUCCEEDED as AL_SUCCEEDED,
    ActionlibGoal,
    ActionlibServer,
)


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = ["MAX_GOALS", "MAX_ORDER", "TutorialNodes", "install_tutorials"]

TALKER = "/talker"
LISTENER = "/listener"
ADD_SERVER = "/add_two_ints_server"
FIBONACCI_SERVER = "/fibonacci_action_server"
ACTIONLIB_NODE = "/fibonacci"
#: The largest order whose ROS 2 sequence (order + 1 numbers) fits int32; actionlib's has one
#: number more.
MAX_ORDER = 46
#: The ROS 2 Fibonacci types ``/fibonacci`` answers, and each one's feedback field.
FIBONACCI_TYPES = {
    "example_interfaces/action/Fibonacci": "sequence",
    "action_tutorials_interfaces/action/Fibonacci": "partial_sequence",
}
#: Running Fibonacci goals per client and action.
MAX_GOALS = 10
#: Characters of a heard message the listener logs (a client could send megabytes).
_LOG_CHARS = 1000


@dataclass(eq=False, slots=True)
class _Run:
    """One Fibonacci goal being computed, ROS 2 (``goal``) or actionlib (``al_goal``)."""

    #: Numbers in the result.
    length: int
    #: When the next step is due.
    due: float
    sequence: list[int]
    goal: Goal | None = None
    al_goal: ActionlibGoal | None = None
    #: The feedback's field (ROS 2: that of the type the goal was sent with).
    field: str = "sequence"

    @property
    def peer(self) -> Peer | None:
        """The client that sent the goal."""
        if self.goal is not None:
            return self.goal.caller
        return self.al_goal.peer if self.al_goal is not None else None


class TutorialNodes(PeerWatcher):
    """The talker, listener, add_two_ints server and Fibonacci action servers of one graph."""

    def __init__(self, graph: Graph) -> None:
        #: The graph they live in.
        self.graph = graph
        self.chatter = graph.advertise("/chatter", "std_msgs/msg/String", TALKER)
        graph.subscribe("/chatter", "std_msgs/msg/String", LISTENER, self._heard)
        graph.add_service(
            "/add_two_ints", "example_interfaces/srv/AddTwoInts", ADD_SERVER, self._add
        )
        graph.actions.add_server(
            "/fibonacci", "example_interfaces/action/Fibonacci", FIBONACCI_SERVER, self
        )
        self.actionlib = ActionlibServer(
            graph,
            "/fibonacci",
            "actionlib_tutorials/Fibonacci",
            ACTIONLIB_NODE,
            self._actionlib_goal,
            self._actionlib_cancel,
        )
        for node in (TALKER, LISTENER, ADD_SERVER, FIBONACCI_SERVER):
            graph.params.add(_sim_time_node(node))
        #: Messages the talker has published.
        self.count = 0
        #: Goals being computed.
        self.runs: list[_Run] = []
        self._next_talk: float | None = None
        self._now = 0.0

    # -- talker and listener ------------------------------------------------------------------

    def _heard(self, msg: Any, source: Peer | None) -> None:
        text = msg["data"]
        if len(text) > _LOG_CHARS:
            text = text[:_LOG_CHARS] + "..."
        self.graph.log("info", f"I heard: [{text}]", name="listener", echo=False)

    def _talk(self, now: float) -> None:
        if any(owner != TALKER for owner in self.chatter.publishers):
            return  # a client talks on /chatter: let it be heard alone
        self.count += 1
        self.graph.publish(self.chatter, {"data": f"Hello World: {self.count}"}, now)

    # -- add_two_ints -------------------------------------------------------------------------

    def _add(self, request: Any) -> dict[str, Any]:
        total = request["a"] + request["b"]
        if not -(2**63) <= total < 2**63:
            msg = f"add_two_ints: {request['a']} + {request['b']} does not fit an int64"
            raise ServiceError(msg)
        return {"sum": total}

    # -- Fibonacci, ROS 2 (graph.actions calls goal/cancel) ----------------------------------

    def _refusal(self, order: int, peer: Peer | None, largest: int = MAX_ORDER) -> str | None:
        if order > largest:
            return f"fibonacci: order {order} is too large (at most {largest}: int32 sequence)"
        if peer is not None and sum(1 for r in self.runs if r.peer is peer) >= MAX_GOALS:
            return f"fibonacci: at most {MAX_GOALS} goals running per client"
        return None

    def goal(self, goal: Goal) -> None:
        """Start computing a ROS 2 Fibonacci goal."""
        order = int(goal.args.get("order", 0)) if isinstance(goal.args, dict) else 0
        try:
            sent = normalize_type(goal.sent_type or goal.action.type, "action")
        except TypeNotFoundError:
            sent = goal.sent_type
        field = FIBONACCI_TYPES.get(sent)
        if field is None:
            served = " or ".join(FIBONACCI_TYPES)
            refusal: str | None = f"fibonacci: {goal.action.name} serves {served}, not {sent}"
        else:
            refusal = self._refusal(order, goal.caller)
        if refusal is not None:
            goal.finish(ABORTED, refusal, ok=False)
            return
        run = _Run(max(order + 1, 2), self._now, [0, 1], goal=goal, field=field or "sequence")
        self._start(run)

    def cancel(self, goal: Goal) -> None:
        """Cancel a ROS 2 goal: it ends canceled with the sequence so far."""
        for run in [r for r in self.runs if r.goal is goal]:
            self.runs.remove(run)
            goal.finish(CANCELED, {"sequence": run.sequence})

    # -- Fibonacci, ROS 1 actionlib -------------------------------------------------------------

    def _actionlib_goal(self, goal: ActionlibGoal, now: float) -> None:
        order = int(goal.goal["order"])
        refusal = self._refusal(order, goal.peer, MAX_ORDER - 1)
        if refusal is not None:
            goal.finish(REJECTED, {"sequence": []}, now, refusal)
            return
        self._start(_Run(max(order + 2, 2), now, [0, 1], al_goal=goal))

    def _actionlib_cancel(self, goal: ActionlibGoal, now: float) -> None:
        for run in [r for r in self.runs if r.al_goal is goal]:
            self.runs.remove(run)
            goal.finish(PREEMPTED, {"sequence": run.sequence}, now)

    # -- running --------------------------------------------------------------------------------

    def _start(self, run: _Run) -> None:
        self.runs.append(run)
        self._step(run, self._now)

    def _step(self, run: _Run, now: float) -> None:
        """One iteration of the tutorial server's 1 Hz loop (or the final result)."""
        seq = run.sequence
        if len(seq) >= run.length:
            self.runs.remove(run)
            if run.goal is not None:
                run.goal.finish(SUCCEEDED, {"sequence": list(seq)})
            elif run.al_goal is not None:
                run.al_goal.finish(AL_SUCCEEDED, {"sequence": list(seq)}, now)
            return
        seq.append(seq[-1] + seq[-2])
        if run.goal is not None:
            run.goal.feedback({run.field: list(seq)})
        elif run.al_goal is not None:
            run.al_goal.feedback({"sequence": list(seq)}, now)
        # the next step at a fixed period from the last one's due time, not from this tick
        # (ticks come up to a step late: counting from them drifted ~50 ms a step)
        run.due += 1.0
        if run.due <= now:  # more than a period behind: start again from now (as ros::Rate)
            run.due = now + 1.0

    def peer_left(self, peer: Peer) -> None:
        """Forget the actionlib goals of a client that left (:meth:`Graph.watch`)."""
        self.actionlib.peer_left(peer)

    def tick(self, now: float) -> None:
        """Run what is due: the talker once a second, each goal's next step."""
        self._now = now
        if self._next_talk is None:
            self._next_talk = now + 1.0
        elif now >= self._next_talk:
            self._next_talk = max(self._next_talk + 1.0, now)
            self._talk(now)
        for run in [r for r in self.runs if r.due <= now]:
            if run in self.runs:
                self._step(run, now)
        self.actionlib.tick(now)


def install_tutorials(graph: Graph) -> TutorialNodes:
    """Start the tutorial nodes on ``graph``; call the result's ``tick(now)`` every step."""
    return TutorialNodes(graph)


def _sim_time_node(name: str) -> ParamNode:
    """The parameters every ROS 2 node declares: ``use_sim_time`` (rclcpp/rclpy TimeSource)."""
    values: dict[str, Any] = {"use_sim_time": False}

    def write(new: dict[str, Any]) -> None:
        values.update(new)

    return ParamNode(name, read=lambda: dict(values), write=write)
