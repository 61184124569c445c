"""simbridge on the ROS 2 graph through Zenoh, as an rmw_zenoh process.

:class:`ZenohLink` keeps a Zenoh session beside the graph and maps both ways:

* **outward**: every in-process node (``/virtual_robot``, ``/sim``, ...) and the rosbridge
  clients (as ``/rosbridge_websocket``, like rosbridge_suite) get rmw_zenoh liveliness tokens
  for their publishers, subscriptions and services. Messages go out on the topic's key
  expression with rmw_zenoh's attachment, serialized to CDR once (the bytes are shared with
  ``cbor-raw`` subscribers) and only while a ROS 2 subscriber exists; latched topics are
  transient-local advanced publishers with a one-sample cache, as rmw_zenoh declares them.
  Services are queryables; a call's CDR request is read into the canonical request
  (:meth:`ZenohLink._on_query`: the graph's access rules for the ROS 2 peers' role first) and
  handed to the graph's service table (in-process handlers and services advertised by
  rosbridge clients alike), whose answer comes back to :meth:`ZenohLink._service_answer` and
  goes out as CDR: no JSON on the way;
* **inward**: publishers and services of other rmw_zenoh processes (found from their tokens,
  gone with them) join the graph, so rosapi lists them and rosbridge clients subscribe, publish
  and call. A remote service is provided in the graph's table with a forwarder
  (:meth:`_Provider.forward`): the canonical request goes out as CDR in a query, the CDR reply
  comes back as the canonical response (:meth:`ZenohLink._remote_done`). Data is subscribed only
  while a rosbridge client or an in-process node listens.

Data samples of the first :data:`CALLBACK_KEYS` subscribed keys come by a callback through an
inbox (at once); past those, they wait in one Zenoh ring channel per key, which the event loop
polls (no Python callback, hence no GIL hand-over, per sample); Zenoh runs the other callbacks
(tokens, queries, replies, latched topics' samples) on its own threads, and they only hand them
to the event loop (``call_soon_threadsafe``). Bad input from the network (a payload that is not
CDR of its type, an unknown type, a name that clashes, a token that vanishes mid-call) becomes a
failed service response or one rate-limited log line, never an exception in the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import itertools
import logging
import os
import sys
import time
from collections import Counter, deque
from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import Any

from simbridge.app.settings import ServerSettings
from simbridge.errors import ConfigError, SimbridgeError
from simbridge.graph import Graph, Topic
from simbridge.graph.access import Access
from simbridge.graph.services import PendingCall
from simbridge.graph.topics import Peer
from simbridge.msgs.cdr import CdrReader, CdrWriter
from simbridge.msgs.message import Outgoing
from simbridge.robot.bridge import ROBOT_NODE
from simbridge.robot.simclock import SIM_NODE
from simbridge.ros2.link import (
    DRAIN_BATCH,
    DRAIN_BYTES,
    ForeignNode,
    Imports,
    Inbox,
    Logbook,
    Refusals,
    Ros2Peer,
    StandIns,
    Take,
    graph_signature,
    local_owner,
    outward_services,
    outward_topics,
)
from simbridge.ros2.names import (
    ADMIN_SPACE,
    DEFAULT_QOS,
    LATCHED_QOS,
    Entity,
    Qos,
    dds_type,
    entity_gid,
    split_node,
    topic_keyexpr,
)
from simbridge.ros2.role import ros2_access
from simbridge.ros2.typehash import TypeHasher
from simbridge.ros2.zenoh.actions import ActionBridge, split_action
from simbridge.ros2.zenoh.attachment import Attachment, pack_attachment
from simbridge.ros2.zenoh.config import ZenohOptions, session_config


__all__ = ["RemoteNode", "ZenohLink", "calm_transmit_threads", "import_zenoh"]

logger = logging.getLogger(__name__)

INSTALL_HINT = 'pip install "simbridge[zenoh]" (in a checkout: pip install ".[zenoh]")'
#: Seconds between two looks at the session's state (connected or not) and the actions' results.
RECONCILE_PERIOD = 0.5
#: Seconds between two full comparisons of the graph with what is declared while nothing
#: changed (the graph's change counters and the tokens say when something did): a safety net
#: for a change made around the tables. A full pass took 15-30 ms with 300 robots, which every
#: 0.5 s delayed a tick's messages (bench.zenoh classroom).
FULL_PERIOD = 30.0
#: Seconds a call from ROS 2 waits for a provider that is not in process (a rosbridge client,
#: another ROS 2 process), and a call to another ROS 2 process for its reply (capped by
#: ``max_call_timeout``).
SERVICE_TIMEOUT = 10.0
#: Calls from ROS 2 (Zenoh queries) waiting for the event loop at most; their request bytes are
#: bounded by ``zenoh_inbox_bytes`` too. Past either, a call is refused on Zenoh's thread with
#: an error reply (counted: ``calls_refused``) instead of growing the loop's queue.
CALL_INBOX_LIMIT = 1_000
#: Samples of the ring channels handed to the graph per poll callback at most. The frames
#: they make for the clients are written when the callback ends (the server corks them:
#: :meth:`simbridge.rosbridge.server.BridgeServer.send_many`). With 32 a callback, the clients
#: got the
#: start of a tick's burst sooner (bench.zenoh classroom 2 x 300: latency p50 19.9-21.5 ->
#: 17.2-19.5 ms) but a client's /odom and /scan went out together less often (23 -> 29 reads
#: per client per second, 0.1-0.2 core more in all), and the p99 rose (32.2, 41.9, 41.1 ->
#: 38.2, 57.0, 46.4 ms in three alternating pairs): a whole burst a callback.
POLL_BATCH = 500
#: The interpreter's GIL switch interval while Zenoh runs (seconds; Python's default is 5 ms).
SWITCH_INTERVAL = 0.0005
#: Subscribed keys whose samples a Zenoh callback hands to the event loop at once (the inbox)
#: instead of a ring channel the loop polls: with few topics, a callback's GIL hand-over costs
#: little and a sample does not wait for the next poll (the hop benchmark's p99 went from about
#: 1-2 ms to 4 ms with every key polled); past these, polling is cheaper per sample (12 against
#: 54 us with 300 callback subscribers).
CALLBACK_KEYS = 8
#: Samples one topic's ring channel holds for the event loop (the oldest go past it: 5 s of a
#: 20 Hz topic).
RING = 100
#: Remote token changes applied per event-loop callback at most (see ZenohLink._drain_tokens).
TOKEN_BATCH = 200
#: The nodes of a simbridge simulator (a process with both takes a turn: ZenohLink.tick_share).
_SIMULATOR_NODES = frozenset({ROBOT_NODE, SIM_NODE})
#: Messages held back for Zenoh from which a tick's first part (its /odom) is put before the
#: rest is computed (see ZenohLink.flush_early).
EARLY_FLUSH = 100
#: The name of Zenoh's transmit threads (its ``tx`` runtime's; they exist once a link is up).
TX_THREADS = "tx-"
#: Seconds between two polls of the ring channels while samples arrive, at least and at most;
#: in between, the period grows with the number of channels so that polling an empty channel
#: costs about 1 % of a core (0.2 us each, ``try_recv`` 0.11 us of it) up to 250 channels,
#: 2.4 % at 600.
POLL_MIN, POLL_MAX = 0.0005, 0.005
POLL_PER_CHANNEL = 0.00002
#: Seconds without a sample after which the channels are no longer polled on a timer of their
#: own but once per tick of the loop (:meth:`ZenohLink.tick`), so that an idle server wakes up
#: for nothing else: a timer of its own, even every 20 ms, cost 0.9 % of a core in a process
#: with a Zenoh session (about 180 us of CPU a wake-up), and doubled what a quiet simulator
#: used. The first sample after a silence waits at most one tick (50 ms at 20 Hz): a command
#: moves a robot at a tick anyway.
IDLE_AFTER = 1.0


def import_zenoh(what: str = "--zenoh") -> Any:
    """Import eclipse-zenoh for ``what`` (the option or command the user gave).

    Raises:
        ConfigError: it is not installed (the message names ``what`` and the install command).
    """
    try:
        return importlib.import_module("zenoh")
    except ImportError:
        msg = f"{what} needs the Zenoh extra: {INSTALL_HINT}"
        raise ConfigError(msg) from None


class RemoteNode(ForeignNode):
    """A node of another rmw_zenoh process (``RemoteNode(name, zid)``: its Zenoh session)."""

    @property
    def zid(self) -> str:
        """The Zenoh session id of the node's process."""
        return self.origin


@dataclass(eq=False, slots=True)
class _Declared:
    """An entity simbridge declared: its token and its Zenoh object."""

    entity: Entity
    token: Any
    gid: bytes
    #: Publisher, queryable or subscriber (None for nodes and subscriptions' tokens).
    handle: Any = None
    latched: bool = False
    sequence: itertools.count[int] = field(default_factory=lambda: itertools.count(1))


class _Caller(Ros2Peer):
    """The peer that makes a ROS 2 call through the graph's service table."""

    label = "ROS 2 (Zenoh)"

    def __init__(self, link: ZenohLink, access: Access) -> None:
        self.link = link
        #: Who the ROS 2 peers are for the graph's rules (``--ros2-role``).
        self.access = access


class _Provider(Ros2Peer):
    """The peer that provides a remote ROS 2 service to the graph (calls become queries)."""

    __slots__ = ("access", "entity", "label", "link")

    def __init__(self, link: ZenohLink, access: Access, entity: Entity) -> None:
        self.link = link
        #: Who the remote server is for the graph's rules (the ROS 2 peers' role).
        self.access = access
        self.entity = entity
        self.label = f"ROS 2 service {entity.name} of {entity.node_fqn} (Zenoh)"

    def forward(self, call: PendingCall, request: Any) -> None:
        """The graph's service table forwards a call: it goes out as a query."""
        self.link._remote_call(self, call, request)


class ZenohLink:
    """One Zenoh session joining simbridge's graph to the ROS 2 graph (see the module doc)."""

    def __init__(
        self,
        graph: Graph,
        options: ZenohOptions,
        *,
        simulator: bool = False,
        settings: ServerSettings | None = None,
    ) -> None:
        #: The graph mapped onto ROS 2.
        self.graph = graph
        #: The server's settings (the link's budgets, the ROS 2 peers' role).
        self.settings = settings = settings or ServerSettings()
        #: Counters for /healthz.
        self.stats: Counter[str] = Counter()
        #: Warnings, rate-limited (also on /rosout), and notes said once.
        self.logbook = Logbook(graph, "Zenoh", "simbridge.ros2.zenoh", self.stats, logger)
        self._log = self.logbook.warn
        self._note = self.logbook.note
        #: Whether this process simulates robots (not ``--no-sim``): it takes a turn in the
        #: step period with the other simulators (:attr:`tick_share`).
        self.simulator = simulator
        #: Domain, distribution, endpoints.
        self.options = options
        self.zenoh = import_zenoh()
        self.config = session_config(
            self.zenoh, options, max_sample_bytes=settings.zenoh_max_sample_bytes
        )
        self.hasher = TypeHasher(graph.registry, options.distro)
        self.cdr = CdrWriter(graph.registry)
        self.reader = CdrReader(graph.registry)
        #: "starting", "connecting" (no router or peer yet), "connected", "closed", "failed".
        self.state = "starting"
        self.error: str | None = None
        self.session: Any = None
        self.zid = ""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ids = itertools.count(0)
        self._node_ids: dict[str, str] = {}
        #: What simbridge declared, by (kind, node, name).
        self._declared: dict[tuple[str, str, str], _Declared] = {}
        #: Outward publishers by topic name (one per topic, under its first local node).
        self._publishers: dict[str, _Declared] = {}
        #: Remote entities by token.
        self._remote: dict[str, Entity] = {}
        #: Tokens of the nodes every simbridge simulator has (``/virtual_robot`` and ``/sim``),
        #: by Zenoh session id of the other processes: a session with both is a simulator.
        self._sim_nodes: dict[str, set[str]] = {}
        #: This simulator's place among the simulators of the network and their number (by
        #: session id), or None alone: where in the step period it ticks (see
        #: :meth:`_update_share`).
        self.tick_share: tuple[int, int] | None = None
        self._remote_dirty = True
        #: Remote token changes from Zenoh's threads waiting for the event loop (under the
        #: inbox's lock), and whether it was woken (see :meth:`_drain_tokens`).
        self._tokens: deque[tuple[str, bool]] = deque()
        self._tokens_rung = False
        #: Remote tokens kept at most (``zenoh_max_remote_tokens``).
        self.max_tokens = settings.zenoh_max_remote_tokens
        #: The remote entities by what they stand for: topic and service names (token ->
        #: entity), node names (tokens), actions' parts (token -> entity).
        self._by_name: dict[str, dict[str, Entity]] = {}
        self._remote_node_tokens: Counter[str] = Counter()
        self._action_parts: dict[str, Entity] = {}
        #: Remote subscriptions per topic name (publish only while there is one).
        self._remote_subs: Counter[str] = Counter()
        #: Inward: topic owners and services simbridge added to the graph for remote entities.
        self._providers: dict[str, _Provider] = {}
        #: Nodes of other processes listed in the graph (rosapi's nodes), by name.
        self._remote_nodes: set[str] = set()
        #: Remote subscriptions stand in the graph as in-process subscribers that do nothing
        #: (so that the simulation publishes what only ROS 2 listens to, and rosapi lists them).
        self.stand_ins = StandIns(graph, self.logbook)
        #: Inward data subscribers by topic name, then key expression.
        self._subscribers: dict[str, dict[str, Any]] = {}
        #: Their ring channels (all but latched topics') by (topic, key expression), polled by
        #: the event loop.
        self._channels: dict[tuple[str, str], Any] = {}
        #: The first :data:`CALLBACK_KEYS` subscribed keys (topic, key expression): delivered by
        #: a callback through the inbox instead.
        self._callback_keys: set[tuple[str, str]] = set()
        self._channel_list: list[tuple[str, Any]] = []
        self._poll_next = 0  # where the last poll stopped (a flood is shared out fairly)
        self._poll_handle: asyncio.Handle | None = None
        #: Loop time of the last poll that found a sample (polls slow down after a silence).
        self._last_sample = float("-inf")
        #: Calls from ROS 2 waiting for a provider that is not in process, at most
        #: ``max_pending_calls`` (the budget of one rosbridge client: the ROS 2 peers are one).
        self.calls_waiting = 0
        self.max_calls_waiting = settings.max_pending_calls
        #: Calls to ROS 2 waiting for a reply: the graph's call id -> (provider, type, call).
        self._calls: dict[str, tuple[_Provider, str, PendingCall]] = {}
        # whatever comes from ROS 2 (samples, calls, goals, remote publishers and services)
        # is admitted as one peer of the role the instructor chose (--ros2-role; in class
        # mode by default a student without a robot: it reads, it drives nothing)
        scope, admin = ros2_access(settings)
        access = Access(scope, admin, guarded=True, peer_id=graph.next_peer_id())
        self._caller = _Caller(self, access)
        #: Why ROS 2 peers may not publish on a name (None: they may), by name.
        self.refusals = Refusals(graph, access, self.logbook)
        self._refused = self.refusals.refused
        self.imports = Imports(graph, self.refusals, self._local_clash, clients_clash=False)
        self._call_ids = itertools.count(1)
        self._forwarding = False
        self._next_reconcile = 0.0
        self._next_full = 0.0
        self._generation = -1
        #: The budgets of samples (``zenoh_max_sample_bytes``, ``zenoh_inbox_bytes``).
        self.max_sample = settings.zenoh_max_sample_bytes
        self.max_inbox = settings.zenoh_inbox_bytes
        #: Samples from Zenoh's threads waiting for the event loop (past its bounds, the oldest
        #: are dropped: ``samples_dropped``); its lock guards the link's other queues too.
        self.inbox = Inbox(
            self.logbook,
            max_bytes=self.max_inbox,
            max_sample=self.max_sample,
            dropped="samples_dropped",
            oversized="samples_oversized",
            setting="zenoh",
        )
        #: Calls from ROS 2 waiting for the event loop (service, type, query, request bytes),
        #: their bytes, and whether the loop was woken; under the inbox's lock.
        self._call_inbox: deque[tuple[str, str, Any, int]] = deque()
        self._calls_bytes = 0
        self._calls_rung = False
        self._switch_interval = sys.getswitchinterval()
        #: Whether Zenoh's transmit threads were found (and made SCHED_BATCH: see
        #: :func:`calm_transmit_threads`).
        self._tx_calmed = False
        #: Deliveries to send to ROS 2 at the end of the current event-loop callback.
        self._outbox: list[tuple[_Declared, Outgoing]] = []
        self._liveliness_sub: Any = None
        #: Actions both ways (rcl_action's services and topics).
        self.actions = ActionBridge(self)

    # -- lifecycle ------------------------------------------------------------------------

    async def start(self) -> None:
        """Open the session (in a thread: it may wait for the network) and start watching."""
        self._loop = self.inbox.loop = asyncio.get_running_loop()
        # Zenoh's threads hand each sample over under the GIL; behind a busy event loop they
        # waited up to the 5 ms switch interval (a sample's p50 latency 2.2 ms -> 1.0 ms at
        # 0.5 ms, with the loop 70 % busy: measured with 4500 samples/s)
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch_interval, SWITCH_INTERVAL))
        try:
            self.session = await self._loop.run_in_executor(None, self.zenoh.open, self.config)
        except Exception as err:  # Zenoh refuses the configuration or cannot listen
            self.state, self.error = "failed", str(err)
            logger.error("Zenoh session could not open: %s", err)
            return
        self.zid = str(self.session.info.zid())
        self.state = "connecting"
        self._liveliness_sub = self.session.liveliness().declare_subscriber(
            f"{ADMIN_SPACE}/{self.options.domain}/**", self._on_token, history=True
        )
        self._update_state()
        logger.info(
            "Zenoh: session %s, domain %d, ROS 2 %s, connecting to %s",
            self.zid,
            self.options.domain,
            self.options.distro,
            ", ".join(self.options.connect) or "the configured endpoints",
        )
        self.reconcile(force=True)

    async def close(self) -> None:
        """Withdraw every token and close the session."""
        session, self.session = self.session, None
        if session is None:
            return
        self.state = "closed"
        self._loop = self.inbox.loop = None  # Zenoh's threads hand nothing more to the loop
        sys.setswitchinterval(self._switch_interval)
        self.actions.close()
        for entry in list(self._declared.values()):
            self._undeclare(entry)
        self._declared.clear()
        self._publishers.clear()
        for subs in self._subscribers.values():
            for sub in subs.values():
                _quietly(sub.undeclare)
        self._subscribers.clear()
        self._callback_keys.clear()
        self._set_channels({})
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, session.close)

    def health(self) -> dict[str, Any]:
        """Return the ``zenoh`` part of ``/healthz``."""
        self._update_state()
        out: dict[str, Any] = {
            "state": self.state,
            "zid": self.zid,
            "domain": self.options.domain,
            "ros_distro": self.options.distro,
            "declared": len(self._declared),
            "remote_entities": len(self._remote),
            "tick_share": list(self.tick_share) if self.tick_share is not None else None,
            **dict(self.stats),
        }
        if self.session is not None:
            info = self.session.info
            out["routers"] = len(list(info.routers_zid()))
            out["peers"] = len(list(info.peers_zid()))
        if self.error:
            out["error"] = self.error
        return out

    def _update_state(self) -> None:
        if self.session is None or self.state in ("closed", "failed"):
            return
        info = self.session.info
        linked = bool(list(info.routers_zid())) or bool(list(info.peers_zid()))
        if linked and not self._tx_calmed:
            self._tx_calmed = calm_transmit_threads() > 0
        new = "connected" if linked else "connecting"
        if new != self.state:
            self.state = new
            logger.info("Zenoh: %s", new)

    # -- the periodic pass ------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Bring what is declared in line with the graph (often enough, cheaply)."""
        if self.session is None:
            return
        if self._poll_handle is None and self._channel_list:
            self._poll()  # idle: polled once a tick (see IDLE_AFTER)
        changed = self._signature() != self._generation
        if now >= self._next_full or (changed and self._due(now)):
            self.reconcile()
            self._next_reconcile = now + RECONCILE_PERIOD
            self._next_full = now + FULL_PERIOD
        elif now >= self._next_reconcile:
            self._update_state()
            self.actions.tick()
            self._next_reconcile = now + RECONCILE_PERIOD

    def _signature(self) -> int:
        return graph_signature(self.graph)

    def _due(self, now: float) -> bool:
        return now >= self._next_reconcile - RECONCILE_PERIOD + 0.05

    def reconcile(self, *, force: bool = False) -> None:
        """Declare what the graph has and Zenoh lacks, undeclare what went, both ways."""
        if self.session is None:
            return
        self.stats["reconciles"] += 1
        if self._remote_dirty or force:
            self._remote_dirty = False
            self._import_remote()
        # after the import, which adds to the graph's tables: what it changed is handled below,
        # not again by a second pass at the next tick
        self._generation = self._signature()
        self._export_local()
        self._update_subscribers()
        self._update_state()
        self.actions.tick()

    # -- outward ----------------------------------------------------------------------------

    def _wanted(self) -> dict[tuple[str, str, str], tuple[str, str, Qos]]:
        """Return the local entities: (kind, node, name) -> (kind, type, QoS)."""
        want: dict[tuple[str, str, str], tuple[str, str, Qos]] = {}
        for node in self.graph.nodes:
            if node not in self._remote_nodes:
                want[("NN", node, "")] = ("NN", "", DEFAULT_QOS)
        for topic, publishers, subscribers in outward_topics(self.graph, self.stand_ins.ids):
            type_name = topic.type or ""
            # the graph's offer in rmw_zenoh's tokens (its default depth is elided from them)
            qos = LATCHED_QOS if topic.qos.transient_local else DEFAULT_QOS
            for node in publishers:
                want[("MP", node, topic.name)] = ("MP", type_name, qos)
            for node in subscribers:
                want[("MS", node, topic.name)] = ("MS", type_name, DEFAULT_QOS)
        for service, node in outward_services(self.graph):
            if not self.actions.exports_service(service.name):
                continue  # the cancel service of another process's action
            want[("SS", node, service.name)] = ("SS", service.type, DEFAULT_QOS)
        want.update(self.actions.wanted())
        for key in list(want):
            if key[0] != "NN":
                want.setdefault(("NN", key[1], ""), ("NN", "", DEFAULT_QOS))
        return want

    def _export_local(self) -> None:
        want = self._wanted()
        for key in [k for k in self._declared if k not in want]:
            self._undeclare(self._declared.pop(key))
        # nodes first: their ids are the endpoints' node ids
        for key in sorted(want, key=lambda k: k[0] != "NN"):
            if key in self._declared:
                continue
            kind, type_name, qos = want[key]
            try:
                self._declare(key, kind, type_name, qos)
            except (SimbridgeError, ValueError) as err:
                self._log(f"declare {key}", f"Zenoh: cannot declare {key[2] or key[1]}: {err}")
        publishers: dict[str, _Declared] = {}
        for key, entry in self._declared.items():
            if key[0] == "MP":
                publishers.setdefault(key[2], entry)
        self._publishers = publishers

    def _declare(self, key: tuple[str, str, str], kind: str, type_name: str, qos: Qos) -> None:
        _, node, name = key
        namespace, short = split_node(node)
        nid = self._node_ids.get(node)
        if nid is None:
            nid = self._node_ids[node] = str(next(self._ids))
        if kind == "NN":
            entity = Entity(self.options.domain, self.zid, nid, nid, "NN", namespace, short)
        else:
            type_hash = (
                self.hasher.service(type_name) if kind == "SS" else self.hasher.message(type_name)
            )
            entity = Entity(
                self.options.domain,
                self.zid,
                nid,
                str(next(self._ids)),
                kind,  # type: ignore[arg-type]
                namespace,
                short,
                name=name,
                type=type_name,
                type_hash=type_hash,
                qos=qos,
            )
        z, session = self.zenoh, self.session
        handle = None
        if kind == "MP":
            if qos.transient_local:
                ext = importlib.import_module("zenoh.ext")
                handle = ext.declare_advanced_publisher(
                    session,
                    entity.keyexpr(),
                    cache=ext.CacheConfig(max_samples=qos.depth),
                    publisher_detection=True,
                    sample_miss_detection=ext.MissDetectionConfig(sporadic_heartbeat=0.5),
                )
            else:
                handle = session.declare_publisher(
                    entity.keyexpr(), congestion_control=z.CongestionControl.DROP
                )
        elif kind == "SS":
            handle = session.declare_queryable(
                entity.keyexpr(),
                self._query_handler(name, type_name),
                complete=True,
                allowed_origin=z.Locality.REMOTE,
            )
        token_key = entity.token()
        token = session.liveliness().declare_token(token_key)
        self._declared[key] = _Declared(
            entity, token, entity_gid(token_key), handle, latched=qos.transient_local
        )
        self.stats["declared_total"] += 1
        if kind == "MP" and qos.transient_local:
            self._prime_latched(name)

    def _prime_latched(self, name: str) -> None:
        """Put a latched topic's last message into the new publisher's cache."""
        topic = self.graph.topics.topics.get(name)
        if topic is not None and topic.latched is not None:
            entry = self._declared.get(("MP", self._first_owner(topic), name))
            if entry is not None:
                self.stats["published"] += self._put(entry, topic.latched)

    def _first_owner(self, topic: Topic) -> str:
        for owner in topic.publishers:
            node = local_owner(owner)
            if node is not None:
                return node
        return ""

    def _undeclare(self, entry: _Declared) -> None:
        if entry.handle is not None:
            _quietly(entry.handle.undeclare)
        _quietly(entry.token.undeclare)

    def on_deliver(self, topic: Topic, out: Outgoing, source: Peer | None) -> None:
        """Tap on every delivery in the graph: forward it to ROS 2 subscribers."""
        if self._forwarding or isinstance(source, _Provider | _Caller):
            return
        entry = self._publishers.get(topic.name)
        if entry is None or not (entry.latched or self._remote_subs[topic.name]):
            return
        loop = self._loop
        if loop is None:
            self.stats["published"] += self._put(entry, out)
            return
        # sent together once the current callback (a tick publishes every robot) is done:
        # Zenoh's puts cost half as much back to back as spread between other work
        if not self._outbox:
            loop.call_soon(self._flush)
        self._outbox.append((entry, out))

    def flush_early(self) -> None:
        """Put what is held back before the end of the callback, if that is a large burst.

        The graph says so when it has more to compute (a step's /odom before its scans are
        cast): 300 robots' /odom then leave a few milliseconds earlier. A small burst waits for
        the rest: two bursts of puts a tick cost more than one, the first put after other work
        being the dearest (bench.zenoh outward, 30 robots, two alternating runs each: median
        ratio 1.31x and 1.32x flushed early, 1.17x and 1.18x not).
        """
        if len(self._outbox) >= EARLY_FLUSH:
            self._flush()

    def _flush(self) -> None:
        """Put what :meth:`on_deliver` held back (at the end of the callback, or earlier)."""
        if not self._outbox:
            return
        outbox, self._outbox = self._outbox, []
        if self.session is None:
            return
        # every payload first, then the puts back to back: each part runs warm, and Zenoh's
        # transmit thread finds the tick's samples together (bench.zenoh outward's ROS 2 phase:
        # 21 -> 15 us a message on the loop, Zenoh's tx thread 0.8 -> 0.3 % of a core)
        ready = []
        for entry, out in outbox:
            payload = self._payload(entry, out)
            if payload is not None:
                ready.append((entry, payload))
        sent = 0
        for entry, payload in ready:
            sent += self._put_bytes(entry, payload)
        self.stats["published"] += sent

    def _put(self, entry: _Declared, out: Outgoing) -> bool:
        """Publish a delivery on a declared publisher; return whether it went out."""
        payload = self._payload(entry, out)
        return payload is not None and self._put_bytes(entry, payload)

    def _payload(self, entry: _Declared, out: Outgoing) -> bytes | None:
        """Return the CDR bytes of a delivery (shared with ``cbor-raw``), None if it has none."""
        try:
            payload = out.cdr() if out.cdr is not None else None
            if payload is None:
                payload = self.cdr.serialize(entry.entity.type, out.msg)
        except Exception as err:  # a message the CDR writer cannot encode: skip, say so once
            self._log(f"cdr {entry.entity.name}", f"Zenoh: {entry.entity.name} not sent: {err}")
            return None
        return payload

    def _put_bytes(self, entry: _Declared, payload: bytes, *, count: bool = False) -> bool:
        """Publish CDR bytes on a declared publisher, with rmw_zenoh's attachment.

        Returns whether it went out; ``count``: add it to the ``published`` counter here (the
        tick's puts are counted together by :meth:`_flush`).
        """
        attachment = pack_attachment(next(entry.sequence), time.time_ns(), entry.gid)
        try:
            entry.handle.put(payload, attachment=attachment)
        except Exception as err:
            self._log(f"put {entry.entity.name}", f"Zenoh: put on {entry.entity.name}: {err}")
            return False
        if count:
            self.stats["published"] += 1
        return True

    # -- calls from ROS 2 ---------------------------------------------------------------------

    def _query_handler(self, name: str, type_name: str) -> Callable[[Any], None]:
        def on_query(query: Any) -> None:  # a Zenoh thread
            self.hand_over_call(name, type_name, query)

        return on_query

    def hand_over_call(self, name: str, type_name: str, query: Any) -> None:
        """Queue a call from ROS 2 for the event loop, or refuse it here (Zenoh's threads).

        A request over ``zenoh_max_sample_bytes``, or past :data:`CALL_INBOX_LIMIT` calls or
        ``zenoh_inbox_bytes`` bytes waiting, gets an error reply at once (``calls_refused``).
        """
        loop = self._loop
        if loop is None:
            return
        payload = query.payload
        size = len(payload) if payload is not None else 0
        refusal = None
        with self.inbox.lock:
            if size > self.max_sample:
                refusal = (
                    f"service {name}: request of {size} bytes over zenoh_max_sample_bytes "
                    f"({self.max_sample})"
                )
            elif (
                len(self._call_inbox) >= CALL_INBOX_LIMIT
                or self._calls_bytes + size > self.max_inbox
            ):
                refusal = (
                    f"service {name}: refused, too many calls waiting (over {CALL_INBOX_LIMIT} "
                    f"calls or zenoh_inbox_bytes {self.max_inbox})"
                )
            else:
                self._call_inbox.append((name, type_name, query, size))
                self._calls_bytes += size
            if refusal is not None:
                self.stats["calls_refused"] += 1
                ring = False
            else:
                ring = not self._calls_rung
                self._calls_rung = True  # one wake-up of the event loop per burst
        if refusal is not None:
            try:
                query.reply_err(refusal.encode())
            except Exception as err:
                logger.debug("reply_err: %s", err)
            finally:
                _quietly(query.drop)
        elif ring:
            loop.call_soon_threadsafe(self._drain_calls)

    def _drain_calls(self) -> None:
        """Take the calls from ROS 2 that arrived, :data:`DRAIN_BATCH` per callback at most."""
        calls = self._call_inbox
        for _ in range(DRAIN_BATCH):
            with self.inbox.lock:
                if not calls:
                    break
                name, type_name, query, size = calls.popleft()
                self._calls_bytes -= size
            try:
                self._on_query(name, type_name, query)
            except Exception:  # one call's fault stops neither the drain nor the others
                logger.exception("Zenoh: a call on %s", name)
        with self.inbox.lock:
            again = bool(calls) and self._loop is not None
            self._calls_rung = again
        if again:
            self._loop.call_soon(self._drain_calls)  # type: ignore[union-attr]

    def _on_query(self, name: str, type_name: str, query: Any) -> None:
        """A call from ROS 2: CDR decoded to the request, the graph's service called with it.

        Refused (an error reply) when the ROS 2 peers' role may not reach the service
        (administrative services, other robots' services: the graph's access rules), when the
        service is gone or changed its type, when the request is not CDR of its type, or when
        ``max_pending_calls`` calls from ROS 2 wait for providers outside this process.
        """
        self.stats["calls_in"] += 1
        try:
            raw = query.attachment
            attachment = Attachment.unpack(bytes(raw.to_bytes()) if raw is not None else b"")
        except ValueError as err:
            self._fail_query(query, f"service {name}: request without a valid attachment ({err})")
            return
        if self.actions.handles(name):
            self.actions.on_query(name, type_name, query, attachment)
            return
        refusal = self.graph.access.reach_refusal(self._caller.access, name)
        if refusal is not None:
            logger.info("%s: service %s", self._caller.label, refusal)
            self._fail_query(query, f"service {refusal}")
            return
        service = self.graph.services.services.get(name)
        if service is None or service.type != type_name:
            self._fail_query(query, f"Service {name} of type {type_name} does not exist")
            return
        try:
            request_type, response_type = self.graph.registry.service(type_name)
            payload = bytes(query.payload.to_bytes()) if query.payload is not None else b""
            request = self._decode(request_type, payload)  # the canonical request, complete
        except Exception as err:  # whatever the network sent: reported, never raised
            self._fail_query(query, f"service {name}: request is not CDR of {type_name}: {err}")
            return
        waits = service.handler is None
        if waits and self.calls_waiting >= self.max_calls_waiting:
            self._fail_query(
                query,
                f"service {name}: refused, ROS 2 peers already wait for {self.max_calls_waiting}"
                " answers (the server's max_pending_calls); wait for them first",
            )
            return

        def done(ok: bool, values: Any) -> None:
            self._service_answer(name, query, response_type, attachment, ok, values)

        timeout = min(SERVICE_TIMEOUT, self.settings.max_call_timeout)
        deadline = asyncio.get_running_loop().time() + timeout
        if waits:
            self.calls_waiting += 1
        release = self._call_ended if waits else None
        self.graph.services.call(self._caller, service, request, deadline, done, release=release)

    def _call_ended(self) -> None:
        self.calls_waiting -= 1

    def _service_answer(
        self,
        name: str,
        query: Any,
        response_type: str,
        attachment: Attachment,
        ok: bool,
        values: Any,
    ) -> None:
        """The graph answered a call from ROS 2: reply to the query (CDR of the response)."""
        if not ok:
            self._fail_query(query, str(values))
        else:
            try:
                # complete and checked: an in-process handler may leave fields to their defaults
                msg = self.graph.converter.from_json(response_type, values)
            except SimbridgeError as err:
                self._fail_query(query, f"response does not fit {response_type}: {err}")
            else:
                self._reply(query, response_type, msg, attachment)
        if split_action(name) is not None:
            self.actions.cancelled(name)

    def _reply(self, query: Any, response_type: str, msg: Any, attachment: Attachment) -> None:
        """Reply to a query from ROS 2 with a response message (echoing sequence and GID)."""
        try:
            payload = self.cdr.serialize(response_type, msg)
        except SimbridgeError as err:
            self._fail_query(query, f"response does not fit {response_type}: {err}")
            return
        reply = Attachment(attachment.sequence, time.time_ns(), attachment.gid).pack()
        try:
            query.reply(query.key_expr, payload, attachment=reply)
        except Exception as err:
            self._log("reply", f"Zenoh: reply on {query.key_expr}: {err}")
        finally:
            _quietly(query.drop)

    def _fail_query(self, query: Any, text: str) -> None:
        self.stats["calls_failed"] += 1
        self._log(f"query {text[:40]}", f"Zenoh: a ROS 2 call failed: {text}")
        try:
            query.reply_err(text.encode())
        except Exception as err:
            logger.debug("reply_err: %s", err)
        finally:
            _quietly(query.drop)

    # -- inward ----------------------------------------------------------------------------

    def _on_token(self, sample: Any) -> None:  # a Zenoh thread
        put = sample.kind == self.zenoh.SampleKind.PUT
        with self.inbox.lock:
            self._tokens.append((str(sample.key_expr), put))
            ring = not self._tokens_rung
            self._tokens_rung = True  # one wake-up of the event loop per burst
        loop = self._loop
        if ring and loop is not None:
            loop.call_soon_threadsafe(self._drain_tokens)

    def _drain_tokens(self) -> None:
        """Apply the token changes that arrived to the graph, :data:`TOKEN_BATCH` at a time.

        In callbacks of their own, not the tick: a flood of 17,000 tokens had held the loop at
        7 Hz for 50 s when every change rebuilt the whole import inside the tick (issue 29).
        Each batch changes only the names its tokens touch (:meth:`_import_names`).
        """
        tokens = self._tokens
        batch = []
        with self.inbox.lock:
            for _ in range(min(len(tokens), TOKEN_BATCH)):
                batch.append(tokens.popleft())
        names: set[str] = set()
        nodes: set[str] = set()
        actions = False
        for token, alive in batch:
            entity = self._token_changed(token, alive)
            if entity is None:
                continue
            if entity.kind == "NN":
                nodes.add(entity.node_fqn)
            elif split_action(entity.name) is not None:
                actions = True
            else:
                names.add(entity.name)
        if (names or nodes or actions) and self.session is not None:
            # what only the tokens changed is done here: the tick's comparison of the graph
            # with Zenoh (its change counters) is not started by it, unless it may change
            # what is declared outward: a client subscribed to one of these topics (its
            # subscription's token follows the topic), or an action came or went
            quiet = self._signature() == self._generation and not actions
            clients = self._clients_on(names)
            if actions:
                self.actions.import_remote(self._allowed_action_parts())
            self._import_names(names, nodes)
            self._update_subscribers(names)
            if quiet and not (clients or self._clients_on(names)):
                self._generation = self._signature()
        with self.inbox.lock:
            again = bool(tokens) and self._loop is not None
            self._tokens_rung = again
        if again:
            self._loop.call_soon(self._drain_tokens)  # type: ignore[union-attr]

    def _clients_on(self, names: Iterable[str]) -> bool:
        """Whether a rosbridge client subscribes to one of these topics."""
        table = self.graph.topics.topics
        return any((t := table.get(n)) is not None and t.sinks for n in names)

    def _token_changed(self, token: str, alive: bool) -> Entity | None:
        """Record a remote token that appeared or went; return its entity if that changed."""
        try:
            entity = Entity.parse(token)
        except ValueError as err:
            self._log("token", f"Zenoh: ignoring a graph token: {err}")
            return None
        if entity.zid == self.zid:
            return None
        if alive:
            if token in self._remote:
                return None
            if len(self._remote) >= self.max_tokens:
                self.stats["tokens_refused"] += 1
                self._log(
                    "tokens",
                    f"Zenoh: a token of {entity.node_fqn} (session {entity.zid}) ignored: "
                    f"{self.max_tokens} remote tokens kept already (zenoh_max_remote_tokens)",
                )
                return None
            self._remote[token] = entity
            self._index(token, entity, alive)
        else:
            if self._remote.pop(token, None) is None:
                return None
            self._index(token, entity, alive)
        if entity.kind == "NN" and entity.node_fqn in _SIMULATOR_NODES:
            nodes = self._sim_nodes.setdefault(entity.zid, set())
            if alive:
                nodes.add(token)
            else:
                nodes.discard(token)
                if not nodes:
                    del self._sim_nodes[entity.zid]
            self._update_share()
        return entity

    def _index(self, token: str, entity: Entity, alive: bool) -> None:
        """Keep the remote entities by name (topics, services), node and action."""
        if entity.kind == "NN":
            if alive:
                self._remote_node_tokens[entity.node_fqn] += 1
            else:
                self._remote_node_tokens[entity.node_fqn] -= 1
                if self._remote_node_tokens[entity.node_fqn] <= 0:
                    del self._remote_node_tokens[entity.node_fqn]
            return
        if split_action(entity.name) is not None:
            if alive:
                self._action_parts[token] = entity
            else:
                self._action_parts.pop(token, None)
            return
        if entity.kind == "MS":
            self._remote_subs[entity.name] += 1 if alive else -1
            if self._remote_subs[entity.name] <= 0:
                del self._remote_subs[entity.name]
        by_name = self._by_name.setdefault(entity.name, {})
        if alive:
            by_name[token] = entity
        else:
            by_name.pop(token, None)
            if not by_name:
                del self._by_name[entity.name]

    def _update_share(self) -> None:
        """Recompute :attr:`tick_share`: this process's rank among the simulators, by zid.

        The simulators of one classroom take turns in the step period: on one machine their
        ticks would otherwise fall together about a third of the time, and every front-end then
        got both bursts at once (``bench.zenoh classroom``, 2 x 300 robots: latency p99 97 ms
        with the two ticks 3 ms apart, 43-52 ms with them 11-19 ms apart). A simulator is a
        session with both a ``/virtual_robot`` and a ``/sim`` node (the tokens of
        ``--no-sim`` processes and of other ROS 2 nodes do not count).
        """
        others = {
            zid
            for zid, tokens in self._sim_nodes.items()
            if {Entity.parse(t).node_fqn for t in tokens} >= _SIMULATOR_NODES
        }
        if not self.zid or not self.simulator or not others:
            self.tick_share = None
            return
        everyone = sorted({*others, self.zid})
        self.tick_share = (everyone.index(self.zid), len(everyone))

    def _allowed_action_parts(self) -> list[Entity]:
        return [
            e
            for e in self._action_parts.values()
            if not self._refused(e.name, f"{e.node_fqn} (session {e.zid}):", count=False)
        ]

    def _import_remote(self) -> None:
        """Make the graph hold exactly the remote publishers and services the tokens show."""
        self.actions.import_remote(self._allowed_action_parts())
        names = {*self._by_name, *self.imports.by_topic, *self.stand_ins.by_topic, *self._providers}
        self._import_names(names, {*self._remote_node_tokens, *self._remote_nodes})

    def _import_names(self, names: Iterable[str], nodes: Iterable[str]) -> None:
        """Bring the graph in line with the tokens of these topic and service names and nodes."""
        for node in nodes:
            self._import_node(node)
        for name in names:
            entities = self._by_name.get(name, {}).values()
            self._import_subscriptions(name, entities)
            self._import_publishers(name, entities)
            self._import_service(name, entities)

    def _import_publishers(self, name: str, entities: Iterable[Entity]) -> None:
        pubs = {
            RemoteNode(e.node_fqn, e.zid): (e.type, e.qos.transient_local)
            for e in entities
            if e.kind == "MP"
        }
        self.imports.update(name, pubs)

    def _local_clash(self, name: str, node: ForeignNode, local: str) -> None:
        self._note(
            f"clash {name}",
            f"Zenoh: {name} of {node} (session {node.origin}) not bridged: {local} here "
            "publishes it already (robot names must be unique across the classroom)",
        )

    def _import_service(self, name: str, entities: Iterable[Entity]) -> None:
        registry = self.graph.registry
        entity = next((e for e in entities if e.kind == "SS"), None)
        if entity is not None and self._refused(
            name, f"{entity.node_fqn} (session {entity.zid}):", count=False
        ):
            entity = None  # the ROS 2 peers' role may not provide it here
        if entity is None:
            provider = self._providers.pop(name, None)
            if provider is not None:
                self.graph.services.withdraw(provider, name)  # fails its pending calls
            return
        if name in self._providers:
            return
        existing = self.graph.services.services.get(name)
        if existing is not None:
            self._note(
                f"clash {name}",
                f"Zenoh: service {name} of {entity.node_fqn} (session {entity.zid}) not "
                f"bridged: {existing.node} here provides it already",
            )
            return
        if entity.type not in registry.services:
            self._log(
                f"type {entity.type}",
                f"Zenoh: service {name} has type {entity.type}, unknown here: not bridged",
            )
            self.stats["unknown_types"] += 1
            return
        provider = _Provider(self, Access(peer_id=self.graph.next_peer_id()), entity)

        def lost(name: str) -> None:  # a rosbridge client advertised the name since
            if self._providers.get(name) is provider:
                del self._providers[name]

        self.graph.services.provide(
            provider, name, entity.type, provider.forward, lost=lost, node=entity.node_fqn
        )
        self._providers[name] = provider

    def _import_node(self, name: str) -> None:
        """List a node of other processes in the graph (rosapi) while it has tokens."""
        nodes = self.graph.nodes
        if name not in self._remote_node_tokens:
            if name in self._remote_nodes:
                self._remote_nodes.discard(name)
                nodes.pop(name, None)
        elif name not in self._remote_nodes and name not in nodes:
            nodes[name] = "a ROS 2 node (Zenoh)"
            self._remote_nodes.add(name)

    def _import_subscriptions(self, name: str, entities: Iterable[Entity]) -> None:
        subs = {RemoteNode(e.node_fqn, e.zid): e.type for e in entities if e.kind == "MS"}
        self.stand_ins.update(name, subs)

    def _update_subscribers(self, only: Collection[str] | None = None) -> None:
        """Subscribe to remote data exactly while something here listens to it.

        ``only``: for these topic names alone (those whose tokens changed).

        On the exact key expression of each remote publisher (its type hash included, from its
        token): a Humble publisher feeds a Jazzy simbridge and vice versa. Not on a wildcard
        (``.../TYPE/*``): Zenoh matched every incoming sample against every wildcard subscriber
        of the session, 88 us of CPU a sample with 600 of them against 9 us with exact keys
        (12,000 samples/s). An in-process node also subscribes at once to the key of this
        process's distribution, as an rmw_zenoh subscription does (no message lost while
        discovery runs). Latched topics keep one advanced subscriber on the wildcard.
        """
        wanted: dict[str, tuple[str, bool, bool]] = {}
        remote = self.imports.by_topic
        table = self.graph.topics.topics
        for name in table if only is None else [n for n in only if n in table]:
            topic = table[name]
            if topic.type is None or not topic.known:
                continue
            if self.refusal(name) is not None:
                continue  # ROS 2 may not publish it here: its samples are not even asked for
            # a rosbridge client's subscription only while ROS 2 publishes the topic
            local = any(id(cb) not in self.stand_ins.ids for _n, cb in topic.internal)
            if local or (topic.sinks and name in remote):
                wanted[name] = (topic.type, topic.latch, local)
        published: dict[str, set[str]] = {}
        for name in wanted:
            for entity in self._by_name.get(name, {}).values():
                if entity.kind == "MP":
                    with contextlib.suppress(ValueError):
                        published.setdefault(name, set()).add(entity.keyexpr())
        keys: dict[str, set[str]] = {}
        for name, (type_name, latched, local) in wanted.items():
            try:
                dds = dds_type(type_name)
                if latched:
                    keys[name] = {f"{self.options.domain}/{name.strip('/')}/{dds}/*"}
                    continue
                keys[name] = set(published.get(name, ()))
                if local:
                    own = self.hasher.message(type_name)
                    keys[name].add(topic_keyexpr(self.options.domain, name, dds, own))
            except (SimbridgeError, ValueError) as err:
                self._log(f"sub {name}", f"Zenoh: cannot subscribe to {name}: {err}")
        channels = dict(self._channels)
        mine = self._subscribers
        for name in list(mine) if only is None else [n for n in only if n in mine]:
            subs = self._subscribers[name]
            for key in [k for k in subs if k not in keys.get(name, ())]:
                _quietly(subs.pop(key).undeclare)
                channels.pop((name, key), None)
                self._callback_keys.discard((name, key))
            if not subs:
                del self._subscribers[name]
        for name, wanted_keys in keys.items():
            latched = wanted[name][1]
            subs = self._subscribers.setdefault(name, {})
            for keyexpr in sorted(wanted_keys - subs.keys()):
                try:
                    if latched:
                        ext = importlib.import_module("zenoh.ext")
                        sub = ext.declare_advanced_subscriber(
                            self.session,
                            keyexpr,
                            self._sample_handler(name),
                            allowed_origin=self.zenoh.Locality.REMOTE,
                            history=ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                        )
                    elif len(self._callback_keys) < CALLBACK_KEYS:
                        sub = self.session.declare_subscriber(
                            keyexpr,
                            self._sample_handler(name),
                            allowed_origin=self.zenoh.Locality.REMOTE,
                        )
                        self._callback_keys.add((name, keyexpr))
                    else:
                        sub = self.session.declare_subscriber(
                            keyexpr,
                            self.zenoh.handlers.RingChannel(RING),
                            allowed_origin=self.zenoh.Locality.REMOTE,
                        )
                        channels[(name, keyexpr)] = sub.handler
                except Exception as err:
                    self._log(f"sub {name}", f"Zenoh: cannot subscribe to {name}: {err}")
                    continue
                subs[keyexpr] = sub
            if not subs:
                del self._subscribers[name]
        if channels != self._channels:
            self._set_channels(channels)

    def _set_channels(self, channels: dict[tuple[str, str], Any]) -> None:
        """Poll these ring channels from now on (none: stop polling)."""
        self._channels = channels
        self._channel_list = [(name, handler) for (name, _key), handler in channels.items()]
        self._poll_next = 0
        if not channels and self._poll_handle is not None:
            self._poll_handle.cancel()
            self._poll_handle = None
        elif channels and self._poll_handle is None and self._loop is not None:
            self._poll_handle = self._loop.call_soon(self._poll)

    def poll_period(self, now: float) -> float:
        """Seconds to the next poll of the ring channels while samples arrive.

        A period that grows with the number of channels (see :data:`POLL_PER_CHANNEL`); after
        :data:`IDLE_AFTER` seconds without a sample the tick polls instead (:meth:`_poll`).
        """
        return min(POLL_MAX, max(POLL_MIN, len(self._channel_list) * POLL_PER_CHANNEL))

    def _poll(self) -> None:
        """Hand the samples waiting in the ring channels to the graph (the event loop).

        Polling instead of one Python callback per sample: each callback ran on a thread of its
        subscriber that took the GIL from the event loop, 54 us of CPU a sample with 300
        subscribers against 12 us polled (measured with 6,000 samples/s). At most
        :data:`POLL_BATCH` samples per callback: the frames they made are written before the
        next batch (see :data:`POLL_BATCH`), the loop's other work (clients, the tick) runs in
        between, and the next batch goes on from the next channel (a flood is shared out).
        """
        self._poll_handle = None
        loop = self._loop
        channels = self._channel_list
        if loop is None or self.session is None or not channels:
            return
        k = self._poll_next % len(channels)
        budget = POLL_BATCH
        room = DRAIN_BYTES
        for name, handler in channels[k:] + channels[:k] if k else channels:
            k += 1
            sample = handler.try_recv()
            while sample is not None:
                payload = sample.payload
                size = len(payload)
                if size > self.max_sample:
                    self.inbox.oversized(name, size)
                else:
                    self._on_sample(name, bytes(payload.to_bytes()))
                    room -= size
                budget -= 1
                if not budget or room <= 0:
                    break
                sample = handler.try_recv()
            if not budget or room <= 0:
                budget = 0
                break
        self._poll_next = k
        now = loop.time()
        if budget < POLL_BATCH:
            self._last_sample = now
        if self._poll_handle is not None or self._loop is None or not self._channel_list:
            return  # closed, or the channels changed meanwhile and their poll is scheduled
        if budget:
            if now - self._last_sample >= IDLE_AFTER:
                return  # a silence: the tick polls from now on, without a wake-up of its own
            self._poll_handle = loop.call_later(self.poll_period(now), self._poll)
        else:
            self._poll_handle = loop.call_soon(self._poll)

    def _sample_handler(self, name: str) -> Callable[[Any], None]:
        def on_sample(sample: Any) -> None:  # a Zenoh thread: as little as it can
            self.hand_over(self._on_sample, name, sample.payload)

        return on_sample

    def hand_over(self, take: Take, name: str, payload: Any) -> None:
        """Queue a sample's payload (Zenoh bytes) for ``take(name, bytes)`` on the event loop.

        Called on Zenoh's threads. A payload over ``zenoh_max_sample_bytes`` is dropped before
        it is copied (counted, reported once per ``LOG_EVERY``); past the inbox's bounds
        (``INBOX_LIMIT`` samples, ``zenoh_inbox_bytes``), the oldest go (counted: the loop is
        overloaded).
        """
        size = len(payload)
        if size > self.max_sample:
            self.inbox.oversized(name, size)
            return
        self.inbox.put(take, name, bytes(payload.to_bytes()))

    def _on_sample(self, name: str, payload: bytes) -> None:
        topic = self.graph.topics.topics.get(name)
        if topic is None or topic.type is None or self.session is None:
            return
        # (names allowed are kept as None: one look-up on the way of every sample)
        if self.refusals.cache.get(name, "") is not None and self._refused(name, "a sample on"):
            return
        self.stats["received"] += 1
        try:
            msg = self._decode(topic.type, payload)
        except Exception as err:  # whatever the network sent: reported, never raised
            self.stats["bad_payloads"] += 1
            self._log(f"bad {name}", f"Zenoh: {name}: payload is not CDR of {topic.type}: {err}")
            return
        out = self.graph.topics.outgoing(topic, msg, self.graph.stamp())
        out.cdr = lambda: payload
        loop = self._loop
        now = loop.time() if loop is not None else 0.0
        self._forwarding = True
        try:
            self.graph.topics.deliver(topic, out, now, None)
        except SimbridgeError as err:
            self._log(f"refused {name}", f"Zenoh: {name}: refused here: {err}")
        finally:
            self._forwarding = False

    def _decode(self, type_name: str, payload: bytes) -> Any:
        """Return the canonical message of CDR bytes (raises whatever rosbags raises)."""
        return self.reader.read(type_name, payload)

    # -- calls to ROS 2 ---------------------------------------------------------------------

    def _remote_call(self, provider: _Provider, call: PendingCall, request: Any) -> None:
        """The graph forwards a call to a remote service: its request goes out as CDR."""
        entity = provider.entity
        services = self.graph.services
        try:
            request_type, response_type = self.graph.registry.service(entity.type)
            payload = self.cdr.serialize(request_type, request)
        except Exception as err:  # a request the caller's front end did not complete
            services.respond(call, f"request does not fit {entity.type}: {err!r}", ok=False)
            return
        attachment = self.client_attachment(entity, next(self._call_ids))
        self._calls[call.id] = (provider, response_type, call)

        def done(replies: list[tuple[bool, bytes]]) -> None:
            self._remote_done(call.id, replies)

        try:
            self._query(entity, payload, attachment, SERVICE_TIMEOUT, done)
        except Exception as err:
            self._calls.pop(call.id, None)
            services.respond(call, f"query failed: {err}", ok=False)

    def client_attachment(self, entity: Entity, sequence: int) -> bytes:
        """Return the attachment of this process's ``sequence``-th request to ``entity``."""
        gid = entity_gid(f"client:{self.zid}:{entity.name}")
        return Attachment(sequence, time.time_ns(), gid).pack()

    def _query(
        self,
        entity: Entity,
        payload: bytes,
        attachment: bytes,
        timeout: float,
        done: Callable[[list[tuple[bool, bytes]]], None],
    ) -> None:
        """Query every server of a remote service; ``done(replies)`` once all have answered.

        ``replies`` are ``(ok, payload bytes)`` as they came, gathered on Zenoh's threads;
        ``done`` runs on the event loop. What Zenoh raises (no session, a bad key) reaches the
        caller.
        """
        replies: list[tuple[bool, bytes]] = []

        def on_reply(reply: Any) -> None:  # a Zenoh thread
            if reply.ok is not None:
                replies.append((True, bytes(reply.ok.payload.to_bytes())))
            else:
                replies.append((False, bytes(reply.err.payload.to_bytes())))

        def on_done() -> None:  # a Zenoh thread
            loop = self._loop
            if loop is not None:
                loop.call_soon_threadsafe(done, replies)

        self.stats["calls_out"] += 1
        self.session.get(
            entity.keyexpr(),
            self.zenoh.handlers.Callback(on_reply, on_done),
            target=self.zenoh.QueryTarget.ALL_COMPLETE,
            consolidation=self.zenoh.ConsolidationMode.NONE,
            payload=payload,
            attachment=attachment,
            timeout=timeout,
        )

    def _remote_done(self, call_id: str, replies: list[tuple[bool, bytes]]) -> None:
        """A remote service replied (or its query ended): the canonical response to the call."""
        pending = self._calls.pop(call_id, None)
        if pending is None:
            return
        provider, response_type, call = pending
        respond = self.graph.services.respond
        if not replies:
            text = f"service {provider.entity.name} gave no reply (its node may have gone)"
            respond(call, text, ok=False)
            return
        ok, payload = replies[0]
        if not ok:
            respond(
                call, payload.decode(errors="replace") or "the service reported an error", ok=False
            )
            return
        try:
            values = self._decode(response_type, payload)
        except Exception as err:  # whatever the network sent: reported, never raised
            self.stats["bad_payloads"] += 1
            respond(call, f"reply is not CDR of {response_type}: {err}", ok=False)
            return
        respond(call, values, ok=True)

    def _remote_robot(self, name: str) -> Entity | None:
        """Return the remote publisher of ``/<name>/odom`` (a robot of another process)."""
        topic = f"/{name}/odom"
        return next((e for e in self._remote.values() if e.kind == "MP" and e.name == topic), None)

    def simulator_of(self, name: str) -> str | None:
        """Return which process of the classroom simulates robot ``name``, or None.

        One end of the robot world's ``Elsewhere`` (the fleet refuses to spawn that name).
        """
        other = self._remote_robot(name)
        return None if other is None else f"{other.node_fqn}, Zenoh session {other.zid}"

    def robots(self) -> list[str]:
        """Return the robots other processes of the classroom simulate (``/NAME/odom``).

        The other end of the robot world's ``Elsewhere`` (the pages' robot picker lists them).
        """
        names = set()
        for entity in self._remote.values():
            parts = entity.name.split("/")
            if (
                entity.kind == "MP"
                and len(parts) == 3
                and parts[2] == "odom"
                and entity.type == "nav_msgs/msg/Odometry"
            ):
                names.add(parts[1])
        return sorted(names)

    # -- access ------------------------------------------------------------------------------

    def refusal(self, name: str) -> str | None:
        """Return why ROS 2 peers may not publish on (or provide) ``name``; None if they may.

        Samples of a refused name are never subscribed to (and dropped if they come); remote
        publishers, services and actions under it are not brought into the graph.
        """
        return self.refusals.refusal(name)

    # -- what the action bridge uses (ActionLink of simbridge.ros2.zenoh.actions) -------------

    @property
    def peer(self) -> Peer:
        """The ROS 2 side as one peer of the graph (its access is the ROS 2 peers' role)."""
        return self._caller

    def now(self) -> float:
        """Return the event loop's monotonic time (the graph's ``now``), 0 before the start."""
        return self._loop.time() if self._loop is not None else 0.0

    def decode(self, type_name: str, payload: bytes) -> Any:
        """Return the canonical message of CDR bytes (raises whatever the reader raises)."""
        return self._decode(type_name, payload)

    def reply(self, query: Any, response_type: str, msg: Any, attachment: Attachment) -> None:
        """Reply to a query from ROS 2 with a canonical response message."""
        self._reply(query, response_type, msg, attachment)

    def fail(self, query: Any, text: str) -> None:
        """Reply to a query from ROS 2 with an error."""
        self._fail_query(query, text)

    def publish(self, node: str, name: str, payload: bytes) -> bool:
        """Publish CDR bytes on the publisher of ``name`` declared under ``node``, if any."""
        entry = self._declared.get(("MP", node, name))
        return entry is not None and self._put_bytes(entry, payload, count=True)

    def subscribe(
        self, name: str, type_name: str, take: Callable[[bytes], None]
    ) -> Callable[[], None] | None:
        """Subscribe to the remote publishers of ``name``; return the undeclare (None: failed).

        Samples reach ``take`` on the event loop through :meth:`hand_over` (its budgets).
        """
        keyexpr = f"{self.options.domain}/{name.strip('/')}/{dds_type(type_name)}/*"

        def taken(_name: str, payload: bytes) -> None:
            take(payload)

        def on_sample(sample: Any) -> None:  # a Zenoh thread
            self.hand_over(taken, name, sample.payload)

        try:
            subscriber = self.session.declare_subscriber(
                keyexpr, on_sample, allowed_origin=self.zenoh.Locality.REMOTE
            )
        except Exception as err:
            self._log(f"sub {keyexpr}", f"Zenoh: cannot subscribe to {keyexpr}: {err}")
            return None
        undeclare: Callable[[], None] = subscriber.undeclare
        return undeclare

    def query(
        self,
        entity: Entity,
        request_type: str,
        request: Any,
        timeout: float,
        on_reply: Callable[[bytes], None],
        on_error: Callable[[str], None],
    ) -> None:
        """Send a canonical request to a remote service; call back on the event loop.

        ``on_reply`` gets the first reply's CDR bytes; ``on_error`` why there is none (no
        session, a request its type cannot hold, an error reply, no reply in time, a reply
        ``on_reply`` could not read).
        """
        if self.session is None:
            on_error(f"{entity.name}: not connected to ROS 2")
            return
        try:
            payload = self.cdr.serialize(request_type, request)
        except SimbridgeError as err:
            on_error(str(err))
            return
        attachment = self.client_attachment(entity, next(self._call_ids))

        def done(replies: list[tuple[bool, bytes]]) -> None:  # the event loop
            if not replies:
                on_error(f"{entity.name} gave no reply (its node may have gone)")
                return
            ok, data = replies[0]
            if not ok:
                on_error(data.decode(errors="replace") or f"{entity.name} reported an error")
                return
            try:
                on_reply(data)
            except Exception as err:  # whatever the network sent: reported, never raised
                self.stats["bad_payloads"] += 1
                on_error(f"{entity.name}: reply is not what its type says: {err}")

        try:
            self._query(entity, payload, attachment, timeout, done)
        except Exception as err:
            on_error(f"query failed: {err}")

    def log(self, key: str, text: str) -> None:
        """Log a warning at most once per ``LOG_EVERY`` seconds per ``key``."""
        self._log(key, text)

    def note(self, key: str, text: str) -> None:
        """Count a name clash; log it once."""
        self._note(key, text)


def calm_transmit_threads() -> int:
    """Make this process's Zenoh transmit threads ``SCHED_BATCH``; return how many there are.

    A put hands its sample to the link's transmit thread, which then sends what it finds
    batched. Woken by the first put of a tick's burst, that thread preempted the event loop on
    its core four to six times a tick and sent the burst in as many writes (bench.zenoh
    outward, 30 robots: 110-220 wake-ups a second, 0.5-1.0 % of a core, and as many forced
    switches of the loop). ``SCHED_BATCH`` (Linux: same share of the CPU, no preemption of
    the running thread on wake-up) lets the puts run on; the thread sends on the other core or
    when the loop yields: 25-30 wake-ups a second, 0.3-0.4 % of a core, and the hop's latency
    within its target. Elsewhere, or where the threads cannot be read, nothing is done (0).
    """
    setter = getattr(os, "sched_setscheduler", None)
    if setter is None:
        return 0
    found = 0
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return 0
    for tid in tasks:
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                if not f.read().startswith(TX_THREADS):
                    continue
            setter(int(tid), os.SCHED_BATCH, os.sched_param(0))
        except OSError:  # the thread ended meanwhile, or the system refuses
            continue
        found += 1
    return found


def _json(value: Any) -> bytes:
    from simbridge.msgs.message import encode_json

    return encode_json(value)


def _quietly(action: Callable[[], Any]) -> None:
    with contextlib.suppress(Exception):
        action()
