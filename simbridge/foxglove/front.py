"""The Foxglove WebSocket protocol beside rosbridge, from the same graph, on the Foxglove SDK.

:class:`FoxgloveFront` runs the SDK's server (``foxglove.start_server``: subprotocol
``foxglove.sdk.v1``) on its own port and maps the graph onto it:

* **channels**: every typed topic of a type the registry knows, with its ``ros2msg`` schema
  (the full definition text) and CDR messages. The CDR bytes are the ones cached on the
  delivery (:attr:`Outgoing.cdr <simbridge.msgs.message.Outgoing.cdr>`), shared with ``cbor-raw``
  subscribers and Zenoh: serialized once, whatever the number of users. Topics are advertised
  when they appear (spawned robots, client-advertised topics) and unadvertised when they go
  (:meth:`FoxgloveFront.tick` compares the tables' change counters). A subscribed channel
  stands in the graph as an in-process subscriber (node ``/foxglove_bridge``), so that the
  simulation publishes what only Foxglove listens to; a latched topic's message is sent again
  when a client subscribes (the SDK's Python API cannot send to one client, so the channel's
  other subscribers get it again too: latched topics are idempotent).
* **client publish**: a client channel makes the client a publisher of its topic on the graph,
  and each message is published there (:meth:`FoxgloveFront.message`) under the graph's rules
  for every front end's peers: the client's scope (``graph.access``), its publish rate, the
  topic's type, the payload validated against it; a refusal becomes an SDK status message.
* **services**: every service of the graph with ``ros2msg`` request and response schemas; a
  call goes to the graph's service table (:meth:`ServiceTable.call
  <simbridge.graph.services.ServiceTable.call>`: in-process handlers and providers alike)
  with the canonical request (decoded from CDR, or JSON checked and completed as a rosbridge
  client's ``args``), after the graph's access rules for the client; the client's calls
  waiting for a provider outside the process are budgeted (``max_pending_calls``).
* **parameters**: the in-process nodes' parameters (``/virtual_robot.robot.mass``), read from
  a snapshot, set through ``/rosapi/set_param`` as a rosbridge client sets them (an
  administrative service: admin rights needed); a change made elsewhere (``/admin``,
  rosbridge) is pushed to the clients that subscribed to it;
* **time**: with ``use_sim_time``, the ``/clock`` time is broadcast as the server's time (the
  stamps are sim time then, and stop with the simulation);
* **connection graph**: publishers, subscribers and services as rosapi lists them (rosbridge
  clients as ``/rosbridge_websocket``, Foxglove clients as ``/foxglove_bridge``), at most once a
  second when it changed.

The SDK calls back on its own threads. Each callback only hands its arguments to the event loop
(``call_soon_threadsafe``); the loop's work is the graph's. Two answers are waited for off the
loop, on SDK threads that hold no lock of the SDK then: a service call (the SDK runs its handler
on a blocking-pool thread, which waits for the loop's answer) and a parameter set (the client's
task waits for the loop to apply it, then returns the values, which the SDK sends to the
parameters' subscribers itself). Parameter reads answer from a snapshot the loop keeps. Each
client has its own bounded queues in the SDK (a client that stops reading loses its oldest data
messages, and is disconnected when its control queue fills), so it never slows the others.

A hazard of the SDK (0.30.3): it calls the Python listener's ``on_parameters_subscribe`` and
``on_connection_graph_subscribe`` (and their unsubscribes) while it holds the lock that
``publish_parameter_values`` and ``publish_connection_graph`` take, and those two keep the GIL
while they wait for it: a publish made while such a callback waits for the GIL (up to the
interpreter's switch interval, 5 ms) deadlocks the process (it did, in a first version that
published the graph when a client subscribed to it). The SDK calls those methods only for the
first subscriber and the last one that leaves, so simbridge keeps a connection of its own
subscribed to every parameter and to the connection graph
(:meth:`FoxgloveFront._hold_parameters`), and publishes either only once that connection holds
them: clients' subscriptions and departures then call nothing under those locks. What remains
is a client subscribing to a parameter name that does not exist, within milliseconds of a
parameter change made elsewhere than on this port (a change made on it the SDK publishes
itself).

The protocol carries no token (the SDK's handshake reads only the subprotocol, and its Python
listener sees a client id): every Foxglove client gets the port's one access (see
:class:`~simbridge.app.settings.ServerSettings` ``foxglove_scope``).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import importlib
import itertools
import json
import logging
import os
import socket
import stat
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import orjson

from simbridge.app.settings import ServerSettings
from simbridge.errors import ConfigError, ProtocolError, ServiceError, SimbridgeError
from simbridge.foxglove.mapping import (
    ADMIN_SCOPE,
    CLIENT_ENCODINGS,
    INSTALL_HINT,
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    param_name,
    plain,
    split_param,
)
from simbridge.graph import Graph, Topic
from simbridge.graph.access import ANY_SCOPE, Access, TokenBucket
from simbridge.graph.services import typed_calls
from simbridge.graph.topics import BRIDGE_NODE, Peer
from simbridge.msgs.cdr import CdrReader, CdrWriter
from simbridge.msgs.message import Outgoing


__all__ = ["FOXGLOVE_NODE", "ConnectionWatch", "FoxgloveFront", "import_foxglove"]

logger = logging.getLogger(__name__)

#: The node that Foxglove clients' subscriptions belong to in the graph (as foxglove_bridge).
FOXGLOVE_NODE = "/foxglove_bridge"
#: Outgoing messages the SDK queues per client (its data and its control queue each).
BACKLOG = 1024
#: Seconds between two connection-graph updates at least.
GRAPH_PERIOD = 1.0
#: Seconds a parameter set of a client waits for the loop to apply it.
SET_TIMEOUT = 2.0
#: The simulation's clock: the server's time with ``use_sim_time``.
CLOCK_TOPIC, CLOCK_TYPE = "/clock", "rosgraph_msgs/msg/Clock"
#: Seconds a service call's SDK thread waits for the graph beyond the call's own timeout.
CALL_MARGIN = 2.0
#: Seconds between two scans of the port's connections at most (sooner when descriptors change).
SCAN_PERIOD = 2.0
#: Seconds a connection past ``foxglove_max_clients`` is left to finish its handshake.
HANDSHAKE_GRACE = 0.1
#: A client's published messages handed by the SDK's threads to the event loop and not yet
#: taken, at most, and their bytes at most; past either, a message is dropped on the SDK's
#: thread (counted: ``messages_dropped``) instead of growing the loop's queue.
INBOX_MESSAGES = 500
INBOX_BYTES = 4_000_000


def set_nodelay(port: int, done: set[tuple[int, int]]) -> int:
    """Set ``TCP_NODELAY`` on this process's connected TCP sockets of local ``port``.

    The SDK's server leaves Nagle's algorithm on for its clients' sockets: a message written
    while the previous one waits for its ACK is held back until the client's delayed ACK comes,
    up to 40 ms on Linux (asyncio, and so rosbridge, turns it off). The sockets are this
    process's own, so simbridge turns it off on them (through a duplicate of each descriptor,
    found in ``/proc/self/fd``; elsewhere this does nothing). ``done``: the (descriptor, peer
    port) pairs already set, updated here. Returns how many were set now.
    """
    try:
        names = os.listdir("/proc/self/fd")
    except OSError:
        return 0
    count = 0
    seen: set[tuple[int, int]] = set()
    for name in names:
        fd = int(name)
        try:
            if not stat.S_ISSOCK(os.fstat(fd).st_mode):
                continue
            sock = socket.socket(fileno=os.dup(fd))  # closing the duplicate leaves the SDK's
        except OSError:
            continue
        with sock:
            try:
                if sock.type != socket.SOCK_STREAM or sock.getsockname()[1] != port:
                    continue
                key = (fd, int(sock.getpeername()[1]))
                seen.add(key)
                if key not in done:
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    count += 1
            except (OSError, IndexError, TypeError):
                continue  # the listening socket has no peer; a socket closed meanwhile
    done.clear()
    done.update(seen)
    return count


class ConnectionWatch:
    """The connections of a port that this process accepted, found in ``/proc/self/fd``.

    The SDK's server (0.30.3) has no client cap and tells its Python listener of no connection
    (the Rust listener's ``on_client_connect`` takes no client and cannot refuse; the Python
    binding does not forward it), nor can it close one client. The sockets are this process's
    own, though: :meth:`scan` lists them (each a connection, from its TCP accept on, handshake
    or not) and :meth:`close` shuts one down, after which the SDK reads the end of the stream
    and forgets the client. A scan costs a ``listdir`` and an ``fstat`` per descriptor; a
    socket is identified once (by its inode) through a duplicate of its descriptor.
    :meth:`changed` (one ``stat``: the number of descriptors, Linux 6.2 on) says when to scan.
    """

    def __init__(self, port: int) -> None:
        self.port = port
        #: descriptor -> (inode, peer (host, port) or None: not one of the port's connections)
        self._known: dict[int, tuple[int, tuple[str, int] | None]] = {}
        #: The order connections were first seen in: (descriptor, inode) -> peer.
        self.order: dict[tuple[int, int], tuple[str, int]] = {}
        self._count = -1

    def changed(self) -> bool:
        """Return whether the number of this process's descriptors changed since the last call."""
        try:
            count = os.stat("/proc/self/fd").st_size
        except OSError:
            return False
        changed, self._count = count != self._count, count
        return changed or count == 0  # 0: a kernel that does not count (scan on the period)

    def scan(self) -> list[tuple[tuple[int, int], tuple[str, int]]]:
        """Return the port's connections, oldest first: ((descriptor, inode), peer)."""
        try:
            names = os.listdir("/proc/self/fd")
        except OSError:
            return []
        known: dict[int, tuple[int, tuple[str, int] | None]] = {}
        for name in names:
            fd = int(name)
            try:
                inode = os.fstat(fd).st_ino
            except OSError:
                continue
            entry = self._known.get(fd)
            if entry is None or entry[0] != inode:
                entry = (inode, self._peer(fd))
            known[fd] = entry
        self._known = known
        current = {(fd, inode): peer for fd, (inode, peer) in known.items() if peer is not None}
        order = {key: peer for key, peer in self.order.items() if key in current}
        order.update(current)  # the new ones after those seen before
        self.order = order
        return list(order.items())

    def _peer(self, fd: int) -> tuple[str, int] | None:
        try:
            if not stat.S_ISSOCK(os.fstat(fd).st_mode):
                return None
            sock = socket.socket(fileno=os.dup(fd))  # closing the duplicate leaves the SDK's
        except OSError:
            return None
        with sock:
            try:
                if sock.type != socket.SOCK_STREAM or sock.getsockname()[1] != self.port:
                    return None
                peer = sock.getpeername()
                return str(peer[0]), int(peer[1])
            except (OSError, IndexError, TypeError):
                return None  # the listening socket has no peer; a socket closed meanwhile

    def close(self, key: tuple[int, int], reason: str) -> bool:
        """Close connection ``key`` (from :meth:`scan`), with a WebSocket close frame.

        Only if it is still that socket (the same inode: a descriptor the SDK closed and the
        process reused meanwhile is left alone). Returns whether it was closed. The close frame
        (1008, ``reason``) is written beside the SDK's own writes: a client
        past its handshake reads it unless the SDK was in the middle of a frame; one still in
        its handshake sees the connection end.
        """
        from websockets.frames import Close, CloseCode, Frame, Opcode

        fd, inode = key
        try:
            sock = socket.socket(fileno=os.dup(fd))
        except OSError:
            return False
        with sock:
            try:
                if os.fstat(sock.fileno()).st_ino != inode:
                    return False
                frame = Frame(Opcode.CLOSE, Close(CloseCode.POLICY_VIOLATION, reason).serialize())
                with contextlib.suppress(OSError):
                    sock.send(frame.serialize(mask=False), socket.MSG_DONTWAIT)
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                return False
        self.order.pop(key, None)
        return True


def import_foxglove() -> Any:
    """Import the Foxglove SDK.

    Raises:
        ConfigError: it is not installed (the message gives the install command).
    """
    try:
        return importlib.import_module("foxglove")
    except ImportError:
        msg = f"--foxglove-port needs the Foxglove extra: {INSTALL_HINT}"
        raise ConfigError(msg) from None


class _Client:
    """One Foxglove client as a peer of the graph: its access and its own budgets."""

    def __init__(self, front: FoxgloveFront, client_id: int, access: Access) -> None:
        self.front = front
        self.client_id = client_id
        #: Who the client is for the graph's rules (the guard's, then ``--foxglove-scope``).
        self.access = access
        self.label = f"Foxglove client {client_id}"
        #: Its client channels: channel id -> (topic, encoding, type or None).
        self.channels: dict[int, tuple[str, str, str | None]] = {}
        #: Its calls waiting for the graph's answer: call number -> future of ``(ok, values)``.
        self.calls: dict[int, asyncio.Future[tuple[bool, Any]]] = {}
        #: How many of them wait for a provider outside this process (``max_pending_calls``).
        self.waiting = 0
        #: Its publish rate (``publish_rate``, ``publish_burst``).
        settings = front.settings
        self.publishes = TokenBucket(settings.publish_rate, settings.publish_burst)

    def call_ended(self) -> None:
        """A call of this client to a provider outside the process ended."""
        self.waiting -= 1


@dataclass(eq=False, slots=True)
class _Channel:
    """A topic's channel: the SDK's object and who subscribed to it."""

    topic: str
    type: str
    channel: Any
    subscribers: set[int] = field(default_factory=set)


class FoxgloveFront:
    """The Foxglove WebSocket server beside the graph (see the module doc)."""

    def __init__(
        self,
        graph: Graph,
        *,
        port: int,
        host: str,
        scope: str | None,
        settings: ServerSettings | None = None,
    ) -> None:
        #: The graph served.
        self.graph = graph
        #: The server's settings (the clients' budgets, use_sim_time, admin_token).
        self.settings = settings = settings or ServerSettings()
        self.port_asked = port
        self.host = host
        #: Access of every Foxglove client (None: what a rosbridge client without a token gets).
        self.scope = scope
        self.fox = import_foxglove()
        self.websocket = importlib.import_module("foxglove.websocket")
        self.context = self.fox.Context()
        self.cdr = CdrWriter(graph.registry)
        self.reader = CdrReader(graph.registry)
        self._prepare, _ = typed_calls(graph.registry, graph.converter)
        self.server: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._channels: dict[str, _Channel] = {}
        self._by_id: dict[int, _Channel] = {}
        self._services: dict[str, str] = {}
        self._clients: dict[int, _Client] = {}
        #: Messages and bytes of each client waiting for the event loop (INBOX_MESSAGES,
        #: INBOX_BYTES), under their lock (the SDK's threads hand them over).
        self._waiting: dict[int, list[int]] = {}
        self._waiting_lock = threading.Lock()
        self._signature: tuple[int, int] = (-1, -1)
        self._call_ids = itertools.count(1)
        #: Parameter sets of Foxglove clients being applied (their changes are not pushed).
        self._setting = 0
        #: simbridge's own connection subscribed to every parameter (see _hold_parameters).
        self._holder: asyncio.Task[None] | None = None
        self._holder_ws: Any = None
        self._own_peer = ("", 0)
        self._holding: set[str] = set()
        #: That connection got the connection graph (it is subscribed): it may be published.
        self._graph_held = False
        self._graph_sent: tuple[int, int] = (-1, -1)
        self._graph_next = 0.0
        #: Clients subscribed to a channel, and the sockets already set to TCP_NODELAY.
        self._receiving: set[int] = set()
        self._nodelay: set[tuple[int, int]] = set()
        #: The port's connections (``foxglove_max_clients``), scanned when the descriptors change.
        self.watch: ConnectionWatch | None = None
        #: The SDK's server listener.
        self.listener = _Listener(self)
        self._scan_next = 0.0
        self._first_seen: dict[tuple[int, int], float] = {}
        self.connections = 0
        #: Parameter values by Foxglove name, replaced whole by the loop (read by SDK threads).
        self._params: dict[str, Any] = {}
        self._time = settings.use_sim_time
        #: Counters for /healthz.
        self.stats: dict[str, int] = {
            "published": 0,
            "received": 0,
            "refused": 0,
            "calls": 0,
            "parameter_sets": 0,
            "clients_refused": 0,
            "messages_dropped": 0,
        }
        self._snapshot_params()

    # -- lifecycle --------------------------------------------------------------------------

    @property
    def port(self) -> int:
        """The bound port (0 before start)."""
        return int(self.server.port) if self.server is not None else 0

    async def start(self) -> None:
        """Start the SDK's server (binding in a thread) and advertise the graph."""
        self._loop = asyncio.get_running_loop()
        ws = self.websocket
        caps = [
            ws.Capability.ClientPublish,
            ws.Capability.Services,
            ws.Capability.Parameters,
            ws.Capability.ConnectionGraph,
        ]
        if self._time:
            caps.append(ws.Capability.Time)
        self.server = await asyncio.to_thread(
            self.fox.start_server,
            name="simbridge",
            host=self.host,
            port=self.port_asked,
            capabilities=caps,
            server_listener=self.listener,
            supported_encodings=list(CLIENT_ENCODINGS),
            context=self.context,
            message_backlog_size=BACKLOG,
        )
        if self._time:
            self.graph.subscribe(CLOCK_TOPIC, CLOCK_TYPE, FOXGLOVE_NODE, self._on_clock)
        self.watch = ConnectionWatch(self.port)
        self.reconcile()
        self._holder = asyncio.create_task(self._hold_parameters(), name="foxglove parameters")
        logger.info("Foxglove WebSocket protocol on port %d (foxglove.sdk.v1)", self.port)

    async def _hold_parameters(self) -> None:
        """Keep one connection of simbridge's own subscribed to every parameter (and read it).

        The SDK calls the listener under its parameter lock only for a name that gains its first
        subscriber or loses its last one (module doc): with this connection subscribed to every
        name, a client's subscriptions and disconnections no longer do, and a change made
        elsewhere can be published safely (``publish_parameter_values``).
        """
        from websockets.asyncio.client import connect
        from websockets.typing import Subprotocol

        host = "127.0.0.1" if self.host in ("0.0.0.0", "::", "") else self.host
        protocols = [Subprotocol("foxglove.sdk.v1")]
        try:
            async with connect(f"ws://{host}:{self.port}", subprotocols=protocols) as ws:
                # not counted in foxglove_max_clients
                self._own_peer = (str(ws.local_address[0]), int(ws.local_address[1]))
                self._holding = set(self._params)
                subscribe = {
                    "op": "subscribeParameterUpdates",
                    "parameterNames": sorted(self._params),
                }
                await ws.send(orjson.dumps(subscribe).decode())
                await ws.send(orjson.dumps({"op": "subscribeConnectionGraph"}).decode())
                async for message in ws:  # parameter values, statuses, graphs: read, dropped
                    # the SDK answers the graph's first subscriber with the whole graph, after
                    # it took this connection's parameter subscription (in order)
                    first = self._holder_ws is None and isinstance(message, str)
                    if first and '"connectionGraphUpdate"' in message:
                        self._holder_ws, self._graph_held = ws, True
        except (TimeoutError, OSError) as err:
            logger.warning("Foxglove: parameter updates from elsewhere are off: %s", err)
        except Exception as err:  # the connection closed: the server stops
            logger.debug("Foxglove: the parameter holder closed: %r", err)
        finally:
            self._holder_ws = None
            self._own_peer = ("", 0)
            self._holding = set()
            self._graph_held = False

    async def close(self) -> None:
        """Stop the server (in a thread: the SDK waits for its connections to close)."""
        server, self.server = self.server, None
        if self._holder is not None:
            self._holder.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._holder
        if self._time:
            self.graph.topics.unsubscribe_internal(CLOCK_TOPIC, self._on_clock)
        if server is not None:
            await asyncio.to_thread(server.stop)
        for entry in self._channels.values():
            entry.channel.close()
        self._channels.clear()
        self._by_id.clear()

    def health(self) -> dict[str, Any]:
        """Return the ``/healthz`` part of the Foxglove port."""
        return {
            "port": self.port,
            "protocol": "foxglove.sdk.v1",
            "access": self.scope or "as a rosbridge client without a token",
            "channels": len(self._channels),
            "subscribed_channels": sum(1 for c in self._channels.values() if c.subscribers),
            "services": len(self._services),
            # the SDK tells no connect or disconnect: clients are the port's sockets (at the last
            # scan) and what they do
            "clients": self.connections,
            "max_clients": self.settings.foxglove_max_clients,
            "clients_subscribed": len(self._receiving),
            "clients_publishing_or_calling": len(self._clients),
            "parameter_updates": self._holder_ws is not None,
            **self.stats,
        }

    def tick(self, now: float) -> None:
        """Advertise what appeared in the graph and unadvertise what went (a tick hook)."""
        if self.server is None:
            return
        signature = (self.graph.topics.changes, self.graph.services.changes)
        if signature != self._signature:
            self.reconcile()
        if self._graph_held and signature != self._graph_sent and now >= self._graph_next:
            self.publish_graph(now)
        watch = self.watch
        if watch is not None and (watch.changed() or now >= self._scan_next):
            self._scan_next = now + SCAN_PERIOD
            self.cap_connections(watch, now)

    def cap_connections(self, watch: ConnectionWatch, now: float) -> None:
        """Close the newest connections past ``foxglove_max_clients`` (simbridge's own excepted).

        Counted from the TCP accept on, in what each costs the process (a descriptor, the SDK's
        queues); one past the budget is closed :data:`HANDSHAKE_GRACE` after it was first seen
        (its handshake is over by then, so it reads the close frame, which names the refusal, as
        the server log does).
        """
        limit = self.settings.foxglove_max_clients
        clients = [(key, peer) for key, peer in watch.scan() if peer != self._own_peer]
        self.connections = len(clients)
        seen = self._first_seen
        self._first_seen = {key: seen.get(key, now) for key, _ in clients}
        if len(clients) <= limit:
            return
        reason = f"too many Foxglove clients (at most {limit}: foxglove_max_clients)"
        for key, peer in clients[limit:]:
            if now < self._first_seen[key] + HANDSHAKE_GRACE:
                self._scan_next = min(self._scan_next, self._first_seen[key] + HANDSHAKE_GRACE)
                continue
            if watch.close(key, reason):
                self.connections -= 1
                self.stats["clients_refused"] += 1
                logger.warning("Foxglove client %s:%d closed: %s", peer[0], peer[1], reason)

    # -- connection graph ---------------------------------------------------------------------

    def publish_graph(self, now: float) -> None:
        """Publish the graph's publishers, subscribers and services as rosapi lists them.

        Only once simbridge's own connection subscribed to the graph (see
        :meth:`_hold_parameters`), at most once every :data:`GRAPH_PERIOD`.
        """
        graph = self.graph
        self._graph_sent = (graph.topics.changes, graph.services.changes)
        self._graph_next = now + GRAPH_PERIOD
        update = self.fox.ConnectionGraph()
        for topic in graph.topics.listed():
            publishers = sorted({self._node(owner) for owner in topic.publishers})
            subscribers = {node for node, _ in topic.internal}
            if topic.sinks:
                subscribers.add(BRIDGE_NODE)
            if publishers:
                update.set_published_topic(topic.name, publishers)
            if subscribers:
                update.set_subscribed_topic(topic.name, sorted(subscribers))
        for name, service in graph.services.services.items():
            provider = service.node if service.handler is not None else self._node(service.provider)
            update.set_advertised_service(name, [provider])
        self.server.publish_connection_graph(update)

    @staticmethod
    def _node(owner: object) -> str:
        if isinstance(owner, str):
            return owner
        return FOXGLOVE_NODE if isinstance(owner, _Client) else BRIDGE_NODE

    # -- channels ---------------------------------------------------------------------------

    def reconcile(self) -> None:
        """Make the channels and services match the graph's topics and services."""
        graph = self.graph
        self._signature = (graph.topics.changes, graph.services.changes)
        wanted = {t.name: t.type for t in graph.topics.listed() if t.known and t.type}
        for name in [n for n, c in self._channels.items() if wanted.get(n) != c.type]:
            self._drop_channel(name)
        for name, type_name in wanted.items():
            if name not in self._channels:
                self._add_channel(name, type_name)
        self._reconcile_services()

    def _add_channel(self, name: str, type_name: str) -> None:
        try:
            text = self.graph.registry.definition_text(type_name)
        except SimbridgeError as err:
            logger.debug("Foxglove: no channel for %s: %s", name, err)
            return
        schema = self.fox.Schema(name=type_name, encoding=SCHEMA_ENCODING, data=text.encode())
        channel = self.fox.Channel(
            name, schema=schema, message_encoding=MESSAGE_ENCODING, context=self.context
        )
        entry = _Channel(name, type_name, channel)
        self._channels[name] = entry
        self._by_id[channel.id()] = entry

    def _drop_channel(self, name: str) -> None:
        entry = self._channels.pop(name)
        self._by_id.pop(entry.channel.id(), None)
        if entry.subscribers:
            self.graph.topics.unsubscribe_internal(name, self._marker)
        entry.channel.close()

    def _marker(self, msg: Any, source: Any) -> None:
        """The in-process subscriber that stands for Foxglove subscribers (does nothing)."""

    def on_deliver(self, topic: Topic, out: Outgoing, source: Peer | None) -> None:
        """Tap on every delivery: log it on the topic's channel if a client subscribed."""
        entry = self._channels.get(topic.name)
        if entry is not None and entry.subscribers:
            self._log(entry, out)

    def _log(self, entry: _Channel, out: Outgoing) -> None:
        try:
            data = out.cdr() if out.cdr is not None else self.cdr.serialize(entry.type, out.msg)
        except Exception as err:  # a message the CDR writer cannot encode: skipped, said once
            logger.debug("Foxglove: %s not sent: %s", entry.topic, err)
            return
        entry.channel.log(data, log_time=self.graph.wall_clock_ns())
        self.stats["published"] += 1

    def _on_clock(self, msg: Any, source: Any) -> None:
        """An in-process subscriber of ``/clock`` (``use_sim_time``): the server's time."""
        clock = msg.get("clock") if isinstance(msg, dict) else None
        if isinstance(clock, dict) and self.server is not None:
            ns = int(clock.get("sec", 0)) * 1_000_000_000 + int(clock.get("nanosec", 0))
            self.server.broadcast_time(max(ns, 0))

    def subscribed(self, client_id: int, channel_id: int) -> None:
        """A client subscribed to a channel (from the SDK, on the loop)."""
        entry = self._by_id.get(channel_id)
        if entry is None:
            return
        if not entry.subscribers:
            self.graph.subscribe(entry.topic, entry.type, FOXGLOVE_NODE, self._marker)
        entry.subscribers.add(client_id)
        if client_id not in self._receiving:  # a client that receives: no Nagle delays
            self._receiving.add(client_id)
            set_nodelay(self.port, self._nodelay)
        topic = self.graph.topics.topics.get(entry.topic)
        if topic is not None and topic.latched is not None:
            self._log(entry, topic.latched)

    def unsubscribed(self, client_id: int, channel_id: int) -> None:
        """A client unsubscribed from a channel or left (from the SDK, on the loop)."""
        entry = self._by_id.get(channel_id)
        if entry is None or client_id not in entry.subscribers:
            return
        entry.subscribers.discard(client_id)
        if not entry.subscribers:
            self.graph.topics.unsubscribe_internal(entry.topic, self._marker)
        if not any(client_id in c.subscribers for c in self._channels.values()):
            self._receiving.discard(client_id)

    # -- clients: publish, calls ------------------------------------------------------------

    def _client(self, client_id: int) -> _Client:
        client = self._clients.get(client_id)
        if client is None:
            access = Access(peer_id=self.graph.next_peer_id())
            client = self._clients[client_id] = _Client(self, client_id, access)
            self.graph.add_peer(client)  # the guard gives the access of a tokenless client
            if self.scope == ADMIN_SCOPE:
                access.scope, access.admin = ANY_SCOPE, True
                access.authenticated = access.guarded = True
            elif self.scope is not None:
                access.scope = self.scope
                access.admin = self.scope == ANY_SCOPE and self.settings.admin_token is None
                access.authenticated = access.guarded = True
            logger.info("%s: publishing or calling", client.label)
        return client

    def _release(self, client: _Client) -> None:
        """Forget a client that holds nothing any more (no channel, no call)."""
        if client.channels or client.calls or self._clients.get(client.client_id) is not client:
            return
        del self._clients[client.client_id]
        self.graph.remove_peer(client)

    def _now(self) -> float:
        return self._loop.time() if self._loop is not None else 0.0

    def advertised(
        self, client_id: int, channel_id: int, topic: str, encoding: str, schema: str
    ) -> None:
        """A client advertised a channel: it publishes ``topic`` (the graph's rules decide)."""
        client = self._client(client_id)
        limit = self.settings.max_advertisements
        if len(client.channels) >= limit:  # each is an advertisement of the client's budget
            self.status(
                f"{client.label}: {topic}: too many client channels (at most {limit}: "
                "max_advertisements)",
                "error",
            )
            return
        if encoding not in CLIENT_ENCODINGS:
            self.status(
                f"{client.label}: {topic}: encoding {encoding!r} is not taken; use "
                f"{' or '.join(CLIENT_ENCODINGS)}",
                "error",
            )
            self._release(client)
            return
        type_name = schema or None
        if type_name is None:
            known = self.graph.topics.topics.get(topic)
            type_name = known.type if known is not None else None
        client.channels[channel_id] = (topic, encoding, type_name)
        if type_name is not None:
            self._advertise(client, channel_id, topic, type_name)

    def _advertise(self, client: _Client, channel_id: int, topic: str, type_name: str) -> bool:
        """Make ``client`` a publisher of ``topic`` on the graph; whether it may."""
        refusal = self.graph.access.publish_refusal(client.access, topic)
        try:
            if refusal is not None:
                raise ProtocolError(f"advertise {refusal}")
            self.graph.topics.advertise(topic, type_name, client, f"foxglove:{channel_id}")
        except ProtocolError as err:
            self.status(f"{client.label}: {err}", "error")
            return False
        return True

    def unadvertised(self, client_id: int, channel_id: int) -> None:
        """A client unadvertised a channel (or left): it no longer publishes its topic."""
        client = self._clients.get(client_id)
        if client is None:
            return
        entry = client.channels.pop(channel_id, None)
        if entry is not None:
            self.graph.topics.unadvertise(entry[0], client, f"foxglove:{channel_id}")
        self._release(client)

    def message(self, client_id: int, channel_id: int, data: bytes) -> None:
        """A client's message: published on the graph as the graph's rules allow.

        The same rules as a rosbridge client's ``publish``: the client's scope (the graph's
        access rules), its publish rate (``publish_rate``, once a guard authenticates the
        peers), the topic's type, the payload validated and completed against it.
        """
        client = self._clients.get(client_id)
        entry = client.channels.get(channel_id) if client is not None else None
        if client is None or entry is None:
            return
        topic_name, encoding, type_name = entry
        self.stats["received"] += 1
        now = self._now()
        graph = self.graph
        topics = graph.topics
        try:
            refusal = graph.access.publish_refusal(client.access, topic_name)
            if refusal is not None:
                raise ProtocolError(f"publish {refusal}")
            if graph.access.guarded and not client.publishes.take(now):
                s = self.settings
                msg = (
                    f"publish {topic_name}: dropped, more than {s.publish_rate:g} publishes per "
                    f"second (the server's publish_rate, burst {s.publish_burst}); slow down"
                )
                raise ProtocolError(msg)
            if type_name is None:
                known = topics.topics.get(topic_name)
                type_name = known.type if known is not None else None
            if type_name is None:
                msg = (
                    f"publish: cannot infer the type of topic {topic_name}: it is not "
                    "advertised; give the channel a schema name"
                )
                raise ProtocolError(msg)
            if encoding == MESSAGE_ENCODING:
                payload = plain(self.reader.read(type_name, data))
            else:
                payload = orjson.loads(data)
        except ProtocolError as err:
            self.status(f"{client.label}: {err}", "error")
            return
        except Exception as err:  # whatever the client sent: told, never raised
            self.status(f"{client.label}: publish {topic_name}: cannot decode: {err}", "error")
            return
        try:
            topic = topics.topics.get(topic_name)
            if topic is None or client not in topic.publishers:
                if not self._advertise(client, channel_id, topic_name, type_name):
                    return
                entry = (topic_name, encoding, type_name)
                client.channels[channel_id] = entry
                topic = topics.topics[topic_name]
            msg = topics.convert(topic, payload)
            topics.deliver(topic, topics.outgoing(topic, msg, graph.stamp()), now, client)
        except SimbridgeError as err:  # a payload that does not fit, a command refused
            self.status(f"{client.label}: publish {topic_name}: {err}", "error")

    async def call(self, client_id: int, name: str, encoding: str, payload: bytes) -> bytes:
        """A client's service call: a rosbridge ``call_service`` of its session.

        Raises:
            ServiceError: the call was refused or failed (the SDK tells the client why).
        """
        self.stats["calls"] += 1
        type_name = self._services.get(name)
        service = self.graph.services.services.get(name)
        if type_name is None or service is None:
            msg = f"service {name} does not exist (any more)"
            raise ServiceError(msg)
        request_type, response_type = self.graph.registry.service(type_name)
        try:
            if encoding == MESSAGE_ENCODING:
                request = self.reader.read(request_type, payload)  # canonical, complete
            else:
                request = orjson.loads(payload) if payload else {}
        except Exception as err:
            text = f"service {name}: request is not {encoding} of {request_type}: {err}"
            raise ServiceError(text) from None
        ok, values = await self._call(client_id, name, request, typed=encoding == MESSAGE_ENCODING)
        if not ok:
            raise ServiceError(str(values))
        # complete and checked: an in-process handler may leave fields to their defaults
        response = self.graph.converter.from_json(response_type, values)
        if encoding == MESSAGE_ENCODING:
            return self.cdr.serialize(response_type, response)
        return orjson.dumps(plain(response))

    async def _call(
        self, client_id: int, name: str, request: Any, *, typed: bool
    ) -> tuple[bool, Any]:
        """Call the graph's service ``name`` for a client; return ``(ok, values)``.

        ``request`` is the canonical request (``typed``: decoded from CDR) or JSON values,
        checked and completed here as a rosbridge client's ``args`` are. Refused (``ok``
        false, the reason as ``values``) by the graph's access rules for the client, when the
        service does not exist, when the request does not fit, or when ``max_pending_calls``
        of the client's calls wait for providers outside this process.
        """
        client = self._client(client_id)
        number = next(self._call_ids)
        try:
            service = self.graph.services.lookup(name)
            refusal = self.graph.access.reach_refusal(client.access, name)
            if refusal is not None:
                return False, f"service {refusal}"
            if not typed:
                prepared = self._prepare(service.type, request)
                if prepared is not None:
                    request = prepared
            waits = service.handler is None
            if waits and client.waiting >= self.settings.max_pending_calls:
                limit = self.settings.max_pending_calls
                return False, (
                    f"call_service {name}: refused, this client already waits for {limit} "
                    "answers (the server's max_pending_calls); wait for them first"
                )
            loop = asyncio.get_running_loop()
            future: asyncio.Future[tuple[bool, Any]] = loop.create_future()
            client.calls[number] = future

            def done(ok: bool, values: Any) -> None:
                if not future.done():
                    future.set_result((ok, values))

            settings = self.settings
            timeout = min(settings.service_timeout, settings.max_call_timeout)
            if waits:
                client.waiting += 1
            release = client.call_ended if waits else None
            self.graph.services.call(
                client, service, request, loop.time() + timeout, done, release=release
            )
            return await asyncio.wait_for(future, timeout + CALL_MARGIN / 2)
        except ServiceError as err:
            return False, str(err)
        finally:
            client.calls.pop(number, None)
            self._release(client)

    def _reconcile_services(self) -> None:
        wanted: dict[str, str] = {}
        for name, service in self.graph.services.services.items():
            try:
                self.graph.registry.service(service.type)
            except SimbridgeError:
                continue
            wanted[name] = service.type
        gone = [n for n, t in self._services.items() if wanted.get(n) != t]
        if gone:
            self.server.remove_services(gone)
            for name in gone:
                del self._services[name]
        new = [self._service(n, t) for n, t in wanted.items() if n not in self._services]
        new = [s for s in new if s is not None]
        if new:
            self.server.add_services(new)
            for service in new:
                self._services[service.name] = wanted[service.name]

    def _service(self, name: str, type_name: str) -> Any:
        fox = self.fox
        try:
            request, response = self.graph.registry.service(type_name)
            parts = [
                fox.MessageSchema(
                    encoding=MESSAGE_ENCODING,
                    schema=fox.Schema(
                        name=part,
                        encoding=SCHEMA_ENCODING,
                        data=self.graph.registry.definition_text(part).encode(),
                    ),
                )
                for part in (request, response)
            ]
        except SimbridgeError as err:
            logger.debug("Foxglove: no service %s: %s", name, err)
            return None
        schema = fox.ServiceSchema(type_name, request=parts[0], response=parts[1])
        return fox.Service(name, schema=schema, handler=self._handler(name))

    def _handler(self, name: str) -> Callable[[Any], bytes]:
        timeout = self.settings.service_timeout + CALL_MARGIN

        def handle(request: Any) -> bytes:  # an SDK blocking-pool thread: it may wait
            loop = self._loop
            if loop is None:
                msg = "the server is stopping"
                raise ServiceError(msg)
            coro = self.call(request.client_id, name, request.encoding, bytes(request.payload))
            future = asyncio.run_coroutine_threadsafe(coro, loop)
            try:
                return future.result(timeout)
            except concurrent.futures.TimeoutError:
                future.cancel()
                msg = f"service {name}: no answer within {timeout:.0f} s"
                raise ServiceError(msg) from None

        return handle

    # -- parameters -------------------------------------------------------------------------

    def _snapshot_params(self) -> None:
        values: dict[str, Any] = {}
        for node in self.graph.params.nodes.values():
            for key, value in node.read().items():
                values[param_name(node.name, key)] = value
        self._params = values  # one assignment: SDK threads read either the old or the new

    def params_changed(self, node: str, names: list[str]) -> None:
        """A node's parameters changed (the builder adds this to ``graph.params.on_change``)."""
        self._snapshot_params()
        # a change of a Foxglove client is published by the SDK itself (see set_parameters);
        # one from elsewhere (/admin, rosbridge) only while a client subscribed to one (the
        # SDK's lock hazard: module doc)
        full = [param_name(node, n) for n in names]
        held = self._holder_ws is not None and self._holding.issuperset(full)
        if self.server is not None and full and not self._setting and held:
            params = self._parameters(full)
            if params:
                self.server.publish_parameter_values(params)

    def _parameters(self, names: list[str] | None) -> list[Any]:
        """Return the SDK parameters of ``names`` (None: all) from the snapshot."""
        values = self._params
        fox = self.fox
        out = []
        for name in names or values:
            if name not in values:
                continue
            value = values[name]
            if isinstance(value, float):
                out.append(fox.Parameter(name, value=value, type=fox.ParameterType.Float64))
            elif isinstance(value, list) and all(isinstance(v, float) for v in value) and value:
                out.append(
                    fox.Parameter(name, value=list(value), type=fox.ParameterType.Float64Array)
                )
            elif isinstance(value, list):
                out.append(fox.Parameter(name, value=[float(v) for v in value]))
            else:
                out.append(fox.Parameter(name, value=value))
        return out

    async def set_parameters(self, client_id: int, changes: list[tuple[str, Any]]) -> None:
        """A client set parameters: ``/rosapi/set_param`` calls of its session, in order.

        The SDK publishes the values its listener returns to the clients that subscribed to
        them (in Rust, without the GIL), so a change made here is not published again.
        """
        self.stats["parameter_sets"] += 1
        nodes = list(self.graph.params.nodes)
        for full, value in changes:
            split = split_param(full, nodes)
            if split is None:
                self.status(f"Foxglove client {client_id}: no parameter {full}", "warning")
                continue
            args = {"name": f"{split[0]}:{split[1]}", "value": json.dumps(value)}
            self._setting += 1  # the in-process service applies the change in the call
            try:
                ok, values = await self._call(client_id, "/rosapi/set_param", args, typed=False)
            finally:
                self._setting -= 1
            if not ok:
                self.status(
                    f"Foxglove client {client_id}: parameter {full} not set: {values}",
                    "warning",
                )

    # -- status -----------------------------------------------------------------------------

    def status(self, text: str, level: str) -> None:
        """Send a status message (the SDK's Python API sends it to every client)."""
        self.stats["refused"] += level == "error"
        if self.server is None:
            return
        levels = self.fox.StatusLevel
        kind = {"info": levels.Info, "warning": levels.Warning, "warn": levels.Warning}
        self.server.publish_status(text[:500], kind.get(level, levels.Error))


class _Listener:
    """The SDK's server listener: every callback hands its arguments to the event loop."""

    def __init__(self, front: FoxgloveFront) -> None:
        self.front = front

    def _soon(self, callback: Callable[..., None], *args: Any) -> None:
        loop = self.front._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(callback, *args)

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._soon(self.front.subscribed, client.id, channel.id)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self._soon(self.front.unsubscribed, client.id, channel.id)

    def on_client_advertise(self, client: Any, channel: Any) -> None:
        self._soon(
            self.front.advertised,
            client.id,
            channel.id,
            str(channel.topic),
            str(channel.encoding),
            str(channel.schema_name or ""),
        )

    def on_client_unadvertise(self, client: Any, client_channel_id: int) -> None:
        self._soon(self.front.unadvertised, client.id, client_channel_id)

    def on_message_data(self, client: Any, client_channel_id: int, data: bytes) -> None:
        front, size, client_id = self.front, len(data), int(client.id)
        loop = front._loop
        if loop is None or loop.is_closed():
            return
        with front._waiting_lock:
            waiting = front._waiting.setdefault(client_id, [0, 0])
            if waiting[0] >= INBOX_MESSAGES or waiting[1] + size > INBOX_BYTES:
                front.stats["messages_dropped"] += 1  # over the client's inbox: dropped here
                return
            waiting[0] += 1
            waiting[1] += size
        loop.call_soon_threadsafe(self._message, client_id, client_channel_id, bytes(data))

    def _message(self, client_id: int, channel_id: int, data: bytes) -> None:
        front = self.front
        with front._waiting_lock:
            waiting = front._waiting.get(client_id)
            if waiting is not None:
                waiting[0] -= 1
                waiting[1] -= len(data)
                if waiting[0] <= 0:
                    del front._waiting[client_id]
        front.message(client_id, channel_id, data)

    def on_get_parameters(
        self, client: Any, param_names: list[str], request_id: str | None = None
    ) -> list[Any]:
        return self.front._parameters(list(param_names) or None)  # the snapshot: no wait

    def on_set_parameters(
        self, client: Any, parameters: list[Any], request_id: str | None = None
    ) -> list[Any]:
        # this client's task waits (the GIL released) for the loop to apply the change; the
        # SDK holds no lock meanwhile, and sends what is returned to the parameters' subscribers
        changes = [(str(p.name), p.get_value()) for p in parameters]
        loop = self.front._loop
        if loop is not None and not loop.is_closed():
            coro = self.front.set_parameters(client.id, changes)
            future = asyncio.run_coroutine_threadsafe(coro, loop)
            try:
                future.result(SET_TIMEOUT)
            except Exception as err:  # a timeout: the values as they are now
                logger.debug("Foxglove: parameter set not applied in time: %r", err)
        return self.front._parameters([name for name, _ in changes])

    # called with the SDK's parameter or connection-graph lock held (module doc): they do nothing
    def on_connection_graph_subscribe(self) -> None:
        return None

    def on_connection_graph_unsubscribe(self) -> None:
        return None

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        return None

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        return None
