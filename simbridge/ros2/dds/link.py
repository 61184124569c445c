"""simbridge on the ROS 2 graph through DDS, as a ROS 2 node on Fast DDS or Cyclone DDS.

:class:`DdsLink` keeps one Cyclone DDS participant beside the graph and maps both ways:

* **outward**: every topic an in-process node (``/virtual_robot``, ``/sim``, ...) or a
  rosbridge client (as ``/rosbridge_websocket``) publishes gets a DDS writer on ``rt/<name>``
  with the ROS type's DDS name; every topic they subscribe to a reader. Writers are reliable
  (so both reliable and best-effort readers match), volatile with depth 10, or transient-local
  with depth 1 for latched topics (``/tf_static``, ``/walls``). The bytes written are the
  message's CDR, made once and shared with ``cbor-raw`` and Zenoh. The participant carries
  ``enclave=/;``, each endpoint from Iron on its ``typehash=``; the nodes and their endpoints
  go out on ``ros_discovery_info``;
* **inward**: writers and readers of other participants (from DDS discovery) on ``rt/``
  topics of a type the registry knows join the graph while they exist, under the node that
  ``ros_discovery_info`` names (``_NODE_NAME_UNKNOWN_`` without it), so rosapi lists them and
  rosbridge clients subscribe and publish.

Cyclone's threads run the data listeners: they only take the samples' bytes and hand them to
the event loop through a bounded inbox (samples and bytes), dropping and counting past it.
Discovery is read on the event loop at each reconcile: every 0.5 s at most, when discovery
delivered something or the graph's tables changed, and every 30 s whatever happened.
Whatever comes from DDS passes the graph's admission as one client of the ROS 2 peers' role
(``--ros2-role``). Bad input (a payload that is not CDR of its type, an unknown type, a name
that clashes, a participant that vanishes) becomes a counter and a rate-limited log line,
never an exception in the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

from simbridge.app.settings import ServerSettings
from simbridge.errors import ConfigError, SimbridgeError
from simbridge.graph import Graph, Topic
from simbridge.graph.access import Access
from simbridge.graph.topics import DEFAULT_TOPIC_QOS, LATCHED_TOPIC_QOS, Peer, TopicQos
from simbridge.msgs.cdr import CdrReader, CdrWriter
from simbridge.msgs.message import Outgoing
from simbridge.ros2.dds.options import DdsOptions
from simbridge.ros2.dds.pack import SharedPack
from simbridge.ros2.dds.trace import KINDS, CycloneTrace, RefusedSample
from simbridge.ros2.dds.types import IdlTypes, old_binding
from simbridge.ros2.dds.wire import (
    DISCOVERY_TOPIC,
    DISCOVERY_TYPE,
    ENCLAVE_USER_DATA,
    ParticipantInfo,
    encode_participant_info,
    gid_size,
    node_entities,
    read_participant_info,
    reply_topic,
    request_topic,
    ros_name,
    topic_name,
    typehash_user_data,
)
from simbridge.ros2.link import (
    ForeignNode,
    Imports,
    Inbox,
    Logbook,
    Refusals,
    Ros2Peer,
    StandIns,
    Take,
    graph_signature,
    outward_services,
    outward_topics,
)
from simbridge.ros2.names import dds_type, ros_type
from simbridge.ros2.role import ros2_access
from simbridge.ros2.typehash import TypeHasher


__all__ = ["DdsLink", "DdsNode", "import_cyclonedds"]

logger = logging.getLogger(__name__)

INSTALL_HINT = 'pip install "simbridge[dds]" (in a checkout: pip install ".[dds]")'
#: Seconds between two reads of DDS discovery and comparisons with the graph, at least.
RECONCILE_PERIOD = 0.5
#: Seconds between two reconciles when nothing said it changed (a safety net: the graph's
#: tables count their changes, and discovery's readers say when they have something).
FULL_PERIOD = 30.0
#: Samples a data listener takes from its reader at once.
TAKE_BATCH = 64
#: Discovery samples read per reconcile at most, per built-in topic.
DISCOVERY_BATCH = 2_000
#: What a node of another participant is called in rosapi's node list.
REMOTE_NODE = "a ROS 2 node (DDS)"
#: rmw_dds_common's name for an endpoint no ``ros_discovery_info`` accounts for.
UNKNOWN_NODE = "/_NODE_NAME_UNKNOWN_"
#: The writer history depth of a volatile topic (rclcpp's default profile).
DEPTH = 10
#: Seconds a call from DDS waits for a provider that is not in process (a rosbridge client,
#: a ROS 2 process over Zenoh), capped by ``max_call_timeout``.
SERVICE_TIMEOUT = 10.0
#: Bytes of rmw_cyclonedds's request header, after the CDR header: the client's id (the last
#: 8 bytes of its GUID) and the request's sequence number, both 64-bit.
REQUEST_HEADER = 16
#: Refused samples held for the next reconcile's log lines at most (the others are counted).
REFUSALS_HELD = 100
#: Seconds a refused sample's log line waits for its participant's ros_discovery_info (to name
#: the node) at most.
NAMED_WITHIN = 5.0
#: The entity id of a participant (after its 12-byte GUID prefix).
PARTICIPANT_ENTITY = b"\x00\x00\x01\xc1"


def import_cyclonedds(what: str = "--dds") -> Any:
    """Import the Cyclone DDS binding for ``what`` (the option the user gave).

    Raises:
        ConfigError: it is not installed (the message names ``what`` and the install command).
    """
    try:
        return importlib.import_module("cyclonedds.domain")
    except ImportError:
        msg = f"{what} needs the DDS extra: {INSTALL_HINT}"
        raise ConfigError(msg) from None


class DdsNode(ForeignNode):
    """A node of another DDS participant (``DdsNode(name, guid)``: the participant's GUID)."""

    @property
    def participant(self) -> str:
        """The GUID (hex) of the node's participant."""
        return self.origin


@dataclass(eq=False, slots=True)
class _Endpoint:
    """A writer or reader simbridge made."""

    name: str
    type: str
    node: str
    handle: Any
    gid: bytes
    latched: bool = False
    #: Readers matched (writers only; kept by Cyclone's listener thread).
    matched: int = 0


@dataclass(frozen=True, slots=True)
class _Remote:
    """An endpoint of another participant, from DDS discovery."""

    participant: bytes
    name: str  # the ROS name (``/odom``)
    type: str  # the ROS type (``nav_msgs/msg/Odometry``), or the DDS name if not ROS's
    latched: bool


@dataclass(eq=False, slots=True)
class _Server:
    """A service simbridge serves on DDS: its request reader and reply writer."""

    name: str
    type: str
    node: str
    reader: Any
    writer: Any
    gids: tuple[bytes, bytes]  # reader's, writer's


class _Caller(Ros2Peer):
    """The peer that makes a DDS client's call through the graph's service table."""

    label = "ROS 2 (DDS)"

    def __init__(self, link: DdsLink, access: Access) -> None:
        self.link = link
        #: Who the DDS peers are for the graph's rules (``--ros2-role``).
        self.access = access


class DdsLink:
    """The graph's front end on DDS (see the module's docstring)."""

    def __init__(
        self,
        graph: Graph,
        options: DdsOptions,
        *,
        simulator: bool = False,
        settings: ServerSettings | None = None,
    ) -> None:
        #: The graph mapped onto DDS.
        self.graph = graph
        #: The server's settings (the link's budgets, the ROS 2 peers' role).
        self.settings = settings = settings or ServerSettings()
        #: Counters for /healthz.
        self.stats: Counter[str] = Counter()
        #: Warnings, rate-limited (also on /rosout).
        self.logbook = Logbook(graph, "DDS", "simbridge.dds", self.stats, logger)
        self._log = self.logbook.warn
        #: Domain, distribution, discovery range.
        self.options = options
        #: Whether this process simulates robots (not ``--no-sim``).
        self.simulator = simulator
        self.dds = import_cyclonedds()
        self.cdr = CdrWriter(graph.registry)
        self.reader = CdrReader(graph.registry)
        self.types = IdlTypes(graph.registry)
        self.hasher = TypeHasher(graph.registry, options.distro)  # type: ignore[arg-type]
        self.gid_size = gid_size(options.distro)
        #: "starting", "running", "closed", "failed".
        self.state = "starting"
        self.error: str | None = None
        self.participant: Any = None
        self._domain: Any = None
        self._trace: CycloneTrace | None = None
        #: Samples Cyclone refused, to be said at the next reconcile.
        self._refused_samples: list[tuple[float, RefusedSample]] = []
        #: Lines of Cyclone's log other than refusals, by kind (``KINDS`` kinds at most).
        self._cyclone_kinds: Counter[str] = Counter()
        self.guid = b""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._writers: dict[str, _Endpoint] = {}
        self._readers: dict[str, _Endpoint] = {}
        self._topics: dict[tuple[str, str], Any] = {}  # (DDS name, DDS type) -> Topic
        self._discovery_writer: Any = None
        #: The transmit pack the writers share (None: each writer sends its own samples).
        self._pack: SharedPack | None = None
        self._flush_pending = False
        self._discovery_reader: Any = None
        self._builtin: list[tuple[str, Any]] = []
        self._announced: bytes | None = None
        #: Other participants: GUID -> their ParticipantEntitiesInfo (once they sent one).
        self._participants: set[bytes] = set()
        self._infos: dict[bytes, ParticipantInfo] = {}
        #: Remote endpoints by their GUID, writers and readers.
        self._remote_writers: dict[bytes, _Remote] = {}
        self._remote_readers: dict[bytes, _Remote] = {}
        #: Inward: topic owners added to the graph, remote subscriptions' markers, nodes.
        self._remote_nodes: set[str] = set()
        #: Remote readers, in the graph as in-process subscribers that do nothing.
        self.stand_ins = StandIns(graph, self.logbook)
        # whatever comes from DDS is admitted as one peer of the ROS 2 peers' role
        scope, admin = ros2_access(settings)
        self._access = Access(scope, admin, guarded=True, peer_id=graph.next_peer_id())
        self._caller = _Caller(self, self._access)
        #: Why DDS peers may not publish on a name (None: they may), by name.
        self.refusals = Refusals(graph, self._access, self.logbook)
        self._refused = self.refusals.refused
        self.imports = Imports(graph, self.refusals, self._local_clash, clients_clash=True)
        self._servers: dict[str, _Server] = {}
        #: Calls from DDS waiting for a provider that is not in process, at most
        #: ``max_pending_calls`` (the budget of one rosbridge client: the DDS peers are one).
        self.calls_waiting = 0
        self.max_calls_waiting = settings.max_pending_calls
        self._forwarding = False
        self._next_reconcile = 0.0
        self._next_full = 0.0
        #: The graph's tables as the last reconcile saw them (``graph_signature``).
        self._generation: int | None = None
        #: Set by Cyclone's threads when a discovery reader has samples (read at the next tick).
        self._discovered = True
        self.max_sample = settings.dds_max_sample_bytes
        self.max_inbox = settings.dds_inbox_bytes
        self.max_remote = settings.dds_max_remote_endpoints
        #: Samples from Cyclone's threads waiting for the event loop (past its bounds, new
        #: ones are dropped: ``dropped_inbox``; over ``dds_max_sample_bytes``:
        #: ``dropped_oversized``).
        self.inbox = Inbox(
            self.logbook,
            max_bytes=self.max_inbox,
            max_sample=self.max_sample,
            dropped="dropped_inbox",
            oversized="dropped_oversized",
            setting="dds",
        )

    # -- lifecycle ------------------------------------------------------------------------

    async def start(self) -> None:
        """Join the domain (the participant, ``ros_discovery_info``, discovery readers)."""
        self._loop = self.inbox.loop = asyncio.get_running_loop()
        try:
            self._open()
        except Exception as err:  # Cyclone refuses the configuration or the network
            self.state, self.error = "failed", str(err)
            logger.error("DDS participant could not start: %s", err)
            return
        self.state = "running"
        logger.info(
            "DDS: participant %s, domain %d, ROS 2 %s, discovery %s",
            self.guid.hex(),
            self.options.domain,
            self.options.distro,
            self.options.discovery,
        )
        self.reconcile()

    def _open(self) -> None:
        dds = self.dds
        core = importlib.import_module("cyclonedds.core")
        builtin = importlib.import_module("cyclonedds.builtin")
        # the domain's log comes back through a pipe, not on stderr: the samples Cyclone
        # refuses are said there, one line for many, and so is the rest of what it says
        assert self._loop is not None
        ddsc = importlib.import_module("cyclonedds.internal").load_cyclonedds()
        self._trace = trace = CycloneTrace(self._loop, self._on_cyclone, ddsc)
        try:
            with trace.domain_log():
                # kept: the domain (and its configuration) lives as long as this object
                self._domain = dds.Domain(self.options.domain, self.options.cyclone_config())
        finally:
            trace.opened()
        qos = core.Qos(core.Policy.Userdata(ENCLAVE_USER_DATA))
        self.participant = dds.DomainParticipant(self.options.domain, qos=qos)
        self.guid = self.participant.guid.bytes
        policy = core.Policy
        t = importlib.import_module("cyclonedds.idl.types")
        gid = self.types.named(
            "rmw_dds_common::msg::dds_::Gid_", {"data": t.array[t.uint8, self.gid_size]}
        )
        node = self.types.named(
            "rmw_dds_common::msg::dds_::NodeEntitiesInfo_",
            {
                "node_namespace": t.bounded_str[256],
                "node_name": t.bounded_str[256],
                "reader_gid_seq": t.sequence[gid],
                "writer_gid_seq": t.sequence[gid],
            },
        )
        info = self.types.named(
            DISCOVERY_TYPE, {"gid": gid, "node_entities_info_seq": t.sequence[node]}
        )
        topic = importlib.import_module("cyclonedds.topic").Topic(
            self.participant, DISCOVERY_TOPIC, info
        )
        pub = importlib.import_module("cyclonedds.pub")
        sub = importlib.import_module("cyclonedds.sub")
        self._discovery_writer = pub.DataWriter(
            self.participant,
            topic,
            qos=core.Qos(
                policy.Reliability.Reliable(100_000_000),
                policy.Durability.TransientLocal,
                policy.History.KeepLast(1),
            ),
        )
        # a step's samples go out together, in as few datagrams as they fit (pack.py)
        self._pack = SharedPack.create(self._discovery_writer)
        if self._pack is not None and not self._pack.adopt(self._discovery_writer):
            self._pack.close()
            self._pack = None
        self._discovery_reader = sub.DataReader(
            self.participant,
            topic,
            qos=core.Qos(
                policy.Reliability.Reliable(100_000_000),
                policy.Durability.TransientLocal,
                policy.History.KeepLast(1),
                policy.IgnoreLocal.Participant,
            ),
        )
        # discovery's readers only say that they have something: the loop reads them
        self._discovery_reader.set_listener(core.Listener(on_data_available=self._on_discovered))
        for kind, which in (
            ("participant", builtin.BuiltinTopicDcpsParticipant),
            ("writer", builtin.BuiltinTopicDcpsPublication),
            ("reader", builtin.BuiltinTopicDcpsSubscription),
        ):
            listener = core.Listener(on_data_available=self._on_discovered)
            reader = builtin.BuiltinDataReader(self.participant, which, listener=listener)
            self._builtin.append((kind, reader))

    def _on_discovered(self, _reader: Any) -> None:  # a Cyclone thread
        self._discovered = True

    async def close(self) -> None:
        """Leave the domain (every endpoint goes with the participant)."""
        participant, self.participant = self.participant, None
        self._loop = self.inbox.loop = None  # Cyclone's threads hand nothing more to the loop
        if participant is not None:
            self.state = "closed"
            if self._pack is not None:
                # each writer its own pack back first: deleting a writer frees the pack it holds
                self._pack.close()
                self._pack = None
            self._writers.clear()
            self._readers.clear()
            self._servers.clear()
            self._builtin.clear()
            self._topics.clear()
            self._discovery_writer = self._discovery_reader = None
            # deleting the participant deletes its entities and waits for its listeners
            with contextlib.suppress(Exception):
                participant.__del__()
        domain, self._domain = self._domain, None
        if domain is not None:
            with contextlib.suppress(Exception):
                domain.__del__()
        if self._trace is not None:  # once the domain is gone (or never was)
            self._trace.close(domain._ref if domain is not None else None)
            self._trace = None

    def health(self) -> dict[str, Any]:
        """Return the ``dds`` part of ``/healthz``."""
        out: dict[str, Any] = {
            "state": self.state,
            "guid": self.guid.hex(),
            "domain": self.options.domain,
            "ros_distro": self.options.distro,
            "discovery": self.options.discovery,
            "writers": len(self._writers),
            "readers": len(self._readers),
            "services": len(self._servers),
            "shared_pack": self._pack is not None,
            "remote_participants": len(self._participants),
            "remote_writers": len(self._remote_writers),
            "remote_readers": len(self._remote_readers),
            **dict(self.stats),
        }
        if self.error:
            out["error"] = self.error
        return out

    # -- the periodic pass ------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Reconcile when discovery or the graph changed (every 0.5 s at most), or every 30 s.

        An idle link costs a comparison a tick: a reconcile reads four discovery readers and
        walks every topic and service (1.1-2.5 ms with 30 robots, measured).
        """
        if self.participant is None or now < self._next_reconcile:
            return
        if not (
            self._discovered
            or self._refused_samples
            or now >= self._next_full
            or graph_signature(self.graph) != self._generation
        ):
            return
        self._next_reconcile = now + RECONCILE_PERIOD
        self._next_full = now + FULL_PERIOD
        self.reconcile()

    def reconcile(self) -> None:
        """Read discovery, import what other participants have, export what the graph has."""
        if self.participant is None:
            return
        self.stats["reconciles"] += 1
        self._discovered = False  # before the read: what comes during it is read next time
        try:
            self._read_discovery()
        except Exception as err:  # a discovery sample Cyclone or we cannot read
            self._log("discovery", f"DDS: discovery not read: {err}")
            self._discovered = True  # what was not read: again at the next period
        if self._refused_samples:
            self._say_refused()
        self._import_remote()
        # after the import, which changes the graph's tables: not a change to come back for
        self._generation = graph_signature(self.graph)
        self._export_local()
        self._announce()

    # -- discovery ------------------------------------------------------------------------

    def _read_discovery(self) -> None:
        core = importlib.import_module("cyclonedds.core")
        alive_state = core.InstanceState.Alive
        for kind, reader in self._builtin:
            samples = reader.take(DISCOVERY_BATCH)
            if len(samples) == DISCOVERY_BATCH:
                self._discovered = True  # more wait: Cyclone says so only of new ones
            for sample in samples:
                info = getattr(sample, "sample_info", None)
                alive = info is None or info.instance_state == alive_state
                if kind == "participant":
                    key = sample.key.bytes
                    if key == self.guid:
                        continue
                    if alive:
                        self._participants.add(key)
                    else:
                        self._forget_participant(key)
                    continue
                key = sample.key.bytes
                table = self._remote_writers if kind == "writer" else self._remote_readers
                if not alive:
                    table.pop(key, None)
                    continue
                participant = sample.participant_key.bytes
                if participant == self.guid:
                    continue
                remote = self._remote(sample, participant)
                if remote is None:
                    continue
                if key not in table and len(table) >= self.max_remote:
                    self.stats["remote_refused"] += 1
                    self._log(
                        "remote limit",
                        f"DDS: more than {self.max_remote} remote {kind}s "
                        "(dds_max_remote_endpoints): the others are ignored",
                    )
                    continue
                table[key] = remote
        infos = _take_raw(self._discovery_reader, DISCOVERY_BATCH)
        if len(infos) == DISCOVERY_BATCH:
            self._discovered = True
        for data, valid in infos:
            if not valid:
                continue
            try:
                info = read_participant_info(data, self.gid_size)
            except ValueError as err:
                self.stats["bad_payloads"] += 1
                self._log("discovery info", f"DDS: a bad {DISCOVERY_TOPIC} sample: {err}")
                continue
            gid = info.gid[:16]
            if gid != self.guid:
                self._infos[gid] = info

    def _forget_participant(self, key: bytes) -> None:
        """A participant left (or its lease ran out): drop it and every endpoint of it."""
        self._participants.discard(key)
        self._infos.pop(key, None)
        for table in (self._remote_writers, self._remote_readers):
            for gone in [k for k, r in table.items() if r.participant == key]:
                del table[gone]

    def _remote(self, sample: Any, participant: bytes) -> _Remote | None:
        """Return the ROS meaning of a discovered endpoint, None if it is not a ROS topic."""
        parsed = ros_name(sample.topic_name)
        if parsed is None or parsed[0] != "rt":
            return None
        try:
            type_name = ros_type(sample.type_name)
        except ValueError:
            type_name = sample.type_name
        latched = False
        with contextlib.suppress(Exception):
            durability = sample.qos["Durability"]
            latched = "Transient" in type(durability).__name__ or "TransientLocal" in repr(
                durability
            )
        return _Remote(participant, parsed[1], type_name, latched)

    def _owner(self, guid: bytes, remote: _Remote) -> DdsNode:
        """The node of a remote endpoint, as ``ros_discovery_info`` names it."""
        info = self._infos.get(remote.participant)
        if info is not None:
            for node in info.nodes:
                if any(g[:16] == guid for g in (*node.writers, *node.readers)):
                    return DdsNode(node.fqn, remote.participant.hex())
        return DdsNode(UNKNOWN_NODE, remote.participant.hex())

    # -- inward -----------------------------------------------------------------------------

    def _import_remote(self) -> None:
        """Make the graph hold exactly the remote publishers, subscriptions and nodes."""
        pubs: dict[str, dict[DdsNode, tuple[str, bool]]] = {}
        for guid, remote in self._remote_writers.items():
            owner = self._owner(guid, remote)
            pubs.setdefault(remote.name, {})[owner] = (remote.type, remote.latched)
        subs: dict[str, dict[DdsNode, str]] = {}
        for guid, remote in self._remote_readers.items():
            subs.setdefault(remote.name, {})[self._owner(guid, remote)] = remote.type
        for name in {*pubs, *self.imports.by_topic}:
            self.imports.update(name, pubs.get(name, {}))
        for name in {*subs, *self.stand_ins.by_topic}:
            self._import_subscriptions(name, subs.get(name, {}))
        self._import_nodes()

    def _local_clash(self, name: str, node: ForeignNode, local: str) -> None:
        self._log(
            f"clash {name}", f"DDS: {name} of {node} not bridged: {local} here publishes it already"
        )
        self.stats["name_clashes"] += 1

    def _import_subscriptions(self, name: str, subs: dict[DdsNode, str]) -> None:
        self.stand_ins.update(name, subs)

    def _import_nodes(self) -> None:
        """List the nodes of other participants in the graph (rosapi) while they exist."""
        nodes = self.graph.nodes
        wanted = {
            node.fqn
            for key, info in self._infos.items()
            if key in self._participants
            for node in info.nodes
        }
        for name in [n for n in self._remote_nodes if n not in wanted]:
            self._remote_nodes.discard(name)
            nodes.pop(name, None)
        for name in wanted - self._remote_nodes:
            if name in nodes:
                self._log(
                    f"node {name}",
                    f"DDS: a node {name} of another participant clashes with {name} here "
                    "(node names must be unique): not listed",
                )
                self.stats["name_clashes"] += 1
                continue
            nodes[name] = REMOTE_NODE
            self._remote_nodes.add(name)

    # -- outward ----------------------------------------------------------------------------

    def _wanted(self) -> tuple[dict[str, tuple[str, str, bool]], dict[str, tuple[str, str]]]:
        """Return the local writers (name -> node, type, latched) and readers (name -> ...)."""
        writers: dict[str, tuple[str, str, bool]] = {}
        readers: dict[str, tuple[str, str]] = {}
        for topic, publishers, subscribers in outward_topics(self.graph, self.stand_ins.ids):
            type_name = topic.type or ""
            # one writer and one reader a topic, under the first node that has it
            if publishers:
                writers[topic.name] = (publishers[0], type_name, topic.qos.transient_local)
            if subscribers:
                readers[topic.name] = (subscribers[0], type_name)
        return writers, readers

    def _export_local(self) -> None:
        writers, readers = self._wanted()
        for name in [n for n in self._writers if n not in writers]:
            self._drop_writer(self._writers.pop(name).handle)
        for name in [n for n in self._readers if n not in readers]:
            _delete(self._readers.pop(name).handle)
        for name, (node, type_name, latched) in writers.items():
            entry = self._writers.get(name)
            if entry is not None and (entry.type, entry.latched) == (type_name, latched):
                entry.node = node
                continue
            if entry is not None:
                self._drop_writer(self._writers.pop(name).handle)
            try:
                self._writers[name] = self._make_writer(name, node, type_name, latched)
            except Exception as err:  # a type Cyclone cannot describe, a refused QoS
                self._log(f"writer {name}", f"DDS: no writer for {name}: {err}")
                continue
            self.stats["writers_made"] += 1
            topic = self.graph.topics.topics.get(name)
            if latched and topic is not None and topic.latched is not None:
                self._write(self._writers[name], topic.latched)
        for name, (node, type_name) in readers.items():
            entry = self._readers.get(name)
            if entry is not None and entry.type == type_name:
                entry.node = node
                continue
            if entry is not None:
                _delete(self._readers.pop(name).handle)
            if self.refusal(name) is not None:
                continue  # the ROS 2 peers' role may not publish it: nothing to read
            try:
                self._readers[name] = self._make_reader(name, node, type_name)
            except Exception as err:
                self._log(f"reader {name}", f"DDS: no reader for {name}: {err}")
                continue
            self.stats["readers_made"] += 1
        self._export_services()

    def _wanted_services(self) -> dict[str, tuple[str, str]]:
        """Return the services to serve on DDS: name -> (node, type)."""
        return {
            service.name: (node, service.type)
            for service, node in outward_services(self.graph)
            if "/_action/" not in service.name
        }

    def _export_services(self) -> None:
        wanted = self._wanted_services()
        for name in [n for n in self._servers if n not in wanted]:
            gone = self._servers.pop(name)
            _delete(gone.reader)
            self._drop_writer(gone.writer)
        for name, (node, type_name) in wanted.items():
            server = self._servers.get(name)
            if server is not None and server.type == type_name:
                server.node = node
                continue
            try:
                self._servers[name] = self._make_server(name, node, type_name)
            except Exception as err:
                self._log(f"service {name}", f"DDS: service {name} not served: {err}")
                continue
            self.stats["services_made"] += 1

    def _make_server(self, name: str, node: str, type_name: str) -> _Server:
        core = importlib.import_module("cyclonedds.core")
        pub = importlib.import_module("cyclonedds.pub")
        sub = importlib.import_module("cyclonedds.sub")
        topic_mod = importlib.import_module("cyclonedds.topic")
        request, response = self.graph.registry.service(type_name)
        topics = []
        for dds_name, part in ((request_topic(name), request), (reply_topic(name), response)):
            key = (dds_name, dds_type(part))
            found = self._topics.get(key)
            if found is None:
                found = topic_mod.Topic(self.participant, dds_name, self.types.wrapped(part))
                self._topics[key] = found
            topics.append(found)
        policy = core.Policy
        qos = [policy.Reliability.Reliable(100_000_000), policy.History.KeepLast(DEPTH)]
        if self.options.distro != "humble":
            qos.append(policy.Userdata(typehash_user_data(self.hasher.service(type_name))))

        def available(reader: Any) -> None:  # a Cyclone thread
            self.hand_over(name, reader, self._on_call)

        reader = sub.DataReader(
            self.participant,
            topics[0],
            qos=core.Qos(*qos, policy.TypeConsistency.AllowTypeCoercion()),
            listener=core.Listener(on_data_available=available),
        )
        writer = pub.DataWriter(self.participant, topics[1], qos=core.Qos(*qos))
        if self._pack is not None:
            self._pack.adopt(writer)
        return _Server(
            name, type_name, node, reader, writer, (reader.guid.bytes, writer.guid.bytes)
        )

    def _topic(self, name: str, type_name: str) -> Any:
        key = (topic_name(name), dds_type(type_name))
        found = self._topics.get(key)
        if found is None:
            topic_mod = importlib.import_module("cyclonedds.topic")
            found = topic_mod.Topic(self.participant, key[0], self.types.get(type_name))
            self._topics[key] = found
        return found

    def _endpoint_qos(self, type_name: str, *, latched: bool, reader: bool) -> Any:
        core = importlib.import_module("cyclonedds.core")
        policy = core.Policy
        policies = [
            policy.Reliability.Reliable(100_000_000),
            policy.Durability.TransientLocal if latched else policy.Durability.Volatile,
            # a writer keeps what the graph offers; a reader the ROS 2 default
            policy.History.KeepLast(DEPTH if reader else _offer(latched).depth),
            policy.DataRepresentation(use_cdrv0_representation=True),
        ]
        if reader:
            # not what this participant writes; and a peer's type that differs only in
            # bounds (another Cyclone sends its type's structure) still matches
            policies += [policy.IgnoreLocal.Participant, policy.TypeConsistency.AllowTypeCoercion()]
        if self.options.distro != "humble":
            policies.append(policy.Userdata(typehash_user_data(self.hasher.message(type_name))))
        return core.Qos(*policies)

    def _make_writer(self, name: str, node: str, type_name: str, latched: bool) -> _Endpoint:
        core = importlib.import_module("cyclonedds.core")
        pub = importlib.import_module("cyclonedds.pub")
        entry = _Endpoint(name, type_name, node, None, b"", latched=latched)

        def matched(writer: Any, status: Any) -> None:  # a Cyclone thread
            entry.matched = status.current_count

        writer = pub.DataWriter(
            self.participant,
            self._topic(name, type_name),
            qos=self._endpoint_qos(type_name, latched=latched, reader=False),
            listener=core.Listener(on_publication_matched=matched),
        )
        entry.handle = writer
        entry.gid = writer.guid.bytes
        if self._pack is not None:
            self._pack.adopt(writer)
        return entry

    def _make_reader(self, name: str, node: str, type_name: str) -> _Endpoint:
        core = importlib.import_module("cyclonedds.core")
        sub = importlib.import_module("cyclonedds.sub")

        def available(reader: Any) -> None:  # a Cyclone thread
            self.hand_over(name, reader, self._on_sample)

        reader = sub.DataReader(
            self.participant,
            self._topic(name, type_name),
            qos=self._endpoint_qos(type_name, latched=False, reader=True),
            listener=core.Listener(on_data_available=available),
        )
        return _Endpoint(name, type_name, node, reader, reader.guid.bytes)

    def _announce(self) -> None:
        """Write this participant's nodes and endpoints on ``ros_discovery_info`` if changed."""
        nodes: dict[str, tuple[list[bytes], list[bytes]]] = {}
        for fqn, what in self.graph.nodes.items():
            if fqn not in self._remote_nodes and not what.startswith("a ROS 2 node"):
                nodes[fqn] = ([], [])
        for entry in self._writers.values():
            nodes.setdefault(entry.node, ([], []))[1].append(entry.gid)
        for entry in self._readers.values():
            nodes.setdefault(entry.node, ([], []))[0].append(entry.gid)
        for server in self._servers.values():
            readers, writers = nodes.setdefault(server.node, ([], []))
            readers.append(server.gids[0])
            writers.append(server.gids[1])
        info = ParticipantInfo(self.guid, node_entities(nodes))
        data = encode_participant_info(info, self.gid_size)
        if data == self._announced or self._discovery_writer is None:
            return
        try:
            self._send(self._discovery_writer, data)
        except Exception as err:
            self._log("announce", f"DDS: {DISCOVERY_TOPIC} not written: {err}")
            return
        self._announced = data
        self.stats["announced"] += 1

    def on_deliver(self, topic: Topic, out: Outgoing, source: Peer | None) -> None:
        """Tap on every delivery in the graph: write it for DDS readers."""
        if self._forwarding:
            return
        entry = self._writers.get(topic.name)
        if entry is None or not (entry.latched or entry.matched):
            return
        self._write(entry, out)

    def _write(self, entry: _Endpoint, out: Outgoing) -> None:
        try:
            payload = out.cdr() if out.cdr is not None else None
            if payload is None:
                payload = self.cdr.serialize(entry.type, out.msg)
        except Exception as err:  # a message the CDR writer cannot encode: skip, say so
            self._log(f"cdr {entry.name}", f"DDS: {entry.name} not sent: {err}")
            return
        try:
            self._send(entry.handle, payload)
        except Exception as err:
            self._log(f"write {entry.name}", f"DDS: write on {entry.name}: {err}")
            return
        self.stats["published"] += 1

    def _send(self, writer: Any, data: bytes) -> None:
        """Write CDR bytes on one of the link's writers; the shared pack goes at the turn's end."""
        _write_raw(writer, data)
        if self._pack is None or self._flush_pending:
            return
        loop = self._loop
        if loop is None:
            self._pack.flush()
            return
        self._flush_pending = True
        loop.call_soon(self._flush)

    def _flush(self) -> None:
        """Send the turn's samples (the shared pack; Cyclone sent any that filled it)."""
        self._flush_pending = False
        if self._pack is not None:
            self._pack.flush()

    def flush_early(self) -> None:
        """Send what the shared pack holds now (the graph has more to compute).

        A step's /odom and /tf then leave before its scans are cast.
        """
        if self._flush_pending and self._pack is not None:
            self._pack.flush()

    def _drop_writer(self, writer: Any) -> None:
        """Delete a writer (its own pack back first: deleting it frees the pack it holds)."""
        if self._pack is not None:
            self._pack.release(writer)
        _delete(writer)

    # -- samples from DDS -------------------------------------------------------------------

    def hand_over(self, name: str, reader: Any, take: Take) -> None:
        """Take a reader's samples and queue them for the event loop (Cyclone's threads).

        Past ``dds_inbox_bytes`` or ``INBOX_LIMIT`` samples, or over ``dds_max_sample_bytes``,
        a sample is dropped here and counted.
        """
        try:
            samples = _take_raw(reader, TAKE_BATCH)
        except Exception:  # the reader went with the participant
            return
        self.inbox.put_many(take, name, [data for data, valid in samples if valid])

    def _on_sample(self, name: str, payload: bytes) -> None:
        topic = self.graph.topics.topics.get(name)
        if topic is None or topic.type is None or self.participant is None:
            return
        if self.refusals.cache.get(name, "") is not None and self._refused(name, "a sample on"):
            return
        self.stats["received"] += 1
        try:
            msg = self.reader.read(topic.type, payload)
        except Exception as err:  # whatever the network sent: reported, never raised
            self.stats["bad_payloads"] += 1
            self._log(f"bad {name}", f"DDS: {name}: payload is not CDR of {topic.type}: {err}")
            return
        out = self.graph.topics.outgoing(topic, msg, self.graph.stamp())
        out.cdr = lambda: payload
        loop = self._loop
        now = loop.time() if loop is not None else 0.0
        self._forwarding = True
        try:
            self.graph.topics.deliver(topic, out, now, None)
        except SimbridgeError as err:
            self._log(f"refused {name}", f"DDS: {name}: refused here: {err}")
        finally:
            self._forwarding = False

    def _on_cyclone(
        self, refused: list[RefusedSample], lines: dict[str, tuple[int, str]], missed: int
    ) -> None:
        """What Cyclone's log said: samples it refused, and its other lines (by kind).

        A refused sample (not CDR of the reader's type) is counted now; whose it was is said at
        the next reconcile, once discovery was read (the writer may be newer than the last
        read). Each other kind of line (an error or warning of Cyclone's) is counted and said
        once per ``LOG_EVERY`` seconds, with its count.
        """
        if refused or missed:
            self.stats["bad_payloads"] += len(refused) + missed
            self.stats["refused_by_cyclone"] += len(refused) + missed
            room = REFUSALS_HELD - len(self._refused_samples)
            now = time.monotonic()
            self._refused_samples.extend((now, sample) for sample in refused[:room])
        for said, (count, text) in lines.items():
            self.stats["cyclone_log_lines"] += count
            kinds = self._cyclone_kinds
            kind = said if said in kinds or len(kinds) < KINDS else "other"
            self._cyclone_kinds[kind] += count
            self._log(
                f"cyclone {kind}",
                f"DDS: Cyclone DDS says: {text} ({self._cyclone_kinds[kind]} such lines so far)",
            )

    def _say_refused(self) -> None:
        """Log (rate-limited) the samples Cyclone refused since the last reconcile."""
        refused, self._refused_samples = self._refused_samples, []
        now = time.monotonic()
        for when, sample in refused:
            participant_key = sample.writer[:12] + PARTICIPANT_ENTITY
            if participant_key not in self._infos and now - when < NAMED_WITHIN:
                # its ros_discovery_info may come a little after its endpoints: wait for it
                self._refused_samples.append((when, sample))
                continue
            parsed = ros_name(sample.topic)
            name = parsed[1] if parsed is not None else sample.topic
            try:
                type_name = ros_type(sample.type)
            except ValueError:
                type_name = sample.type
            remote = self._remote_writers.get(sample.writer)
            participant = participant_key.hex()
            owner = (
                f"{self._owner(sample.writer, remote)} (participant {participant})"
                if remote is not None
                else f"participant {participant}"
            )
            what = {"rq": f"a request to {name}", "rr": f"a reply on {name}"}.get(
                parsed[0] if parsed is not None else "", f"{name}: a sample"
            )
            self._log(
                f"bad {name}",
                f"DDS: {what} from {owner} is not CDR of {type_name}: Cyclone DDS refused it "
                f"({sample.reason}); {self.stats['refused_by_cyclone']} refused so far",
            )

    # -- calls from DDS (rmw_cyclonedds's wire) ----------------------------------------------

    def _on_call(self, name: str, payload: bytes) -> None:
        """A request from a DDS client: answer it through the graph's service table.

        rmw_cyclonedds writes a request header (client id, sequence number) before the request
        and expects it back before the response; rmw_fastrtps's clients correlate through the
        DDS sample identity instead, which this library cannot write (docs/dds.md).
        """
        server = self._servers.get(name)
        if server is None or self.participant is None:
            return
        self.stats["calls_in"] += 1
        try:
            if len(payload) < 4 + REQUEST_HEADER:
                msg = (
                    f"{len(payload)} bytes, without rmw_cyclonedds's request header (an "
                    "rmw_fastrtps client? Its calls are not answered: docs/dds.md)"
                )
                raise ValueError(msg)
            header = payload[4 : 4 + REQUEST_HEADER]
            request_type, response_type = self.graph.registry.service(server.type)
            body = payload[:4] + payload[4 + REQUEST_HEADER :]
            request = self.reader.read(request_type, body)  # the canonical request, complete
        except Exception as err:  # whatever the network sent: reported, never raised
            self.stats["bad_payloads"] += 1
            self._log(
                f"call {name}", f"DDS: a request to {name} is not CDR of {server.type}: {err}"
            )
            return
        # the graph's access rules for the ROS 2 peers' role (administrative services, other
        # robots' services), then the service as it is now
        refusal = self.graph.access.reach_refusal(self._access, name)
        service = self.graph.services.services.get(name)
        if refusal is None and (service is None or service.type != server.type):
            refusal = f"{name} of type {server.type} does not exist (any more)"
        waits = service is not None and service.handler is None
        if refusal is None and waits and self.calls_waiting >= self.max_calls_waiting:
            refusal = (
                f"{name}: refused, DDS peers already wait for {self.max_calls_waiting} answers "
                "(the server's max_pending_calls)"
            )
        if refusal is not None or service is None:
            self._failed(server, f"service {refusal}")
            return

        def done(ok: bool, values: Any) -> None:
            self._service_answer(server, response_type, header, ok, values)

        loop = self._loop
        now = loop.time() if loop is not None else 0.0
        deadline = now + min(SERVICE_TIMEOUT, self.settings.max_call_timeout)
        if waits:
            self.calls_waiting += 1
        release = self._call_ended if waits else None
        self.graph.services.call(self._caller, service, request, deadline, done, release=release)

    def _call_ended(self) -> None:
        self.calls_waiting -= 1

    def _failed(self, server: _Server, text: str) -> None:
        # rmw has no error reply: the client waits; say why here
        self.stats["calls_failed"] += 1
        self._log(f"failed {server.name}", f"DDS: a call to {server.name}: {text}")

    def _service_answer(
        self, server: _Server, response_type: str, header: bytes, ok: bool, values: Any
    ) -> None:
        """The graph answered a call from DDS: write the reply with the request's header."""
        if not ok:
            self._failed(server, str(values))
            return
        try:
            # complete and checked: an in-process handler may leave fields to their defaults
            msg = self.graph.converter.from_json(response_type, values)
            data = self.cdr.serialize(response_type, msg)
            self._send(server.writer, data[:4] + header + data[4:])
        except Exception as err:
            self.stats["calls_failed"] += 1
            self._log(f"reply {server.name}", f"DDS: no reply to a call of {server.name}: {err}")
            return
        self.stats["calls_answered"] += 1

    # -- access ------------------------------------------------------------------------------

    def refusal(self, name: str) -> str | None:
        """Return why DDS peers may not publish on ``name``; None if they may (cached)."""
        return self.refusals.refusal(name)


def _write_raw(writer: Any, data: bytes) -> None:
    """Write serialized CDR (with its encapsulation header) on a Cyclone writer."""
    ret = _clayer().ddspy_write(writer._ref, data)
    if ret < 0:
        msg = f"dds_write returned {ret}"
        raise RuntimeError(msg)


def _take_raw(reader: Any, limit: int) -> list[tuple[bytes, bool]]:
    """Take up to ``limit`` samples of a Cyclone reader as their serialized bytes."""
    clayer = _clayer()
    if _TAKES_MASK:
        ret = clayer.ddspy_take(reader._ref, _ANY, limit)
    else:  # the binding 0.10 takes every state, with no mask argument
        ret = clayer.ddspy_take(reader._ref, limit)
    if isinstance(ret, int):
        msg = f"dds_take returned {ret}"
        raise RuntimeError(msg)
    return [(bytes(data), bool(info.valid_data)) for data, info in ret]


_CLAYER: Any = None
#: Whether the binding's ``ddspy_take`` takes a state mask (from 11 on; 0.10's takes none).
_TAKES_MASK = True
#: Any sample, view and instance state (Cyclone's DDS_ANY_STATE mask).
_ANY = 0x7F


def _clayer() -> Any:
    """Cyclone's C layer (imported once: it sits on the path of every sample)."""
    global _CLAYER, _TAKES_MASK
    if _CLAYER is None:
        _CLAYER = importlib.import_module("cyclonedds._clayer")
        _TAKES_MASK = not old_binding()
    return _CLAYER


def _delete(entity: Any) -> None:
    with contextlib.suppress(Exception):
        entity.__del__()


def _offer(latched: bool) -> TopicQos:
    """Return the graph's offer for a topic, latched or not (``Topic.qos``)."""
    return LATCHED_TOPIC_QOS if latched else DEFAULT_TOPIC_QOS
