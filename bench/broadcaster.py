"""The physical floor of fan-out: a bare websockets server broadcasting the same bytes.

    python -m bench.broadcaster PORT

Every client that connects receives, like a simbridge subscriber of ``/odom`` and ``/scan``,
the publish frame of ``/odom`` at 20 Hz and of ``/scan`` at 10 Hz: byte for byte the frames
simbridge sends for the default world (built once at start with simbridge's encoder), with the
current wall-clock stamp patched in. Sending uses ``websockets.broadcast`` on absolute 20 Hz
deadlines; incoming messages (the clients' subscribe ops) are read and ignored. Nothing else:
no graph, no simulation, no per-client queues.
"""

from __future__ import annotations

import asyncio
import sys
import time

from websockets.asyncio.server import ServerConnection, broadcast, serve

from simbridge.app.config import Params, load_world
from simbridge.graph import Graph
from simbridge.graph.access import Access
from simbridge.robot.bridge import RobotBridge
from simbridge.rosbridge.front import Rosbridge
from simbridge.sim import World


ZERO = b'"stamp":{"sec":0,"nanosec":0}'


def templates() -> dict[str, bytes]:
    """Return the /odom and /scan publish frames of simbridge with a zero stamp."""
    graph = Graph(wall_clock_ns=lambda: 0)
    front = Rosbridge(graph)
    world = World(load_world(None), Params())
    bridge = RobotBridge(graph, world)
    frames: dict[str, bytes] = {}

    class Catch:
        label = "catch"

        def __init__(self) -> None:
            self.session = front.new_session()

        @property
        def access(self) -> Access:
            return self.session.access

        def send(self, frame: object, key: object = None, limit: int = 0) -> None:
            data = getattr(frame, "data", b"")
            raw = data if isinstance(data, bytes) else data.encode()
            for name in ("/odom", "/scan"):
                if f'"topic":"{name}"'.encode() in raw:
                    frames[name] = raw

    peer = Catch()
    for name in ("/odom", "/scan"):
        front.receive(peer, f'{{"op":"subscribe","topic":"{name}"}}', 0.0)
    world.step()
    bridge.publish(0.0)
    assert set(frames) == {"/odom", "/scan"} and all(ZERO in f for f in frames.values())
    return frames


async def run(port: int) -> None:
    frames = templates()
    clients: set[ServerConnection] = set()

    async def handler(ws: ServerConnection) -> None:
        clients.add(ws)
        try:
            async for _ in ws:
                pass
        finally:
            clients.discard(ws)

    async with serve(handler, "127.0.0.1", port, compression=None, ping_interval=None):
        loop = asyncio.get_running_loop()
        start = loop.time()
        k = 0
        while True:
            k += 1
            await asyncio.sleep(max(0.0, start + k * 0.05 - loop.time()))
            sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
            stamp = b'"stamp":{"sec":%d,"nanosec":%d}' % (sec, nanosec)
            odom = frames["/odom"].replace(ZERO, stamp, 1).decode()
            broadcast(clients, odom)
            if k % 2 == 1:
                broadcast(clients, frames["/scan"].replace(ZERO, stamp, 1).decode())


if __name__ == "__main__":
    asyncio.run(run(int(sys.argv[1])))
