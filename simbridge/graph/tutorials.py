"""The ROS tutorial nodes, in process: what every roslibjs/roslibpy example talks to.

Started by ``simbridge --demo-nodes`` or ``demo_nodes: true`` in the world file, they behave as
ROS 2's ``demo_nodes_cpp``, ``action_tutorials_cpp`` and ROS 1's ``actionlib_tutorials``:

* ``/talker`` publishes ``std_msgs/msg/String`` ``"Hello World: N"`` (N = 1, 2, ...) on
  ``/chatter`` once a second. It is a stand-in: while a client advertises ``/chatter`` (a
  student's own talker, roslibpy's hello-world example) it stays quiet, so that the client's
  listeners hear that talker alone; it resumes when no client publishes there any more;
* ``/listener`` subscribes to ``/chatter`` and logs ``I heard: [text]`` (info, on ``/rosout``);
* ``/add_two_ints_server`` serves ``/add_two_ints`` (``example_interfaces/srv/AddTwoInts``);
* ``/fibonacci_action_server`` serves the ROS 2 action ``/fibonacci``
  (``example_interfaces/action/Fibonacci``): the sequence starts ``[0, 1]`` and grows by one
  number a second, each sent as feedback; the result is ``order + 1`` numbers (at least 2). A
  cancelled goal ends canceled with the sequence so far;
* ``/fibonacci`` serves the same as a ROS 1 actionlib server (``actionlib_tutorials/Fibonacci``
  on ``/fibonacci/goal`` ... ``/result``, see :mod:`simbridge.graph.actionlib`) for ROS 1-era
  clients (roslibjs ``ActionClient``, roslibpy ``ros1.actionlib``).

An order above 46 is refused (the 48th Fibonacci number does not fit the ``int32[]`` of the
result), and each client has at most :data:`MAX_GOALS` goals running per action.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from simbridge.errors import ServiceError
from simbridge.graph.actionlib import (
    PREEMPTED,
    REJECTED,
    SUCCEEDED as AL_SUCCEEDED,
    ActionlibGoal,
    ActionlibServer,
)
from simbridge.graph.actions import ABORTED, CANCELED, SUCCEEDED, Goal
from simbridge.graph.topics import Peer


if TYPE_CHECKING:
    from simbridge.graph.graph import Graph

__all__ = ["MAX_GOALS", "MAX_ORDER", "TutorialNodes", "install_tutorials"]

TALKER = "/talker"
LISTENER = "/listener"
ADD_SERVER = "/add_two_ints_server"
FIBONACCI_SERVER = "/fibonacci_action_server"
ACTIONLIB_NODE = "/fibonacci"
#: The largest order whose sequence fits int32.
MAX_ORDER = 46
#: Running Fibonacci goals per client and action.
MAX_GOALS = 10
#: Characters of a heard message the listener logs (a client could send megabytes).
_LOG_CHARS = 1000


@dataclass(eq=False, slots=True)
class _Run:
    """One Fibonacci goal being computed, ROS 2 (``goal``) or actionlib (``al_goal``)."""

    order: int
    due: float
    sequence: list[int]
    goal: Goal | None = None
    al_goal: ActionlibGoal | None = None

    @property
    def peer(self) -> Peer | None:
        """The client that sent the goal."""
        if self.goal is not None:
            return self.goal.caller
        return self.al_goal.peer if self.al_goal is not None else None


class TutorialNodes:
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

    def _refusal(self, order: int, peer: Peer | None) -> str | None:
        if order > MAX_ORDER:
            return f"fibonacci: order {order} is too large (at most {MAX_ORDER}: int32 sequence)"
        if peer is not None and sum(1 for r in self.runs if r.peer is peer) >= MAX_GOALS:
            return f"fibonacci: at most {MAX_GOALS} goals running per client"
        return None

    def goal(self, goal: Goal) -> None:
        """Start computing a ROS 2 Fibonacci goal."""
        order = int(goal.args.get("order", 0)) if isinstance(goal.args, dict) else 0
        refusal = self._refusal(order, goal.caller)
        if refusal is not None:
            goal.finish(ABORTED, refusal, result=False)
            return
        self._start(_Run(order, self._now, [0, 1], goal=goal))

    def cancel(self, goal: Goal) -> None:
        """Cancel a ROS 2 goal: it ends canceled with the sequence so far."""
        for run in [r for r in self.runs if r.goal is goal]:
            self.runs.remove(run)
            goal.finish(CANCELED, {"sequence": run.sequence})

    # -- Fibonacci, ROS 1 actionlib -------------------------------------------------------------

    def _actionlib_goal(self, goal: ActionlibGoal, now: float) -> None:
        order = int(goal.goal["order"])
        refusal = self._refusal(order, goal.peer)
        if refusal is not None:
            goal.finish(REJECTED, {"sequence": []}, now, refusal)
            return
        self._start(_Run(order, now, [0, 1], al_goal=goal))

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
        if len(seq) >= run.order + 1:
            self.runs.remove(run)
            if run.goal is not None:
                run.goal.finish(SUCCEEDED, {"sequence": list(seq)})
            elif run.al_goal is not None:
                run.al_goal.finish(AL_SUCCEEDED, {"sequence": list(seq)}, now)
            return
        seq.append(seq[-1] + seq[-2])
        if run.goal is not None:
            run.goal.feedback({"sequence": list(seq)})
        elif run.al_goal is not None:
            run.al_goal.feedback({"sequence": list(seq)}, now)
        run.due = now + 1.0

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
