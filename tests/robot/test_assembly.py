"""graph.assembly: the server and the headless API offer the graph it builds, the same one."""

from __future__ import annotations

from websockets.asyncio.client import ClientConnection

from simbridge.app.config import WorldSpec
from simbridge.headless import Simulation
from tests.helpers import recv_until, send_json


#: What a client lists of a graph: rosapi service -> the field of its reply.
LISTINGS = {
    "/rosapi/topics": "topics",
    "/rosapi/services": "services",
    "/rosapi/action_servers": "action_servers",
    "/rosapi/nodes": "nodes",
}


async def test_lists_the_same_topics_services_and_actions_as_the_server(
    ws: ClientConnection,
) -> None:
    """One assembly: a client of the server and the headless API list the same graph."""
    served: dict[str, list[str]] = {}
    for service, field in LISTINGS.items():
        await send_json(ws, {"op": "call_service", "service": service, "id": service})
        reply = await recv_until(ws, lambda m, s=service: m.get("id") == s)
        assert reply["result"] is True, reply
        served[field] = sorted(reply["values"][field])
    sim = Simulation()
    headless = {
        field: sorted(sim.call_service(service)[field]) for service, field in LISTINGS.items()
    }
    assert headless == served
    for name in ("/estop", "/estop/reset", "/republish_tfs", "/spawn", "/sim/step"):
        assert name in headless["services"]
    for name in ("/estop/state", "/walls", "/clock", "/cmd_vel", "/odom", "/scan"):
        assert name in headless["topics"]
    assert "/tf2_web_republisher" in headless["action_servers"]


def test_the_world_file_turns_on_the_tutorial_nodes_in_the_headless_api_too() -> None:
    """demo_nodes: true adds /add_two_ints, /fibonacci and /chatter; the default world has none."""
    plain = Simulation()
    assert "/add_two_ints" not in plain.call_service("/rosapi/services")["services"]
    sim = Simulation(WorldSpec(demo_nodes=True))
    assert sim.call_service("/add_two_ints", {"a": 2, "b": 40}) == {"sum": 42}
    assert "/fibonacci" in sim.call_service("/rosapi/action_servers")["action_servers"]
    assert "/chatter" in sim.call_service("/rosapi/topics")["topics"]
