from __future__ import annotations

import json

from simbridge.app.config import Params, WorldSpec
from simbridge.graph import Graph
from simbridge.robot.walls import LINE_LIST, WallsPublisher
from simbridge.sim import World
from tests.helpers import RecordingPeer, rosbridge_of


def test_walls_are_a_latched_line_list_of_every_segment() -> None:
    spec = WorldSpec(walls=[(0, 0, 2, 0), (2, 0, 2, 1)], boxes=[{"center": (1, 1), "size": (1, 1)}])
    graph = Graph()
    world = World(spec, Params())
    WallsPublisher(graph, world).publish(0.0)
    peer = RecordingPeer(graph)
    rosbridge_of(graph).receive(peer, json.dumps({"op": "subscribe", "topic": "/walls"}), 0.0)
    (msg,) = peer.take()
    marker = msg["msg"]
    assert marker["type"] == LINE_LIST and marker["header"]["frame_id"] == "odom"
    points = [(p["x"], p["y"]) for p in marker["points"]]
    assert len(points) == 2 * len(spec.segments()) == 12
    assert points[:4] == [(0, 0), (2, 0), (2, 0), (2, 1)]
