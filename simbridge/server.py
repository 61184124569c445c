"""The WebSocket server: one :class:`Client` per connection, each a peer of the graph.

Sending follows websockets' broadcast advice (``docs/topics/broadcast.rst``): a frame is
written to the socket at once while the client keeps up, without a task switch or a copy
(encoded once, written to every subscriber). When a client's socket buffer passes the high-water
mark, further frames wait in its bounded :class:`~simbridge.protocol.SendQueue` (drop-oldest per
subscription, byte budget per client), drained by the client's own writer task. A slow or
stalled client therefore never delays the simulation loop or any other client.
"""

from __future__ import annotations

import asyncio
import contextlib
import http
import logging
from collections.abc import Hashable
from typing import Any

from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from simbridge.config import ServerSettings
from simbridge.graph import Graph, Peer
from simbridge.protocol import Frame, SendQueue, Session, status_frame
from simbridge.web import HttpRequest, WebApp, parse_target


__all__ = ["BridgeServer", "Client"]

logger = logging.getLogger(__name__)

#: Socket write-buffer size above which frames are queued instead of written (bytes).
WRITE_HIGH_WATER = 64 * 1024


class Client:
    """One connected WebSocket client (a :class:`~simbridge.graph.Peer`)."""

    def __init__(self, ws: ServerConnection, session: Session, settings: ServerSettings) -> None:
        #: The connection.
        self.ws = ws
        #: Protocol state.
        self.session = session
        address = ws.remote_address
        where = f"{address[0]}:{address[1]}" if address else "?"
        #: Label for logs.
        self.label = f"client {session.client_id} ({where})"
        #: Frames waiting for the socket.
        self.queue = SendQueue(settings.max_queue_bytes)
        #: Set when the queue has frames for the writer task.
        self.wake = asyncio.Event()
        #: The connection is closing or closed: drop everything.
        self.closed = False
        #: Frames written (directly or by the writer task).
        self.frames_sent = 0
        #: The client was told that frames were dropped for it.
        self.told_dropped = False

    def send(self, frame: Frame, key: Hashable | None = None, limit: int = 0) -> None:
        """Write a frame now if the socket keeps up, else queue it (drop-oldest)."""
        if self.closed:
            return
        transport = self.ws.transport
        if not self.queue and transport.get_write_buffer_size() <= WRITE_HIGH_WATER:
            broadcast((self.ws,), frame.data, text=frame.text)
            self.frames_sent += 1
            return
        if self.queue.push(frame, key, limit) and not self.told_dropped:
            self.told_dropped = True
            logger.info("%s is not keeping up: dropping its oldest queued messages", self.label)
            if self.session.wants_status("warning"):
                self.queue.push(
                    status_frame(
                        "warning",
                        "you are not reading fast enough: the oldest queued messages were "
                        "dropped (throttle_rate or queue_length limit what you receive)",
                    )
                )
        self.wake.set()

    async def write_loop(self) -> None:
        """Drain the queue into the socket, awaiting its flow control."""
        while True:
            await self.wake.wait()
            self.wake.clear()
            while (frame := self.queue.pop()) is not None:
                await self.ws.send(frame.data, text=frame.text)
                self.frames_sent += 1


class BridgeServer:
    """rosbridge v2 over WebSocket on ``settings.host:settings.port``."""

    def __init__(self, graph: Graph, settings: ServerSettings, web: WebApp | None = None) -> None:
        #: The graph that handles every op.
        self.graph = graph
        #: Network settings.
        self.settings = settings
        #: Answers plain HTTP requests on the WebSocket port (``/healthz``, the page).
        self.web = web
        #: The running websockets server.
        self.server: Server | None = None
        #: Connected clients.
        self.clients: set[Client] = set()
        #: Connections accepted since start.
        self.connections_total = 0
        graph.topics.send_many = self._send_many

    def _send_many(self, frame: Frame, entries: list[tuple[Peer, Hashable, int]]) -> None:
        """Write ``frame`` to many subscribers: one ``broadcast`` for all that keep up.

        The same rule as :meth:`Client.send`, applied to a whole group at once; a client with
        queued frames or a full socket buffer gets the frame through its queue.
        """
        direct = []
        for peer, key, limit in entries:
            if (
                type(peer) is Client
                and not peer.closed
                and not peer.queue
                and peer.ws.transport.get_write_buffer_size() <= WRITE_HIGH_WATER
            ):
                direct.append(peer.ws)
                peer.frames_sent += 1
            else:
                peer.send(frame, key, limit)
        if direct:
            broadcast(direct, frame.data, text=frame.text)

    @property
    def port(self) -> int:
        """The bound port (useful with port 0)."""
        assert self.server is not None
        return int(next(iter(self.server.sockets)).getsockname()[1])

    async def start(self) -> None:
        """Start listening."""
        s = self.settings
        self.server = await serve(
            self._handler,
            s.host,
            s.port,
            process_request=self._process_request,
            max_size=s.max_message_size,
            ping_interval=s.ping_interval,
            ping_timeout=s.ping_timeout,
            compression=None,  # per-client deflate would defeat encode-once
            server_header="simbridge",
        )

    async def close(self) -> None:
        """Close every connection and stop listening."""
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return None
        if self.web is None:
            return connection.respond(426, "this is a rosbridge WebSocket endpoint\n")
        path, query = parse_target(request.path)
        headers = {k.lower(): v for k, v in request.headers.raw_items()}
        answer = self.web.handle(HttpRequest("GET", path, query, headers))
        out = Headers(answer.headers)
        out["Content-Length"] = str(len(answer.body))
        out["Connection"] = "close"
        out["Server"] = "simbridge"
        reason = http.HTTPStatus(answer.status).phrase
        return Response(answer.status, reason, out, answer.body)

    async def _handler(self, ws: ServerConnection) -> None:
        graph = self.graph
        session = graph.new_session()
        client = Client(ws, session, self.settings)
        self.clients.add(client)
        self.connections_total += 1
        graph.add_peer(client)
        writer = asyncio.create_task(client.write_loop(), name=f"writer-{session.client_id}")
        logger.info("%s connected", client.label)
        loop = asyncio.get_running_loop()
        try:
            async for message in ws:
                try:
                    graph.receive(client, message, loop.time())
                except Exception as err:  # a bug must not cost the client its connection
                    logger.exception("%s: internal error", client.label)
                    client.send(status_frame("error", f"internal error: {err}"))
        except ConnectionClosed:
            pass
        finally:
            client.closed = True
            client.queue.clear()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, ConnectionClosed):
                await writer
            self.clients.discard(client)
            graph.remove_peer(client)
            logger.info("%s disconnected (code %s)", client.label, ws.close_code)

    def stats(self) -> dict[str, Any]:
        """Return connection statistics for ``/healthz``."""
        return {
            "clients": len(self.clients),
            "connections_total": self.connections_total,
            "queued_frames": sum(len(c.queue) for c in self.clients),
            "dropped_frames": sum(c.queue.dropped for c in self.clients),
        }
