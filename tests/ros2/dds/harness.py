"""The DDS test harness: private network namespaces, DDS domains, and the ROS 2 peers.

DDS discovery is multicast, so every DDS process of a test runs inside a network namespace the
test creates (:class:`NetNamespace`: only ``lo``, up, multicast on, a 224.0.0.0/4 route on it)
and no DDS packet reaches the machine's interfaces. Fast DDS's shared memory is not separated by
network namespaces, so each test also holds a DDS domain of its own (:func:`allocate_domain`, a
lock file per domain id, shared with every other test run on the machine).

Three ways into a namespace:

- ``ns.command(argv)``: the argv prefixed with ``nsenter --net=...``, for a subprocess (a
  ``simbridge --dds`` server, a peer);
- ``with ns.entered():``: the calling thread joins the namespace (``setns``); every socket it
  creates and every process it starts (Node, roslibpy, Chromium) is inside, so an in-process
  simbridge ``App`` and its clients can run there together. Threads started inside stay inside
  (and keep the namespace alive) after the block: stop what was started there (the App, its
  DDS participant, an executor made inside) before the block ends;
- ``ns.forward(port)``: a host port on 127.0.0.1 that forwards each TCP connection to
  ``127.0.0.1:port`` inside the namespace, for clients that stay on the host.

The peers print one JSON event a line (see ``peer/peer.cpp``); :class:`PeerProcess` collects
them and waits for conditions, :class:`DdsGraph` reads them as ``ros2 topic list -t`` and
``ros2 node list`` would.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import fcntl
import itertools
import json
import os
import select
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import pytest

from tests.helpers import ROOT, TIMEOUT_FACTOR


PEER_SOURCES = ROOT / "tests" / "ros2" / "dds" / "peer"
#: Where scripts/setup-test-deps.sh builds the Fast DDS peer (git-ignored).
PEER_BUILD = ROOT / "build" / "ddspeer"
PEER_BIN = PEER_BUILD / "ddspeer"
#: The second DDS implementation's peer: Cyclone DDS from PyPI, ddspeer's options and events.
SECOND_PEER = ROOT / "tests" / "ros2" / "dds" / "second_peer.py"

#: ROS_DOMAIN_IDs the tests take turns on (0 is left to manual tries).
DOMAINS = range(1, 101)
#: The multicast group and port of DDS discovery (SPDP) for a domain (DDSI-RTPS 2.x, 9.6.1.1).
SPDP_GROUP = "239.255.0.1"


def spdp_port(domain: int) -> int:
    return 7400 + 250 * domain


_CLONE_NEWNET = 0x40000000
_libc = ctypes.CDLL(None, use_errno=True)


def _setns(fd: int) -> None:
    if _libc.setns(fd, _CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"setns: {os.strerror(err)}")


# The namespace holder: makes the namespace, sets up lo, then lives as long as its stdin is open
# (so the namespace goes with the test run, even if pytest itself is killed).
_HOLDER = (
    "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo"
    " && echo ready && exec cat >/dev/null"
)


class NetNamespace:
    """A private network namespace with only ``lo``; :meth:`close` ends it and all in it."""

    def __init__(self) -> None:
        if os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("nsenter"):
            raise RuntimeError("network namespaces need root and util-linux (unshare, nsenter)")
        self._holder = subprocess.Popen(
            ["unshare", "--net", "--", "sh", "-c", _HOLDER],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        assert self._holder.stdout is not None
        ready, _, _ = select.select([self._holder.stdout], [], [], 10 * TIMEOUT_FACTOR)
        line = self._holder.stdout.readline() if ready else b""
        if line.strip() != b"ready":
            self._holder.kill()
            err = self._holder.communicate()[1].decode(errors="replace")
            raise RuntimeError(f"could not set up a network namespace: {err.strip()}")
        self.path = f"/proc/{self._holder.pid}/ns/net"
        self._fd = os.open(self.path, os.O_RDONLY)
        self.inode = os.fstat(self._fd).st_ino
        self._forwarders: list[_Forwarder] = []
        self._processes: list[subprocess.Popen[bytes] | asyncio.subprocess.Process] = []

    def command(self, argv: list[str]) -> list[str]:
        """``argv`` run inside the namespace."""
        return ["nsenter", f"--net={self.path}", "--", *argv]

    def own(self, proc: subprocess.Popen[bytes] | asyncio.subprocess.Process) -> None:
        """Kill ``proc`` (started in the namespace) when the namespace closes, if still running."""
        self._processes.append(proc)

    @contextlib.contextmanager
    def entered(self) -> Iterator[None]:
        """The calling thread inside the namespace for the block (back where it was after)."""
        home = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
        try:
            _setns(self._fd)
            try:
                yield
            finally:
                _setns(home)
        finally:
            os.close(home)

    def forward(self, port: int) -> int:
        """A port of the host's 127.0.0.1 whose connections reach ``127.0.0.1:port`` inside."""
        forwarder = _Forwarder(self._fd, port)
        self._forwarders.append(forwarder)
        return forwarder.port

    def interfaces(self) -> list[str]:
        """The names of the namespace's network interfaces."""
        out = subprocess.run(
            self.command(["ip", "-o", "link", "show"]), capture_output=True, check=True, text=True
        ).stdout
        return [line.split(":")[1].strip().split("@")[0] for line in out.splitlines() if line]

    def close(self) -> None:
        for forwarder in self._forwarders:
            forwarder.close()
        for proc in self._processes:
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
        for proc in self._processes:
            if isinstance(proc, subprocess.Popen):
                proc.wait(5)
        os.close(self._fd)
        assert self._holder.stdin is not None
        self._holder.stdin.close()
        try:
            self._holder.wait(5)
        except subprocess.TimeoutExpired:
            self._holder.kill()
            self._holder.wait()
        for stream in (self._holder.stdout, self._holder.stderr):
            if stream is not None:
                stream.close()


def namespace_holders(inode: int) -> list[str]:
    """What holds the network namespace ``inode``: ``/proc`` paths of processes, threads, fds."""
    target = f"net:[{inode}]"
    holders = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        links = [proc / "ns" / "net"]
        with contextlib.suppress(OSError):
            links += [task / "ns" / "net" for task in (proc / "task").iterdir()]
            links += list((proc / "fd").iterdir())
        for link in links:
            with contextlib.suppress(OSError):
                if os.readlink(link) == target:
                    holders.append(str(link))
    return holders


def namespace_exists(inode: int) -> bool:
    """Whether any process (or thread) of the machine is in, or holds, the namespace ``inode``."""
    return bool(namespace_holders(inode))


class _Forwarder:
    """TCP from the host's 127.0.0.1 to 127.0.0.1 in a namespace, one thread per direction."""

    def __init__(self, ns_fd: int, target_port: int) -> None:
        # the listening socket is made here, in the caller's (host) namespace
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.1)
        self.port = int(self._listener.getsockname()[1])
        self._target = target_port
        self._ns_fd = ns_fd
        self._stop = threading.Event()
        self._sockets: list[socket.socket] = []
        self._thread = threading.Thread(target=self._accept, name="netns-forward", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        _setns(self._ns_fd)  # this thread's sockets are made inside the namespace
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                upstream = socket.create_connection(("127.0.0.1", self._target), timeout=5)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            client.settimeout(None)
            self._sockets += [client, upstream]
            for src, dst in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pump, args=(src, dst), daemon=True).start()

    @staticmethod
    def _pump(src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := src.recv(65536):
                dst.sendall(data)
        except OSError:
            pass
        with contextlib.suppress(OSError):
            dst.shutdown(socket.SHUT_WR)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self._listener.close()
        for sock in self._sockets:
            with contextlib.suppress(OSError):
                sock.close()


_allocations = itertools.count()


@contextlib.contextmanager
def allocate_domain() -> Iterator[int]:
    """A DDS domain id no other test on this machine holds meanwhile (lock files in /tmp)."""
    # each allocation starts further on, so that consecutive tests do not share a domain either
    start = (os.getpid() + next(_allocations)) % len(DOMAINS)
    for offset in range(len(DOMAINS)):
        domain = DOMAINS[(start + offset) % len(DOMAINS)]
        lock: IO[str] = open(f"/tmp/simbridge-dds-domain-{domain}.lock", "w")  # noqa: SIM115
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        try:
            yield domain
        finally:
            lock.close()
        return
    raise RuntimeError(f"all DDS domains {DOMAINS.start}-{DOMAINS.stop - 1} are in use")


# --- the peers' events ------------------------------------------------------------------------

Event = dict[str, Any]


def ros_topic(dds_name: str) -> str | None:
    """The ROS name of a DDS topic (``rt/odom`` -> ``/odom``), None for non-ROS topics."""
    for prefix in ("rt/", "rq/", "rr/"):
        if dds_name.startswith(prefix):
            return "/" + dds_name[len(prefix) :]
    return None


def ros_type(dds_type: str) -> str:
    """``nav_msgs::msg::dds_::Odometry_`` -> ``nav_msgs/msg/Odometry``."""
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_type


def service_type(dds_type: str) -> str:
    """``std_srvs::srv::dds_::Empty_Request_`` -> ``std_srvs/srv/Empty``."""
    name = ros_type(dds_type)
    for suffix in ("_Request", "_Response"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


@dataclass
class Endpoint:
    kind: str  # "reader" | "writer"
    guid: str
    topic: str  # as on the wire: rt/odom
    type: str  # as on the wire: nav_msgs::msg::dds_::Odometry_
    reliability: str
    durability: str
    user_data: str


@dataclass
class DdsGraph:
    """The ROS graph as a peer's discovery events show it (rmw_dds_common graph_cache)."""

    endpoints: dict[str, Endpoint] = field(default_factory=dict)
    participants: dict[str, str] = field(default_factory=dict)  # guid -> USER_DATA
    node_infos: dict[str, list[Event]] = field(default_factory=dict)  # participant gid -> nodes

    @classmethod
    def of(cls, events: list[Event]) -> DdsGraph:
        graph = cls()
        for ev in events:
            kind = ev.get("event")
            if kind == "endpoint":
                if ev["alive"]:
                    graph.endpoints[ev["guid"]] = Endpoint(
                        ev["kind"],
                        ev["guid"],
                        ev["topic"],
                        ev["type"],
                        ev["reliability"],
                        ev["durability"],
                        ev["user_data"],
                    )
                else:
                    graph.endpoints.pop(ev["guid"], None)
            elif kind == "participant":
                if ev["alive"]:
                    graph.participants[ev["guid"]] = ev["user_data"]
                else:
                    graph.participants.pop(ev["guid"], None)
                    graph.node_infos.pop(ev["guid"], None)
                    graph.endpoints = {
                        g: e for g, e in graph.endpoints.items() if g[:24] != ev["guid"][:24]
                    }
            elif kind == "nodes":
                graph.node_infos[ev["gid"]] = ev["nodes"]
        return graph

    def topics(self) -> dict[str, set[str]]:
        """ROS topic name -> ROS types, as ``ros2 topic list -t`` (``rt/`` topics only)."""
        out: dict[str, set[str]] = {}
        for e in self.endpoints.values():
            if e.topic.startswith("rt/"):
                out.setdefault("/" + e.topic[3:], set()).add(ros_type(e.type))
        return out

    def nodes(self) -> set[str]:
        """Fully qualified names of the nodes announced on ``ros_discovery_info``."""
        names = set()
        for nodes in self.node_infos.values():
            for n in nodes:
                ns = n["namespace"].rstrip("/")
                names.add(f"{ns}/{n['name']}")
        return names

    def node(self, fqn: str) -> dict[str, dict[str, str]]:
        """A node's publishers, subscribers, services and clients, as ``ros2 node info``.

        ROS name -> ROS type each, from the gids the node lists on ``ros_discovery_info``.
        """
        for nodes in self.node_infos.values():
            for n in nodes:
                if f"{n['namespace'].rstrip('/')}/{n['name']}" != fqn:
                    continue
                out: dict[str, dict[str, str]] = {
                    "publishers": {},
                    "subscribers": {},
                    "services": {},
                    "clients": {},
                }
                for gid in [*n["writers"], *n["readers"]]:
                    e = self.endpoints.get(gid)
                    if e is None:
                        continue
                    if e.topic.startswith("rt/"):
                        role = "publishers" if e.kind == "writer" else "subscribers"
                        out[role]["/" + e.topic[3:]] = ros_type(e.type)
                    elif e.topic.startswith("rq/") and e.topic.endswith("Request"):
                        role = "services" if e.kind == "reader" else "clients"
                        out[role]["/" + e.topic[3 : -len("Request")]] = service_type(e.type)
                return out
        raise KeyError(f"no node {fqn} on ros_discovery_info (nodes: {sorted(self.nodes())})")

    def services(self) -> dict[str, set[str]]:
        """ROS service name -> types, as ``ros2 service list -t`` (from ``rq/`` readers)."""
        out: dict[str, set[str]] = {}
        for e in self.endpoints.values():
            if e.kind == "reader" and e.topic.startswith("rq/") and e.topic.endswith("Request"):
                out.setdefault("/" + e.topic[3 : -len("Request")], set()).add(service_type(e.type))
        return out

    def writers(self, topic: str) -> list[Endpoint]:
        return [e for e in self.endpoints.values() if e.kind == "writer" and e.topic == topic]

    def readers(self, topic: str) -> list[Endpoint]:
        return [e for e in self.endpoints.values() if e.kind == "reader" and e.topic == topic]


class PeerProcess:
    """A peer started in a namespace: its JSON events as they come, and its stdin."""

    def __init__(self, proc: asyncio.subprocess.Process, label: str) -> None:
        self.proc = proc
        self.label = label
        self.events: list[Event] = []
        self.stderr: list[str] = []
        self._new = asyncio.Event()
        self._tasks = [
            asyncio.create_task(self._read_stdout()),
            asyncio.create_task(self._read_stderr()),
        ]

    async def _read_stdout(self) -> None:
        assert self.proc.stdout is not None
        async for raw in self.proc.stdout:
            line = raw.decode(errors="replace").strip()
            if not line:
                continue
            try:
                event = json.loads(line)
            except ValueError:
                event = {"event": "unparsed", "line": line}
            self.events.append(event)
            self._new.set()
            self._new = asyncio.Event()
        self._new.set()

    async def _read_stderr(self) -> None:
        assert self.proc.stderr is not None
        async for raw in self.proc.stderr:
            self.stderr.append(raw.decode(errors="replace").rstrip())
            del self.stderr[:-50]

    def _diagnosis(self) -> str:
        counts: dict[str, int] = {}
        for e in self.events:
            counts[str(e.get("event"))] = counts.get(str(e.get("event")), 0) + 1
        others = [e for e in self.events if e.get("event") not in ("sample", "cmd_vel")]
        tail = [json.dumps(e)[:300] for e in others[-15:]]
        return (
            f"{self.label} (exit {self.proc.returncode}); events {counts}; last but samples:\n  "
            + "\n  ".join(tail)
            + ("\nstderr:\n  " + "\n  ".join(self.stderr[-15:]) if self.stderr else "")
        )

    async def wait_for(
        self, predicate: Callable[[Event], bool], timeout: float = 10.0, what: str = "an event"
    ) -> Event:
        """The first event (so far or to come) that ``predicate`` accepts; AssertionError else."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout * TIMEOUT_FACTOR
        seen = 0
        while True:
            new = self._new
            for event in self.events[seen:]:
                if predicate(event):
                    return event
            seen = len(self.events)
            remaining = deadline - loop.time()
            if self._tasks[0].done():
                raise AssertionError(f"{self.label} ended without {what}: {self._diagnosis()}")
            if remaining <= 0:
                raise AssertionError(f"no {what} within {timeout} s from {self._diagnosis()}")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(new.wait(), remaining)

    async def sample(
        self,
        topic: str,
        predicate: Callable[[Any], bool] = lambda data: True,
        timeout: float = 10.0,
    ) -> Any:
        """The data of the first sample of ``topic`` (a ROS name) that ``predicate`` accepts."""
        event = await self.wait_for(
            lambda e: e.get("event") == "sample" and e["topic"] == topic and predicate(e["data"]),
            timeout,
            f"sample of {topic}",
        )
        return event["data"]

    def samples(self, topic: str) -> list[Any]:
        return [
            e["data"] for e in self.events if e.get("event") == "sample" and e["topic"] == topic
        ]

    def graph(self) -> DdsGraph:
        return DdsGraph.of(self.events)

    async def wait_graph(
        self, predicate: Callable[[DdsGraph], bool], timeout: float = 10.0, what: str = "graph"
    ) -> DdsGraph:
        """The graph once ``predicate`` holds of it."""
        await self.wait_for(lambda e: predicate(self.graph()), timeout, what)
        return self.graph()

    async def send(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line.encode() + b"\n")
        await self.proc.stdin.drain()

    async def stop(self, timeout: float = 5.0) -> int:
        """End of stdin (a clean stop, the peer's endpoints removed); kill past ``timeout``."""
        if self.proc.returncode is None:
            assert self.proc.stdin is not None
            with contextlib.suppress(ConnectionError):
                self.proc.stdin.close()
            try:
                await asyncio.wait_for(self.proc.wait(), timeout)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    self.proc.kill()
                await self.proc.wait()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.wait_for(task, 2)
        assert self.proc.returncode is not None
        return self.proc.returncode


async def start_peer(
    ns: NetNamespace,
    argv: list[str],
    domain: int,
    label: str,
    ready: bool = True,
) -> PeerProcess:
    """Start ``argv`` in ``ns`` on ``domain``; wait for its ``ready`` event."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    proc = await asyncio.create_subprocess_exec(
        *ns.command(argv),
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=env,
        limit=1 << 24,  # a sample is one line: /walls can be long
    )
    ns.own(proc)
    peer = PeerProcess(proc, label)
    if ready:
        await peer.wait_for(lambda e: e.get("event") == "ready", 15, "ready")
    return peer


# --- fixtures (tests/ros2/dds/conftest.py re-exports them; so can any other conftest) --------

PeerFactory = Callable[..., Awaitable[PeerProcess]]


@pytest.fixture
def netns() -> Iterator[NetNamespace]:
    """A fresh private network namespace; everything in it is killed at the end of the test.

    The teardown fails if anything still holds the namespace 3 s after (a thread started in
    ``entered()`` and never stopped, say).
    """
    try:
        ns = NetNamespace()
    except RuntimeError as exc:
        pytest.skip(str(exc))
    try:
        yield ns
    finally:
        ns.close()
        # whatever the test did, nothing may be left in the namespace (its threads included)
        deadline = time.monotonic() + 3 * TIMEOUT_FACTOR
        while (holders := namespace_holders(ns.inode)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not holders, f"the test's network namespace outlived it, held by {holders}"


@pytest.fixture
def dds_domain() -> Iterator[int]:
    """A ROS_DOMAIN_ID of this test's own (Fast DDS shared memory crosses namespaces)."""
    with allocate_domain() as domain:
        yield domain


@pytest.fixture(scope="session")
def ddspeer_bin() -> Path:
    """The Fast DDS peer, built by ``make deps``; the test is skipped if it was not built."""
    if not PEER_BIN.exists():
        pytest.skip(f"the Fast DDS test peer is not built ({PEER_BIN}): run `make deps`")
    return PEER_BIN


@pytest.fixture
async def ddspeer(
    netns: NetNamespace, dds_domain: int, ddspeer_bin: Path
) -> AsyncIterator[PeerFactory]:
    """Start Fast DDS peers in ``netns`` on ``dds_domain`` (``await start("--robot")``).

    Returns once the peer printed ``ready`` (its entities made and announced); every peer is
    stopped at the end of the test.
    """
    peers: list[PeerProcess] = []

    async def start(*args: str, node: str = "ddspeer", distro: str = "humble") -> PeerProcess:
        argv = [str(ddspeer_bin), "--domain", str(dds_domain), "--node", node, "--distro", distro]
        peer = await start_peer(netns, [*argv, *args], dds_domain, f"ddspeer {node}")
        peers.append(peer)
        return peer

    yield start
    for peer in peers:
        await peer.stop()


@pytest.fixture
async def cyclonepeer(netns: NetNamespace, dds_domain: int) -> AsyncIterator[PeerFactory]:
    """Start Cyclone DDS peers (``second_peer.py``) in ``netns`` on ``dds_domain``."""
    pytest.importorskip("cyclonedds")
    peers: list[PeerProcess] = []

    async def start(*args: str, node: str = "second_peer", distro: str = "humble") -> PeerProcess:
        argv = [sys.executable, str(SECOND_PEER), "--domain", str(dds_domain), "--node", node]
        peer = await start_peer(netns, [*argv, "--distro", distro, *args], dds_domain, node)
        peers.append(peer)
        return peer

    yield start
    for peer in peers:
        await peer.stop()
