"""The WebSocket server: one :class:`Client` per connection, each a peer of the graph.

Sending follows websockets' broadcast advice (``docs/topics/broadcast.rst``): a frame is
written to the socket at once while the client keeps up, without a task switch or a copy
(encoded once, written to every subscriber). When a client's socket buffer passes the high-water
mark, further frames wait in its bounded :class:`~simbridge.rosbridge.SendQueue` (drop-oldest per
subscription, byte budget per client), drained by the client's own writer task. A slow or
stalled client therefore never delays the simulation loop or any other client.

Hostile or broken clients are bounded here (``docs/security.md``): upgrades from a foreign
``Origin``, over ``max_clients`` or with a wrong ``?token=`` are refused with an HTTP status
before the handshake, and so is one more connection of a token that has
``max_connections_per_token`` (the connections of a token with admin rights are not counted
in ``max_clients``: students who fill it never lock the instructor out); where a token is
required, connections without one wait in a small pool of their own (``max_unauthenticated``),
have ``auth_timeout`` seconds to authenticate and may send only small frames until they do;
incoming messages are rate limited per client (excess ones are dropped with one ``status`` a
second) and the connections of one token spend one share of the loop's time together
(``client_work_share``); a client that reads nothing for ``stall_timeout`` seconds while
messages wait for it (timed from when they began to wait) is disconnected; keepalive pings
evict dead peers.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
import weakref
from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import Close, CloseCode
from websockets.http11 import Request, Response
from websockets.protocol import State
from websockets.typing import Origin

from simbridge.app.guard import token_access
from simbridge.app.settings import ServerSettings
from simbridge.graph.access import Access
from simbridge.msgs.registry import generate_interfaces
from simbridge.rosbridge import Frame, SendQueue, Session, TokenBucket, status_frame
from simbridge.rosbridge.front import Rosbridge
from simbridge.rosbridge.subscribers import SendEntries


if TYPE_CHECKING:
    import ssl


__all__ = ["BridgeServer", "Client", "HttpHandler"]

logger = logging.getLogger(__name__)

#: What answers a plain HTTP request (not an upgrade) on the WebSocket port: the page and
#: ``/healthz`` where the composition root hands one in. Typed with websockets' own request and
#: response, so that this server knows nothing of who answers.
HttpHandler = Callable[[Request], Response]

#: Socket write-buffer size above which frames are queued instead of written (bytes): the
#: transport's high-water mark, so websockets' ``paused`` flag says it (and stays set until the
#: buffer drains below a quarter of it).
WRITE_HIGH_WATER = 64 * 1024
#: Incoming messages handled back to back before the handler lets other tasks run.
BATCH = 16
#: Largest frame read from a connection that still owes a token (an ``auth`` op is small).
UNAUTHENTICATED_MAX_SIZE = 16 * 1024  # = Limits.unauthenticated_frame_bytes
#: Seconds of work on one client's frames before the handler lets other tasks run.
SLICE = 0.005
#: A client's work budget may run ahead of its share by this many seconds of the loop's time.
WORK_BURST = 0.0125
#: Bytes read from a client's socket at a time (each read is parsed into frames at once).
READ_CHUNK = 32 * 1024
#: Incoming WebSocket messages websockets buffers for a client before it stops reading its
#: socket (each up to max_message_size): what a client whose frames wait can make us hold.
MAX_QUEUE = 4
#: A client without the admin token: websockets reads messages up to this many times
#: max_frame_bytes (longer ones between get the session's named refusal; longer still close).
STUDENT_READ_FACTOR = 2


def tls_context(certfile: str, keyfile: str | None) -> ssl.SSLContext:
    """Return a server TLS context for a PEM certificate chain and key (wss://, https://)."""
    import ssl  # only a TLS run loads it (see simbridge.app.tuning.import_asyncio)

    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.load_cert_chain(certfile, keyfile)
    return context


def closed_on_purpose(close: Close | None) -> bool:
    """Whether a client ended its connection itself: a close frame with code 1000 or none.

    Anything else counts as a lost link (``safety.stop_on_lost_link``): no close frame (a
    killed script or browser, a crash, a peer dropped by the keepalive or the server), an error
    code, or 1001 "going away" (RFC 6455 7.4.1), which a browser sends for a page that was
    closed, left or whose browser died, never because its code chose to close.
    """
    return close is not None and close.code in (CloseCode.NORMAL_CLOSURE, CloseCode.NO_STATUS_RCVD)


class Client:
    """One connected WebSocket client (a :class:`~simbridge.graph.Peer`)."""

    def __init__(
        self,
        ws: ServerConnection,
        session: Session,
        settings: ServerSettings,
        work: TokenBucket | None = None,
    ) -> None:
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
        #: Framed messages for the socket, written together at the end of this turn of the
        #: event loop (see :meth:`BridgeServer.send_many`).
        self.corked: list[bytes] = []
        #: The client was told that frames were dropped for it.
        self.told_dropped = False
        #: When the client last made progress (monotonic seconds): the writer completed a
        #: write, or frames started to wait for it. Stall detection times from here.
        self.last_progress = asyncio.get_running_loop().time()
        #: The connection still owes a token (its own slot pool, a deadline, small frames).
        self.unauthenticated = False
        #: Closes the connection if it has not authenticated in time.
        self.auth_timer: asyncio.TimerHandle | None = None
        #: Incoming-message rate limit.
        self.messages = TokenBucket(settings.message_rate, settings.message_burst)
        #: Share of the loop's time its frames may take (seconds of work per second): its own,
        #: or the one its token's connections share (``work``).
        self.work = work or TokenBucket(session.limits.work_share, WORK_BURST)
        #: It connected with a token with admin rights (not counted in ``max_clients``).
        self.reserved = False
        #: Whose connections it is counted with and shares ``work`` with: its token, or for
        #: one that authenticated with the ``auth`` op its scope and address (None: its own).
        self.identity: str | None = None

    def close_soon(self, code: int, reason: str) -> None:
        """Close the connection after what is queued (e.g. a failed ``auth``)."""
        if not self.closed:
            task = asyncio.get_running_loop().create_task(self.ws.close(code, reason))
            _background.add(task)
            task.add_done_callback(_background.discard)

    def abort(self) -> None:
        """Drop the connection at once (the peer reads nothing: no close handshake)."""
        self.closed = True
        self.queue.clear()
        self.corked.clear()
        self.ws.transport.abort()

    def uncork(self) -> None:
        """Write the frames corked in this turn of the event loop, in one write."""
        data, self.corked = self.corked, []
        if data and not self.closed and self.ws.protocol.state is State.OPEN:
            self.ws.transport.write(data[0] if len(data) == 1 else b"".join(data))

    @property
    def access(self) -> Access:
        """Who the peer is for the graph's rules (its session's access)."""
        return self.session.access

    def send(self, frame: Frame, key: Hashable | None = None, limit: int = 0) -> None:
        """Write a frame now if the socket keeps up, else queue it (drop-oldest)."""
        if self.closed:
            return
        if not (self.queue.pending or self.ws.paused):
            if self.corked:
                self.uncork()  # in order: what was published before goes first
            broadcast((self.ws,), frame.data, text=frame.text)
            self.frames_sent += 1
            return
        if not self.queue.pending:
            # the client stopped keeping up just now: a stall is timed from here, not from
            # the last write of the queue (a client that read everything for 40 s and
            # pauses now has paused for 0 s)
            self.last_progress = asyncio.get_running_loop().time()
        if self.queue.push(frame, key, limit) and not self.told_dropped:
            self.told_dropped = True
            logger.info("%s is not keeping up: dropping its oldest queued messages", self.label)
            for reply in self.session.status(
                "warning",
                "you are not reading fast enough: the oldest queued messages were dropped "
                "(throttle_rate or queue_length limit what you receive)",
            ):
                self.queue.push(reply.frame)
        self.wake.set()

    async def write_loop(self) -> None:
        """Drain the queue into the socket, awaiting its flow control."""
        while True:
            await self.wake.wait()
            self.wake.clear()
            while (frame := self.queue.pop()) is not None:
                await self.ws.send(frame.data, text=frame.text)
                self.frames_sent += 1
                self.last_progress = asyncio.get_running_loop().time()
            self.told_dropped = False  # caught up: tell again if it falls behind again


#: Tasks that must not be garbage-collected before they finish.
_background: set[asyncio.Task[None]] = set()


class BridgeServer:
    """rosbridge v2 over WebSocket on ``settings.host:settings.port``."""

    def __init__(
        self, front: Rosbridge, settings: ServerSettings, http: HttpHandler | None = None
    ) -> None:
        #: What carries out every op of the clients.
        self.front = front
        #: The robot's graph.
        self.graph = front.graph
        #: Network settings.
        self.settings = settings
        #: Answers plain HTTP requests on the WebSocket port (``/healthz``, the page); without
        #: it they get 426.
        self.http = http
        #: The running websockets server.
        self.server: Server | None = None
        #: Connected clients.
        self.clients: set[Client] = set()
        #: Connections accepted since start.
        self.connections_total = 0
        #: Upgrades refused (origin, token, max_clients) and clients evicted for stalling.
        self.refused_total = 0
        self.stalled_total = 0
        self._watcher: asyncio.Task[None] | None = None
        #: Connections admitted without a token that have not authenticated yet.
        self._unauthenticated: weakref.WeakSet[ServerConnection] = weakref.WeakSet()
        #: Connections admitted with each token (``max_connections_per_token``).
        self._by_token: dict[str, weakref.WeakSet[ServerConnection]] = {}
        #: The loop share each token's connections share, and how many use it.
        self._shares: dict[str, tuple[TokenBucket, int]] = {}
        #: Clients with corked frames, and the callback that writes them.
        self._corked: list[Client] = []
        self._uncork_handle: asyncio.Handle | None = None
        self._interfaces_warming = False

    def send_many(self, frame: Frame, entries: SendEntries) -> None:
        """Write ``frame`` to many subscribers that keep up, framed once for all.

        The same rule as :meth:`Client.send`, applied to a whole group at once; a client with
        queued frames or a full socket buffer gets the frame through its queue. The frames a
        client gets in one turn of the event loop (a tick's /odom and /scan, a batch of samples
        from Zenoh) are corked and written together at its end: one ``send`` system call for
        the server and one read for the client instead of one per message. The builder makes
        it the rosbridge front end's ``subscribers.send_many`` (:mod:`simbridge.app.build`).
        """
        wire = b""
        corked = self._corked
        for peer, key, limit in entries:
            if type(peer) is Client and not (peer.closed or peer.queue.pending or peer.ws.paused):
                ws = peer.ws
                protocol = ws.protocol
                if protocol.state is State.OPEN and not (
                    ws.send_in_progress or protocol.extensions
                ):
                    wire = wire or _wire(frame)  # what broadcast() writes, framed once for all
                    if not peer.corked:
                        corked.append(peer)
                    peer.corked.append(wire)
                else:
                    broadcast((ws,), frame.data, text=frame.text)  # closing: it skips it
                peer.frames_sent += 1
            else:
                peer.send(frame, key, limit)
        if corked and self._uncork_handle is None:
            self._uncork_handle = asyncio.get_running_loop().call_soon(self._uncork)

    def _uncork(self) -> None:
        self._uncork_handle = None
        corked, self._corked = self._corked, []
        for client in corked:
            client.uncork()

    @property
    def port(self) -> int:
        """The bound port (useful with port 0)."""
        assert self.server is not None
        return int(next(iter(self.server.sockets)).getsockname()[1])

    async def start(self) -> None:
        """Start listening."""
        s = self.settings
        # non-browser clients (roslibpy, Node) send no Origin; the allow-list is for pages
        origins: list[Origin | None] | None = None
        if s.allowed_origins is not None:
            origins = [*(Origin(o) for o in s.allowed_origins), None]
        self.server = await serve(
            self._handler,
            s.host,
            s.port,
            process_request=self._process_request,
            max_size=s.max_message_size,
            max_queue=MAX_QUEUE,
            ping_interval=s.ping_interval,
            ping_timeout=s.ping_timeout,
            compression=None,  # per-client deflate would defeat encode-once
            write_limit=WRITE_HIGH_WATER,
            server_header="simbridge",
            origins=origins,
            ssl=tls_context(s.certfile, s.keyfile) if s.certfile else None,
        )
        if s.stall_timeout is not None:
            self._watcher = asyncio.create_task(self._watch_stalls(s.stall_timeout))

    async def close(self) -> None:
        """Close every connection and stop listening."""
        if self._watcher is not None:
            self._watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._watcher
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return self._admit(connection, request)
        if self.http is None:
            return connection.respond(426, "this is a rosbridge WebSocket endpoint\n")
        return self.http(request)

    def _admit(self, connection: ServerConnection, request: Request) -> Response | None:
        """Refuse an upgrade with a token that grants nothing, or over its pool's slots.

        Where clients must authenticate, a connection without a token (it may still send an
        ``auth`` op) takes a slot of its own small pool, ``max_unauthenticated``, never one of
        the ``max_clients`` that authenticated students need.
        """
        s = self.settings
        token = _query_token(request.path)
        granted = None if token is None else token_access(s, token)
        if token is not None and granted is None:
            self.refused_total += 1
            logger.warning("refused a client: invalid token")
            return connection.respond(401, "invalid token\n")
        if token is None and s.auth_required:
            waiting = [c for c in self._unauthenticated if c.state is not State.CLOSED]
            if len(waiting) >= s.max_unauthenticated:
                self.refused_total += 1
                logger.warning(
                    "refused a client: %d connections without a token wait to authenticate "
                    "(max_unauthenticated)",
                    len(waiting),
                )
                return connection.respond(
                    503,
                    f"simbridge is full: {len(waiting)} connections without a token are "
                    f"waiting to authenticate (max_unauthenticated); connect with "
                    "?token=YOUR_TOKEN\n",
                )
            self._unauthenticated.add(connection)
            return None
        if token is not None:
            same = self._by_token.get(token)
            held = 0 if same is None else sum(1 for c in same if c.state is not State.CLOSED)
            if held >= s.max_connections_per_token:
                self.refused_total += 1
                logger.warning(
                    "refused a client: its token has %d connections (max_connections_per_token)",
                    held,
                )
                return connection.respond(
                    503,
                    f"simbridge refuses more connections with this token: it has {held} "
                    "(the server's max_connections_per_token); close some first\n",
                )
        # the instructor's connections (a token with admin rights) are not counted: students
        # that fill max_clients never lock the instructor out
        if granted is None or not granted[1]:
            admitted = sum(1 for c in self.clients if not (c.unauthenticated or c.reserved))
            if admitted >= s.max_clients:
                self.refused_total += 1
                logger.warning(
                    "refused a client: %d clients connected (max_clients)", s.max_clients
                )
                return connection.respond(
                    503,
                    f"simbridge is full: {s.max_clients} clients connected; try again later\n",
                )
        if token is not None:
            self._by_token.setdefault(token, weakref.WeakSet()).add(connection)
        return None

    def _share(self, token: str | None, session: Session) -> TokenBucket | None:
        """Return the loop share the connections of ``token`` spend together (None: no token).

        Every connection of a token counts against one ``client_work_share``: 24 connections
        of one student sending 400 kB frames took 24 shares of the loop (98 % of a core).
        """
        if token is None or token_access(self.settings, token) is None:
            return None
        return self._join(token, session)

    def _join(self, identity: str, session: Session) -> TokenBucket:
        bucket, users = self._shares.get(identity, (None, 0))
        if bucket is None:
            bucket = TokenBucket(session.limits.work_share, WORK_BURST)
        self._shares[identity] = (bucket, users + 1)
        return bucket

    def _unshare(self, token: str | None) -> None:
        if token is None or token not in self._shares:
            return
        bucket, users = self._shares[token]
        if users <= 1:
            del self._shares[token]
            if not self._by_token.get(token):
                self._by_token.pop(token, None)
        else:
            self._shares[token] = (bucket, users - 1)

    def _leave(self, client: Client) -> None:
        """Take ``client`` out of the connections and the share of its identity, if it has one."""
        identity, client.identity = client.identity, None
        if identity is None:
            return
        if identity in self._by_token:
            self._by_token[identity].discard(client.ws)
        self._unshare(identity)

    def _owes_token(self, client: Client) -> None:
        """Give a connection that owes a token its deadline and small frames."""
        s = self.settings
        client.unauthenticated = True
        # the auth op is a few hundred bytes: nothing bigger is read before admission
        _frame_limit(client.ws, min(UNAUTHENTICATED_MAX_SIZE, s.max_message_size))

        def deadline() -> None:
            if client.unauthenticated and not client.closed:
                logger.info(
                    "%s did not authenticate within %g s: closing", client.label, s.auth_timeout
                )
                text = (
                    f"not authenticated within {s.auth_timeout:g} s (the server's auth_timeout): "
                    "connect with ?token=YOUR_TOKEN or send an auth op first"
                )
                self.front.apply(client, client.session.status("error", text))
                client.close_soon(1008, "authentication timeout")

        client.auth_timer = asyncio.get_running_loop().call_later(s.auth_timeout, deadline)

    def _admitted(self, client: Client) -> None:
        """The connection authenticated: it leaves the pool of those that owe a token.

        It is admitted as a connection with a token would be: one identity (its scope and its
        address: one student's machine) has at most ``max_connections_per_token`` connections
        and one loop share, and it takes one of the ``max_clients`` slots unless it has admin
        rights. Before, a client with one valid MAC opened connections past ``max_clients``
        (the others got 503), each with a loop share of its own. Refused, it is told why, owes
        a token again and is closed (1013).
        """
        s = self.settings
        session = client.session
        address = client.ws.remote_address
        identity = f"\0auth {session.scope} {address[0] if address else '?'}"
        same = self._by_token.get(identity)
        held = 0 if same is None else sum(1 for c in same if c.state is not State.CLOSED)
        refusal = None
        if held >= s.max_connections_per_token:
            refusal = (
                f"auth: refused, {held} connections authenticated with scope {session.scope} "
                "from your address are open (the server's max_connections_per_token); close "
                "some first"
            )
        elif not session.admin:
            admitted = sum(1 for c in self.clients if not (c.unauthenticated or c.reserved))
            if admitted >= s.max_clients:
                refusal = (
                    f"auth: refused, simbridge is full: {s.max_clients} clients connected (the "
                    "server's max_clients); try again later"
                )
        if refusal is not None:
            self.refused_total += 1
            logger.warning("%s refused after auth: %s", client.label, refusal)
            session.connect(session.scope, False, authenticated=False)  # owes a token again
            self.front.apply(client, session.status("error", refusal))
            client.close_soon(CloseCode.TRY_AGAIN_LATER, "too many connections")
            return
        client.unauthenticated = False
        client.reserved = session.admin
        self._leave(client)  # one share per connection: a URL token's is left first
        self._by_token.setdefault(identity, weakref.WeakSet()).add(client.ws)
        client.work = self._join(identity, session)
        client.identity = identity
        _frame_limit(client.ws, self._read_limit(session))
        self._unauthenticated.discard(client.ws)
        if client.auth_timer is not None:
            client.auth_timer.cancel()

    def _read_limit(self, session: Session) -> int:
        """Return the largest message websockets reads for an admitted ``session``.

        websockets holds up to :data:`MAX_QUEUE` read messages per connection, each up to this
        size, before the session sees them. A client without the admin token has its frames
        refused by the session past ``max_frame_bytes``, so websockets need not read more than
        twice that for it: a longer message closes the connection (1009, "message too big")
        instead of being buffered, and what a student's connection can make the server hold
        before the session is ``MAX_QUEUE`` x 2 x ``max_frame_bytes`` (8 MB by default).
        """
        s = self.settings
        if session.admin:
            return s.max_message_size
        return min(s.max_message_size, STUDENT_READ_FACTOR * s.max_frame_bytes)

    async def _watch_stalls(self, timeout: float) -> None:
        """Disconnect clients that have read nothing for ``timeout`` s while frames wait."""
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(min(1.0, timeout / 4))
            now = loop.time()
            for client in list(self.clients):
                if client.closed or not client.queue:
                    continue
                if now - client.last_progress > timeout:
                    self.stalled_total += 1
                    logger.warning(
                        "%s read nothing for %.0f s (stall_timeout): disconnecting it",
                        client.label,
                        now - client.last_progress,
                    )
                    client.abort()

    def _rate_limited(self, client: Client, now: float) -> bool:
        if client.messages.take(now):
            return False
        if client.session.may_tell("message_rate", now):
            logger.info("%s sends too fast: dropping messages", client.label)
            s = self.settings
            text = (
                f"too many messages: more than {s.message_rate:g} per second (the server's "
                f"message_rate, burst {s.message_burst}); messages were dropped"
            )
            self.front.apply(client, client.session.status("error", text))
        return True

    def _warm_interfaces(self) -> None:
        """Make the service/action interfaces in a worker thread, once (the first client)."""
        if self._interfaces_warming:
            return
        self._interfaces_warming = True
        future = asyncio.get_running_loop().run_in_executor(None, generate_interfaces)
        future.add_done_callback(_log_failure)

    async def _handler(self, ws: ServerConnection) -> None:
        front = self.front
        token = _query_token(ws.request.path) if ws.request else None
        session = front.new_session(token)
        work = self._share(token, session)
        try:
            client = Client(ws, session, self.settings, work)
        except BaseException:
            self._unshare(token if work is not None else None)
            raise
        if work is not None:
            client.identity = token
        writer: asyncio.Task[None] | None = None
        try:  # from here whatever raises, the finally gives back the share and the slot
            granted = None if token is None else token_access(self.settings, token)
            client.reserved = granted is not None and granted[1]
            _read_chunk(ws)
            self.clients.add(client)
            self.connections_total += 1
            self._warm_interfaces()  # off the loop, before a client's first rosapi call
            front.add_peer(client)
            if not session.authenticated:  # set on connect by the guard (none: all admitted)
                self._owes_token(client)
            else:
                _frame_limit(ws, self._read_limit(session))
            writer = asyncio.create_task(client.write_loop(), name=f"writer-{session.client_id}")
            logger.info("%s connected", client.label)
            loop = asyncio.get_running_loop()
            handled = 0
            yielded = loop.time()
            async for message in ws:
                now = loop.time()
                # a dropped message counts too: a flood of them, queued by one read of the
                # socket (256 kB: thousands of small frames), once held the loop 190 ms
                if not self._rate_limited(client, now):
                    try:
                        front.receive(client, message, now)
                    except Exception as err:  # a bug must not cost the client its connection
                        logger.exception("%s: internal error", client.label)
                        client.send(status_frame("error", f"internal error: {err}"))
                    if client.unauthenticated and session.authenticated:
                        self._admitted(client)
                del message  # not held while this client waits for its share
                done = loop.time()
                handled += 1
                # its share of the loop's time spent: its next frames wait (unread, so TCP
                # slows it down) while the loop and the other clients run
                wait = client.work.charge(done, done - now)
                if wait > 0:
                    while wait > 0:  # its token's other connections may spend it meanwhile
                        await asyncio.sleep(wait)
                        wait = client.work.owed(loop.time())
                    yielded = loop.time()
                elif handled % BATCH == 0 or done - yielded > SLICE:
                    await asyncio.sleep(0)  # a flood must not hold the loop: let ticks run
                    yielded = loop.time()
        except ConnectionClosed:
            pass
        finally:
            client.closed = True
            client.queue.clear()
            client.corked.clear()
            self._unauthenticated.discard(ws)
            if client.auth_timer is not None:
                client.auth_timer.cancel()
            if writer is not None:
                writer.cancel()
                with contextlib.suppress(asyncio.CancelledError, ConnectionClosed):
                    await writer
            self.clients.discard(client)
            self._leave(client)
            lost = not closed_on_purpose(ws.protocol.close_rcvd)
            front.remove_peer(client, lost=lost)
            logger.info(
                "%s disconnected (code %s%s)", client.label, ws.close_code, ", lost" if lost else ""
            )

    def stats(self) -> dict[str, Any]:
        """Return connection statistics for ``/healthz``."""
        return {
            "clients": len(self.clients),
            "connections_total": self.connections_total,
            "queued_frames": sum(len(c.queue) for c in self.clients),
            "dropped_frames": sum(c.queue.dropped for c in self.clients),
            "refused_total": self.refused_total,
            "unauthenticated": sum(1 for c in self.clients if c.unauthenticated),
            "stalled_total": self.stalled_total,
        }


def _wire(frame: Frame) -> bytes:
    """Return ``frame`` as the server writes it (RFC 6455 section 5.2: one final frame, no mask).

    The bytes are the same for every client: the server negotiates no extension (no
    permessage-deflate, see :meth:`BridgeServer.start`), so a frame is framed once and written
    as is to each subscriber (websockets' ``broadcast`` framed it again for each connection).
    """
    data = frame.data
    first = 0x81 if frame.text else 0x82  # FIN + text or binary
    n = len(data)
    if n < 126:
        return bytes((first, n)) + data
    if n < 65536:
        return _HEAD16.pack(first, 126, n) + data
    return _HEAD64.pack(first, 127, n) + data


_HEAD16 = struct.Struct("!BBH")
_HEAD64 = struct.Struct("!BBQ")


def _read_chunk(ws: ServerConnection) -> None:
    """Read at most READ_CHUNK bytes from the socket at a time (asyncio's default: 256 kB).

    websockets parses every frame of a read in one callback: 256 kB of small frames is 3,700
    frames, 30 ms with no turn for the loop. (A TLS transport reads through its SSL protocol
    and keeps its own size.)
    """
    transport = ws.transport
    if isinstance(getattr(type(transport), "max_size", None), int):
        transport.max_size = READ_CHUNK  # type: ignore[attr-defined]


def _frame_limit(ws: ServerConnection, size: int) -> None:
    """Set the largest message ``ws`` reads from now on (websockets 14-15 and 16+ spellings)."""
    protocol = ws.protocol
    name = "max_message_size" if hasattr(protocol, "max_message_size") else "max_size"
    setattr(protocol, name, size)


def _query_token(target: str) -> str | None:
    """Return the ``token`` query parameter of a request target, if any."""
    values = parse_qs(urlsplit(target).query).get("token")
    return values[0] if values else None


def _log_failure(future: asyncio.Future[None]) -> None:
    """Log what a worker thread's job raised (the interfaces are then made on first use)."""
    if not future.cancelled() and future.exception() is not None:
        logger.error("making the interfaces failed", exc_info=future.exception())
