from __future__ import annotations

import json
from typing import Any

import pytest

from simbridge.app.build import guard_graph
from simbridge.app.config import Params, load_world
from simbridge.app.guard import Guard
from simbridge.app.settings import ServerSettings
from simbridge.graph import Graph
from simbridge.robot.bridge import RobotBridge
from simbridge.robot.estop import EStop
from simbridge.robot.fleet import install_fleet
from simbridge.sim import World
from tests.helpers import ROOT, RecordingPeer, rosbridge_of


@pytest.fixture
def setup() -> tuple[Graph, World, EStop]:
    graph = Graph()
    world = World(load_world(None), Params())
    RobotBridge(graph, world)
    estop = EStop(graph, world)
    graph.watch(estop)
    return graph, world, estop


def call(peer: RecordingPeer, graph: Graph, service: str) -> Any:
    rosbridge_of(graph).receive(
        peer, json.dumps({"op": "call_service", "service": service, "id": "c"}), 0.0
    )
    return next(m for m in peer.take() if m.get("op") == "service_response")


def pub(peer: RecordingPeer, graph: Graph, v: float, w: float) -> None:
    msg = {"linear": {"x": v}, "angular": {"z": w}}
    rosbridge_of(graph).receive(
        peer, json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": msg}), 0.0
    )


def test_estop_halts_at_once_and_ignores_cmd_vel_until_reset(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    pub(peer, graph, 0.3, 1.0)
    world.step()
    assert world.robots[""].state.v == 0.3
    reply = call(peer, graph, "/estop")
    assert reply["result"] is True and reply["values"]["success"] is True
    assert world.robots[""].state.v == 0.0 and world.robots[""].state.omega == 0.0
    before = world.robots[""].state.x
    pub(peer, graph, 0.5, 0.0)
    for _ in range(10):
        world.step()
    assert world.robots[""].state.x == before
    call(peer, graph, "/reset")  # a world reset does not release the latch
    pub(peer, graph, 0.5, 0.0)
    world.step()
    assert world.estopped and world.robots[""].state.v == 0.0
    call(peer, graph, "/estop/reset")
    assert not world.estopped
    world.step()
    assert world.robots[""].state.v == 0.0  # stays still until the next command
    pub(peer, graph, 0.2, 0.0)
    world.step()
    assert world.robots[""].state.v == 0.2


def test_estop_state_is_latched_for_late_subscribers(setup: Any) -> None:
    graph, _, _ = setup
    caller = RecordingPeer(graph)
    call(caller, graph, "/estop")
    late = RecordingPeer(graph)
    rosbridge_of(graph).receive(late, json.dumps({"op": "subscribe", "topic": "/estop/state"}), 0.0)
    assert [m["msg"] for m in late.take()] == [{"data": True}]
    call(caller, graph, "/estop/reset")
    assert [m["msg"] for m in late.take()] == [{"data": False}]


def test_estop_refuses_request_fields(setup: Any) -> None:
    graph, world, _ = setup
    peer = RecordingPeer(graph)
    frame = {"op": "call_service", "service": "/estop", "args": {"bogus": 1}, "id": "x"}
    rosbridge_of(graph).receive(peer, json.dumps(frame), 0.0)
    reply = next(m for m in peer.take() if m.get("op") == "service_response")
    assert reply["result"] is False and "bogus" in reply["values"]
    assert not world.estopped


# -- the scope of an e-stop in a class (issue 13) -------------------------------------------

TOKENS = {"token-for-r1-aaaa": "r1", "token-for-r2-bbbb": "r2"}
ADMIN = "the-admin-token"


@pytest.fixture
def classroom() -> tuple[Graph, World, EStop, Guard]:
    graph = Graph()
    world = World(load_world(ROOT / "config" / "worlds" / "classroom.yaml"), Params())
    bridge = RobotBridge(graph, world)
    estop = EStop(graph, world)
    graph.watch(estop)
    bridge.on_robot_added.append(estop.add_robot)
    bridge.on_robot_removed.append(estop.remove_robot)
    install_fleet(bridge)
    settings = ServerSettings(client_tokens=TOKENS, admin_token=ADMIN)
    guard = Guard(graph, settings, robots=lambda: world.robots.keys())
    guard_graph(graph, guard)
    rosbridge_of(graph, guard)
    return graph, world, estop, guard


def student(graph: Graph, guard: Guard, token: str) -> RecordingPeer:
    p = RecordingPeer(graph, token=token)
    guard.peer_connected(p)
    return p


def drive(graph: Graph, peer: RecordingPeer, robot: str, v: float) -> None:
    msg = {"linear": {"x": v}, "angular": {"z": 0.0}}
    frame = {"op": "publish", "topic": f"/{robot}/cmd_vel", "msg": msg}
    rosbridge_of(graph).receive(peer, json.dumps(frame), 0.0)


def state_of(graph: Graph, guard: Guard, topic: str) -> bool:
    watcher = student(graph, guard, ADMIN)
    rosbridge_of(graph).receive(watcher, json.dumps({"op": "subscribe", "topic": topic}), 0.0)
    return bool(watcher.take()[-1]["msg"]["data"])


def test_a_students_estop_stops_only_their_robot_and_they_release_it(classroom: Any) -> None:
    graph, world, _, guard = classroom
    alice = student(graph, guard, "token-for-r1-aaaa")
    bob = student(graph, guard, "token-for-r2-bbbb")
    drive(graph, alice, "r1", 0.3)
    drive(graph, bob, "r2", 0.3)
    world.step()
    reply = call(alice, graph, "/estop")
    assert reply["result"] is True and "r1" in reply["values"]["message"]
    assert "r2" not in reply["values"]["message"]
    world.step()
    assert world.robots["r1"].state.v == 0.0 and world.robots["r2"].state.v == 0.3
    drive(graph, bob, "r2", 0.2)  # bob drives on
    drive(graph, alice, "r1", 0.2)  # alice's command is ignored while held
    world.step()
    assert world.robots["r1"].state.v == 0.0 and world.robots["r2"].state.v == 0.2
    assert state_of(graph, guard, "/r1/estop/state") and not state_of(
        graph, guard, "/r2/estop/state"
    )
    assert state_of(graph, guard, "/estop/state")  # some robot is held
    # bob cannot release alice's stop, nor reach r1's services
    reply = call(bob, graph, "/estop/reset")
    assert "nothing of this connection's" in reply["values"]["message"]
    assert world.halted("r1")
    reply = call(bob, graph, "/r1/estop/reset")
    assert reply["result"] is False and "another robot" in reply["values"]
    reply = call(alice, graph, "/estop/reset")
    assert reply["values"]["success"] is True and "released: r1" in reply["values"]["message"]
    assert not world.halted("r1") and not state_of(graph, guard, "/estop/state")


def test_the_instructors_estop_is_global_and_only_they_release_it(classroom: Any) -> None:
    graph, world, estop, guard = classroom
    alice = student(graph, guard, "token-for-r1-aaaa")
    teacher = student(graph, guard, ADMIN)
    reply = call(teacher, graph, "/estop")
    assert "every robot (global)" in reply["values"]["message"]
    assert all(world.halted(n) for n in world.robots) and world.estopped
    reply = call(alice, graph, "/estop/reset")
    assert reply["values"]["success"] is False
    assert "still held by client" in reply["values"]["message"]
    assert "admin token" in reply["values"]["message"]
    # a robot spawned under the global stop is held too
    call_args = {"x": 0.0, "y": 1.2, "theta": 0.0, "name": "late"}
    frame = {"op": "call_service", "service": "/spawn", "args": call_args, "id": "s"}
    rosbridge_of(graph).receive(teacher, json.dumps(frame), 0.0)
    assert world.halted("late")
    (latch,) = estop.latches.values()
    estop.release_latch(latch.id)  # /admin releases it
    assert not any(world.halted(n) for n in world.robots)


def test_a_robot_estop_covers_that_robot_and_a_reconnected_page_may_release_it(
    classroom: Any,
) -> None:
    graph, world, _, guard = classroom
    alice = student(graph, guard, "token-for-r1-aaaa")
    reply = call(alice, graph, "/r1/estop")
    assert reply["result"] is True and world.halted("r1")
    assert not any(world.halted(n) for n in ("r2", "r3", "r4"))
    reply = call(alice, graph, "/r2/estop")
    assert reply["result"] is False  # not her robot
    other_tab = student(graph, guard, "token-for-r1-aaaa")
    reply = call(other_tab, graph, "/r1/estop/reset")
    assert world.halted("r1"), "another live connection of the same token may not release it"
    rosbridge_of(graph).remove_peer(
        alice
    )  # the page lost its link; it comes back with the same token
    again = student(graph, guard, "token-for-r1-aaaa")
    reply = call(again, graph, "/r1/estop/reset")
    assert reply["values"]["success"] is True and not world.halted("r1")


def test_latches_are_counted_a_repeated_stop_keeps_one_latch(classroom: Any) -> None:
    """15,000 /r1/estop calls of one student are one latch; a reconnected page takes it over.

    Past max_estop_latches, a stop of a held robot makes no new latch; one of a robot that is
    not held still latches (a stop is never refused).
    """
    graph, world, estop, guard = classroom
    alice = student(graph, guard, "token-for-r1-aaaa")
    for _ in range(50):
        reply = call(alice, graph, "/r1/estop")
        assert reply["result"] is True and "latched for r1" in reply["values"]["message"]
    assert len(estop.latches) == 1
    rosbridge_of(graph).remove_peer(alice)
    again = student(graph, guard, "token-for-r1-aaaa")
    call(again, graph, "/estop")  # her robot again: the gone page's latch becomes hers
    (latch,) = estop.latches.values()
    assert latch.owner == again.session.client_id
    # the cap: other connections' stops of r1 (held already) add nothing past it
    estop.max_latches = 3
    taken = [student(graph, guard, ADMIN) for _ in range(4)]
    for peer in taken:
        call(peer, graph, "/r1/estop")
    assert len(estop.latches) == 3
    reply = call(taken[-1], graph, "/r1/estop")
    assert "held already by" in reply["values"]["message"]
    assert "max_estop_latches" in reply["values"]["message"]
    reply = call(taken[-1], graph, "/r2/estop")  # r2 is not held: it latches
    assert world.halted("r2") and len(estop.latches) == 4
