"""ROS 2 over Zenoh (issue 15): the Zenoh hop, outward publishing, and a classroom of processes.

``python -m bench.zenoh [hop|outward|classroom|calls] [SECONDS]`` (default: hop and outward, 20
s).
Every process is separate: a router (``simbridge zenohd``) on a free port of 127.0.0.1, the
simbridge processes, the clients. Peers find each other through the router, then exchange data
directly (rmw_zenoh's default topology: the router is not a broker on one host).

* ``hop``: one robot simulated by process A; a rosbridge client of A and a rosbridge client of a
  ``--no-sim`` process B both subscribe to its /odom. Latency = arrival minus the message's
  header stamp (the wall clock when A published it), p50 and p99, side by side in one run.
  Target: p99 added by the hop <= 2 ms.
* ``outward``: 30 robots; A's CPU (its own user + system seconds over the same window's wall
  seconds) while one rosbridge client subscribes to every robot's /odom and /scan and /tf, then
  while one ROS 2 subscriber (another process: rmw_zenoh subscription tokens, one Zenoh
  subscriber counting samples) does; ``ROUNDS`` (default 3) rounds, alternating which goes
  first, and the median of the rounds' ratios (one run's ratio moved 1.19-1.36x with the
  machine's load). Target: ROS 2 <= 1.0x the rosbridge client (issue 24's; 1.3x when the
  link was first built).
* ``calls``: service calls across Zenoh, one at a time, ``SECONDS`` each way (default world
  with ``--demo-nodes``): a ROS 2 client (this process, as rmw_zenoh: a query with its
  attachment, CDR both ways) calls the in-process ``/add_two_ints``; a rosbridge client calls
  it too, for reference (taking turns on :data:`ROSBRIDGE_CONNECTIONS` connections: one
  client's calls in a row would pass ``message_rate``); a rosbridge client calls
  ``/bench_add``, which this process provides as a ROS 2 server (a queryable and its
  liveliness token), so that simbridge forwards each call as a query. Per row: calls, calls/s,
  round trip p50 and p99 in microseconds, and simbridge's CPU per call (its user + system
  seconds over the row, minus its CPU with nobody calling over as long, per call).
  ``SIMBRIDGE_BASELINE=DIR`` runs the same rows against another checkout's simbridge too (e.g.
  a ``git worktree`` of an older commit), alternating over ``ROUNDS`` rounds, with the ratios:
  before and after in one run (``SIMBRIDGE_TREE=DIR`` replaces this checkout's).
* ``classroom``: ``SIMS`` simulators x ``ROBOTS`` robots and ``FRONTS`` ``--no-sim`` front-ends
  x ``CLIENTS`` clients, each client on one robot's /odom and /scan through the router
  (environment variables; default 2 x 300 and 2 x 300). The clients are ``bench.loadgen``
  processes (``LOADGENS`` per front-end, default 1): real rosbridge WebSocket clients (the
  handshake, ``subscribe`` ops, every message received and its stamp read), kept as cheap as
  a client can be because here they share the machine with what they measure (in a class,
  the students' own machines run them). Per client: /odom rate, losses (gaps in the
  header stamps), latency p99. Target: 20 Hz +- 10 %, 0 lost, p99 <= 50 ms. Where the CPU
  goes: each process kind's cores (user + system seconds over the run's seconds) against the
  cores the machine has. Where in the 50 ms period each simulator ticks (they take turns: see
  ``ZenohLink.tick_share``). ``CPROFILE=DIR`` runs each simbridge process under cProfile (its
  ``.prof`` file in DIR when it exits; the figures are then those of a profiled run).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import math
import os
import re
import statistics
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import psutil
import yaml
from websockets.asyncio.client import connect

from bench import ros2outward
from bench.procs import (
    ROOT,
    collect,
    cpu_seconds,
    free_port,
    load_average,
    percentile,
    start_loadgens,
    stop,
    tree_env,
)


def _world(directory: Path, prefix: str, count: int, name: str) -> Path:
    side = max(1, int(count**0.5 + 0.999))
    robots = [
        {"name": f"{prefix}{k + 1}", "pose": [1.0 * (k % side), 1.0 * (k // side), 0.0]}
        for k in range(count)
    ]
    size = side + 2.0
    spec = {
        "name": name,
        "walls": [[-2, -2, size, -2], [size, -2, size, size], [size, size, -2, size]],
        "robots": robots,
    }
    path = directory / f"{name}.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


@contextmanager
def _router() -> Iterator[str]:
    with _router_process() as (endpoint, _proc):
        yield endpoint


@contextmanager
def _router_process() -> Iterator[tuple[str, psutil.Process]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "simbridge", "zenohd", "--listen", endpoint],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    proc.stdout.readline()
    try:
        yield endpoint, psutil.Process(proc.pid)
    finally:
        stop(proc)


@contextmanager
def _simbridge(
    router: str, *options: str, zenoh: bool = True, tree: Path = ROOT
) -> Iterator[tuple[psutil.Process, int]]:
    cmd = [sys.executable, "-m", "simbridge", "--host", "127.0.0.1", "--port", "0", "--no-http"]
    if os.environ.get("CPROFILE"):  # each simbridge process under cProfile, to that directory
        kind = "front-end" if "--no-sim" in options else "simulator"
        out = f"{os.environ['CPROFILE']}/{kind}-{time.monotonic_ns()}.prof"
        cmd[1:1] = ["-m", "cProfile", "-o", out]
    cmd += ["--log-level", "warning", "--max-clients", "2000"]
    if zenoh:
        cmd += ["--zenoh", "--zenoh-connect", router, "--zenoh-listen", "tcp/127.0.0.1:0"]
    cwd, env = tree_env(tree)
    proc = subprocess.Popen([*cmd, *options], cwd=cwd, env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        match = re.search(r"ws://[^:]+:(\d+)/", line)
        if match is None:
            msg = f"simbridge did not start: {line!r}"
            raise RuntimeError(msg)
        yield psutil.Process(proc.pid), int(match.group(1))
    finally:
        stop(proc)


def _wait_topic(port: int, topic: str, timeout: float = 30.0) -> None:
    async def probe() -> None:
        deadline = time.monotonic() + timeout
        async with connect(f"ws://127.0.0.1:{port}") as ws:
            while time.monotonic() < deadline:
                await ws.send(
                    json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
                )
                reply = json.loads(await ws.recv())
                if topic in reply.get("values", {}).get("topics", []):
                    return
                await asyncio.sleep(0.5)
        msg = f"{topic} did not reach the front-end within {timeout} s"
        raise RuntimeError(msg)

    asyncio.run(probe())


def hop(seconds: float) -> bool:
    with tempfile.TemporaryDirectory() as tmp, _router() as router:
        world = _world(Path(tmp), "hop", 1, "hop")
        with (
            _simbridge(router, "--world", str(world)) as (_a, port_a),
            _simbridge(router, "--no-sim") as (_b, port_b),
        ):
            _wait_topic(port_b, "/hop1/odom")
            same: list[float] = []
            via: list[float] = []

            async def both() -> None:
                await asyncio.gather(
                    ros2outward.rosbridge_latencies(port_a, "/hop1/odom", seconds, same),
                    ros2outward.rosbridge_latencies(port_b, "/hop1/odom", seconds, via),
                )

            asyncio.run(both())
    rows = [("same process (A)", same), ("via B through the router", via)]
    print(f"zenoh hop: /odom latency of a rosbridge client, {seconds:g} s, {load_average()}")
    ros2outward.print_latencies(rows)
    added = (percentile(via, 0.99) - percentile(same, 0.99)) * 1e3
    ratio = percentile(via, 0.99) / max(percentile(same, 0.99), 1e-9)
    ok = added <= 2.0
    print(
        f"p99 added by the hop: {added:.2f} ms (ratio {ratio:.2f}x); target <= 2 ms: "
        f"{'met' if ok else 'NOT met'}"
    )
    return ok


def _ros2_subscriber(router: str, names: list[tuple[str, str]], seconds: float) -> Any:
    """Start a ROS 2 subscriber process: rmw_zenoh subscription tokens, one counting subscriber.

    It does not decode: the figure is the server's CPU, not the subscriber's.
    """
    code = f"""
import json, time, zenoh
from simbridge.ros2.names import Entity
conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("connect/endpoints", '["{router}"]')
conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
conf.insert_json5("scouting/multicast/enabled", "false")
s = zenoh.open(conf)
zid = str(s.info.zid())
tokens = [s.liveliness().declare_token(Entity(0, zid, "0", "0", "NN", "/", "bench_sub").token())]
for i, (name, type_name) in enumerate({names!r}):
    e = Entity(0, zid, "0", str(i + 1), "MS", "/", "bench_sub", name=name, type=type_name,
               type_hash="RIHS01_0")
    tokens.append(s.liveliness().declare_token(e.token()))
count = [0]
sub = s.declare_subscriber("0/**", lambda sample: count.__setitem__(0, count[0] + 1))
time.sleep(3)
start = count[0]
print("start", flush=True)
time.sleep({seconds})
print(json.dumps({{"messages": count[0] - start}}), flush=True)
import os
os._exit(0)  # without waiting for Zenoh's threads
"""
    return subprocess.Popen(
        [sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, text=True
    )


def outward(seconds: float) -> bool:
    n = 30
    rounds = int(os.environ.get("ROUNDS", "3"))
    topics = ros2outward.robot_topics(n)
    with tempfile.TemporaryDirectory() as tmp, _router() as router:
        world = _world(Path(tmp), "r", n, "outward")
        with _simbridge(router, "--world", str(world)) as (proc, port):
            time.sleep(3)
            idle = ros2outward.cpu_share(proc, seconds)
            results = ros2outward.compare_outward(
                proc,
                port,
                topics,
                seconds,
                rounds,
                lambda: _ros2_subscriber(router, topics, seconds),
            )
    title = f"zenoh outward: {n} robots' /odom, /scan and /tf, {rounds} alternating rounds of"
    title += f" {seconds:g} s"
    return ros2outward.report_outward(title, idle, results, label="ROS 2", target=1.0)


def classroom(seconds: float) -> bool:
    sims = int(os.environ.get("SIMS", "2"))
    robots = int(os.environ.get("ROBOTS", "300"))
    fronts = int(os.environ.get("FRONTS", "2"))
    clients = int(os.environ.get("CLIENTS", "300"))
    loadgens = int(os.environ.get("LOADGENS", "1"))  # load-generator processes per front-end
    names = [f"s{s}r{k + 1}" for s in range(sims) for k in range(robots)]
    with tempfile.TemporaryDirectory() as tmp, _router_process() as (router, router_proc):
        worlds = [_world(Path(tmp), f"s{s}r", robots, f"sim{s}") for s in range(sims)]
        with contextlib.ExitStack() as stack:
            sim_started = [
                stack.enter_context(_simbridge(router, "--world", str(w))) for w in worlds
            ]
            sim_procs = [proc for proc, _ in sim_started]
            started = [stack.enter_context(_simbridge(router, "--no-sim")) for _ in range(fronts)]
            front_procs = [proc for proc, _ in started]
            for _, port in started:
                for s in range(sims):
                    _wait_topic(port, f"/s{s}r{robots}/odom", timeout=180)
            time.sleep(2)
            start = time.time() + 5.0
            end = start + seconds
            procs = []
            for f, (_, port) in enumerate(started):
                specs = [
                    {
                        "subscribe": [f"/{robot}/odom", f"/{robot}/scan"],
                        "drive": None,
                    }
                    for robot in (names[(f * clients + c) % len(names)] for c in range(clients))
                ]
                procs += start_loadgens(f"ws://127.0.0.1:{port}", specs, loadgens, start, end)
            kinds = {
                "simulators": sim_procs,
                "front-ends": front_procs,
                "router": [router_proc],
                "load generators": [psutil.Process(p.pid) for p in procs],
            }
            measured = [p for group in kinds.values() for p in group]
            time.sleep(max(0.0, start - time.time()))
            cpu0 = [p.cpu_times() for p in measured]
            health0 = _healths(sim_started, started)
            steal0 = _steal()
            time.sleep(max(0.0, end - time.time()))
            cpu1 = [p.cpu_times() for p in measured]
            steal = _steal() - steal0
            health1 = _healths(sim_started, started)
            load = load_average()
            results = collect(procs, timeout=seconds + 120)
    rates: list[float] = []
    lost = 0
    lat: list[float] = []
    errors = [r["error"] for r in results if r.get("error")]
    for r in results:
        lat += r.get("latencies", [])
        odom = next((t for t in r.get("stamps", {}) if t.endswith("/odom")), None)
        stamps = r["stamps"][odom] if odom is not None else []
        rates.append(len(stamps) / seconds)
        lost += sum(max(0, round((b - a) / 50e6) - 1) for a, b in itertools.pairwise(stamps))
    used = {
        id(p): (b.user - a.user, b.system - a.system)
        for p, a, b in zip(measured, cpu0, cpu1, strict=True)
    }
    low, high = percentile(rates, 0.01), percentile(rates, 0.99)
    p50, p99 = percentile(lat, 0.5) * 1e3, percentile(lat, 0.99) * 1e3
    print(
        f"zenoh classroom: {sims} simulators x {robots} robots, {fronts} front-ends x "
        f"{clients} clients (/odom + /scan each), {seconds:g} s, {load}"
    )
    print(f"CPU in cores (CPU seconds / wall seconds) of the {os.cpu_count()} this machine has:")
    print(f"  {'':16}{'cores':>6}{'user':>6}{'system':>8}  each")
    totals = [0.0, 0.0]
    for kind, group in kinds.items():
        user = sum(used[id(p)][0] for p in group) / seconds
        system = sum(used[id(p)][1] for p in group) / seconds
        totals[0] += user
        totals[1] += system
        each = " ".join(f"{sum(used[id(p)]) / seconds:.2f}" for p in group)
        print(f"  {kind:16}{user + system:6.2f}{user:6.2f}{system:8.2f}  {each}")
    print(f"  {'all':16}{sum(totals):6.2f}{totals[0]:6.2f}{totals[1]:8.2f}")
    print(f"  {'stolen (VM host)':16}{steal / seconds:6.2f}")
    reads = sum(r.get("reads", 0) for r in results)
    print(
        f"client reads: {reads / seconds / max(1, len(results)):.1f} per client per second, "
        f"{len(lat) / max(1, reads):.2f} messages per read"
    )
    print(
        f"/odom rate per client: p1 {low:.1f} Hz, p99 {high:.1f} Hz (target 18-22 Hz); "
        f"{len(results)} clients, {len(errors)} errors {errors[:2]}"
    )
    print(
        f"/odom lost (stamp gaps): {lost} (target 0); latency p50 {p50:.1f} ms, "
        f"p99 {p99:.1f} ms (target <= 50), {len(lat)} messages"
    )
    phases = []
    for k in range(sims):
        angles = [
            2.0 * math.pi * (t % 50_000_000) / 50e6
            for r in results
            for topic, values in r.get("stamps", {}).items()
            if topic.startswith(f"/s{k}r") and topic.endswith("/odom")
            for t in values[:20]
        ]
        mean = math.atan2(sum(map(math.sin, angles)), sum(map(math.cos, angles)))
        phases.append((mean / (2.0 * math.pi) * 50.0) % 50.0 if angles else float("nan"))
    print(
        "where each simulator ticks in the 50 ms period (its /odom stamps, circular mean, ms): "
        + " ".join(f"{p:.1f}" for p in phases)
    )
    _print_health(health0, health1)
    ok = low >= 18.0 and high <= 22.0 and lost == 0 and p99 <= 50.0 and not errors
    print(f"targets: {'met' if ok else 'NOT met'}")
    return ok


#: The tutorial service every default world has (example_interfaces/srv/AddTwoInts).
ADD_SERVICE = "/add_two_ints"
#: The service the bench's own ROS 2 process provides (AddTwoInts, like the tutorial's).
REMOTE_SERVICE = "/bench_add"
#: CDR encapsulation header (little-endian plain CDR), as rmw_zenoh writes it.
_CDR_LE = b"\x00\x01\x00\x00"


def _mangle(name: str) -> str:
    return name.replace("/", "%")


def _service_token(session: Any, name: str, timeout: float = 30.0) -> list[str]:
    """Return the parts of the liveliness token of service ``name`` (rmw_zenoh: ``SS``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.liveliness().get("@ros2_lv/**", timeout=2.0):
            if reply.ok is None:
                continue
            parts = str(reply.ok.key_expr).split("/")
            if len(parts) >= 13 and parts[5] == "SS" and parts[9] == _mangle(name):
                return parts
        time.sleep(0.2)
    msg = f"no ROS 2 service {name} appeared within {timeout} s"
    raise RuntimeError(msg)


def _zenoh_session(router: str) -> Any:
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([router]))
    conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _ros2_calls(session: Any, token: list[str], seconds: float) -> list[float]:
    """Call /add_two_ints over Zenoh as an rmw_zenoh client, one after the other.

    Returns each call's round trip in seconds (query sent -> reply read, sum checked).
    """
    domain, dds, type_hash = token[1], token[10], token[11]
    key = f"{domain}/{ADD_SERVICE.strip('/')}/{dds}/{type_hash}"
    gid = os.urandom(16)
    times: list[float] = []
    end = time.monotonic() + seconds
    sequence = 0
    while time.monotonic() < end:
        sequence += 1
        payload = _CDR_LE + struct.pack("<qq", sequence, 2)
        attachment = struct.pack("<qqB16s", sequence, time.time_ns(), 16, gid)
        t0 = time.perf_counter()
        replies = list(session.get(key, payload=payload, attachment=attachment, timeout=5.0))
        elapsed = time.perf_counter() - t0
        (reply,) = replies
        body = bytes(reply.ok.payload.to_bytes())
        (total,) = struct.unpack_from("<q", body, 4)
        if total != sequence + 2:
            msg = f"/add_two_ints answered {total} for {sequence} + 2"
            raise RuntimeError(msg)
        times.append(elapsed)
    return times


@contextmanager
def _ros2_provider(router: str, like: list[str]) -> Iterator[None]:
    """Provide ``/bench_add`` from this process as an rmw_zenoh server would.

    Its type, type hash and QoS are those of the token ``like`` (simbridge's /add_two_ints).
    """
    session = _zenoh_session(router)
    zid = str(session.info.zid())
    dds, type_hash, qos = like[10], like[11], like[12]
    head = f"@ros2_lv/0/{zid}/0"

    def answer(query: Any) -> None:
        body = bytes(query.payload.to_bytes())
        a, b = struct.unpack_from("<qq", body, 4)
        att = bytes(query.attachment.to_bytes())
        query.reply(query.key_expr, _CDR_LE + struct.pack("<q", a + b), attachment=att)

    key = f"0/{REMOTE_SERVICE.strip('/')}/{dds}/{type_hash}"
    queryable = session.declare_queryable(key, answer, complete=True)  # as rmw_zenoh declares it
    tokens = [
        session.liveliness().declare_token(f"{head}/0/NN/%/%/bench_server"),
        session.liveliness().declare_token(
            f"{head}/1/SS/%/%/bench_server/{_mangle(REMOTE_SERVICE)}/{dds}/{type_hash}/{qos}"
        ),
    ]
    try:
        yield
    finally:
        for token in tokens:
            token.undeclare()
        queryable.undeclare()
        session.close()


#: WebSocket connections the rosbridge rows take turns on: one client's calls in a row would
#: pass the server's per-client message_rate (1000 per second), which is not what is measured.
ROSBRIDGE_CONNECTIONS = 4


async def _rosbridge_calls(port: int, service: str, seconds: float) -> list[float]:
    """Call ``service`` (AddTwoInts) as rosbridge clients, one call after the other."""
    times: list[float] = []
    async with contextlib.AsyncExitStack() as stack:
        url = f"ws://127.0.0.1:{port}"
        sockets = [
            await stack.enter_async_context(connect(url, max_size=None))
            for _ in range(ROSBRIDGE_CONNECTIONS)
        ]
        end = time.monotonic() + seconds
        k = 0
        while time.monotonic() < end:
            k += 1
            ws = sockets[k % len(sockets)]
            op = {"op": "call_service", "service": service, "id": str(k), "args": {"a": k, "b": 2}}
            t0 = time.perf_counter()
            await ws.send(json.dumps(op))
            while True:
                reply = json.loads(await asyncio.wait_for(ws.recv(), 15))
                if reply.get("id") == str(k):
                    break
            times.append(time.perf_counter() - t0)
            if not reply.get("result") or reply["values"].get("sum") != k + 2:
                msg = f"{service} answered {reply!r} for {k} + 2"
                raise RuntimeError(msg)
    return times


def _per_call(
    proc: psutil.Process, idle: float, run: Callable[[], list[float]]
) -> tuple[list[float], float]:
    """Run ``run`` (sequential calls); return its round trips and the server's CPU s per call.

    ``idle`` is the server's CPU share with nobody calling, taken off its share during the run.
    """
    t0, c0 = time.monotonic(), cpu_seconds(proc)
    times = run()
    wall, cpu = time.monotonic() - t0, cpu_seconds(proc) - c0
    return times, max(cpu - idle * wall, 0.0) / max(len(times), 1)


#: One row of ``calls``: label, round trips (s), server CPU seconds per call.
_CallRow = tuple[str, list[float], float]


def _call_rows(tree: Path, seconds: float) -> tuple[float, list[_CallRow]]:
    """Run the ``calls`` rows against ``tree``'s simbridge; return its idle CPU and the rows."""
    with _router() as router, _simbridge(router, "--demo-nodes", tree=tree) as (proc, port):
        session = _zenoh_session(router)
        try:
            token = _service_token(session, ADD_SERVICE)
            _ros2_calls(session, token, 1.0)  # warm: the first query finds its route
            time.sleep(1)
            t0, c0 = time.monotonic(), cpu_seconds(proc)
            time.sleep(seconds)
            idle = (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
            rows: list[_CallRow] = []
            ros2, ros2_cpu = _per_call(proc, idle, lambda: _ros2_calls(session, token, seconds))
            rows.append(("ROS 2 -> simbridge (Zenoh)", ros2, ros2_cpu))
            local, local_cpu = _per_call(
                proc, idle, lambda: asyncio.run(_rosbridge_calls(port, ADD_SERVICE, seconds))
            )
            rows.append(("rosbridge -> simbridge", local, local_cpu))
            with _ros2_provider(router, token):
                _wait_service(port, REMOTE_SERVICE)
                asyncio.run(_rosbridge_calls(port, REMOTE_SERVICE, 1.0))  # warm
                remote, remote_cpu = _per_call(
                    proc, idle, lambda: asyncio.run(_rosbridge_calls(port, REMOTE_SERVICE, seconds))
                )
            rows.append(("rosbridge -> ROS 2 (Zenoh)", remote, remote_cpu))
        finally:
            session.close()
    return idle, rows


def calls(seconds: float) -> bool:
    """Service calls across Zenoh, one at a time, from each side (see the module doc).

    With ``SIMBRIDGE_BASELINE=DIR`` the rows run against that checkout's simbridge and this
    one's, alternating over ``ROUNDS`` rounds (default 2), each figure the median of its rounds,
    with the ratios current / baseline.
    """
    baseline = os.environ.get("SIMBRIDGE_BASELINE")
    trees = [("current", Path(os.environ.get("SIMBRIDGE_TREE") or ROOT))]
    if baseline:
        trees.insert(0, ("baseline", Path(baseline)))
    rounds = int(os.environ.get("ROUNDS", "2")) if baseline else 1
    results: dict[str, list[tuple[float, list[_CallRow]]]] = {label: [] for label, _ in trees}
    for k in range(rounds):
        for label, tree in trees if k % 2 == 0 else trees[::-1]:
            results[label].append(_call_rows(tree, seconds))
    print(
        f"zenoh calls: AddTwoInts one at a time, {seconds:g} s each, {rounds} round(s),"
        f" {load_average()}"
    )
    medians: dict[str, dict[str, tuple[float, float, float, float]]] = {}
    for label, tree in trees:
        idle = statistics.median(r[0] for r in results[label])
        print(f"{label}: simbridge of {tree}; nobody calling: server CPU {100 * idle:.1f} %")
        print(f"{'':28}{'calls':>8}{'calls/s':>9}{'p50 us':>9}{'p99 us':>9}{'CPU us/call':>13}")
        medians[label] = {}
        for i, (name, _, _) in enumerate(results[label][0][1]):
            runs = [r[1][i] for r in results[label]]
            count = statistics.median(len(t) for _, t, _ in runs)
            rate = statistics.median(len(t) / max(sum(t), 1e-9) for _, t, _ in runs)
            p50 = statistics.median(percentile(t, 0.5) for _, t, _ in runs) * 1e6
            p99 = statistics.median(percentile(t, 0.99) for _, t, _ in runs) * 1e6
            cpu = statistics.median(c for _, _, c in runs) * 1e6
            medians[label][name] = (rate, p50, p99, cpu)
            print(f"{name:28}{count:>8.0f}{rate:>9.0f}{p50:>9.0f}{p99:>9.0f}{cpu:>13.0f}")
    if baseline:
        print("current / baseline:")
        for name, (rate, p50, p99, cpu) in medians["current"].items():
            b = medians["baseline"][name]
            print(
                f"{name:28} calls/s {rate / b[0]:.2f}x, p50 {p50 / b[1]:.2f}x,"
                f" p99 {p99 / b[2]:.2f}x, server CPU per call {cpu / max(b[3], 1e-9):.2f}x"
            )
    return True


def _wait_service(port: int, name: str, timeout: float = 30.0) -> None:
    async def probe() -> None:
        deadline = time.monotonic() + timeout
        async with connect(f"ws://127.0.0.1:{port}") as ws:
            while time.monotonic() < deadline:
                op = {"op": "call_service", "service": "/rosapi/services", "id": "s"}
                await ws.send(json.dumps(op))
                reply = json.loads(await ws.recv())
                if name in reply.get("values", {}).get("services", []):
                    return
                await asyncio.sleep(0.3)
        msg = f"{name} did not reach simbridge within {timeout} s"
        raise RuntimeError(msg)

    asyncio.run(probe())


def _steal() -> float:
    """Seconds of CPU the hypervisor took from this machine so far (``/proc/stat``: steal)."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
    except OSError:
        return 0.0
    return int(fields[8]) / os.sysconf("SC_CLK_TCK") if len(fields) > 8 else 0.0


def _health(port: int) -> dict[str, Any]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=10) as answer:
        body: dict[str, Any] = json.loads(answer.read())
    return body


def _healths(
    sims: list[tuple[psutil.Process, int]], fronts: list[tuple[psutil.Process, int]]
) -> dict[str, list[dict[str, Any]]]:
    return {
        "simulators": [_health(port) for _, port in sims],
        "front-ends": [_health(port) for _, port in fronts],
    }


def _print_health(
    before: dict[str, list[dict[str, Any]]], after: dict[str, list[dict[str, Any]]]
) -> None:
    """Print what each simbridge process counted in the window (its /healthz, differenced).

    Where messages can be lost or wait: a simulator's skipped and late ticks (a tick skipped is
    a stamp missing for every client), the ring channels and inbox of a front-end's Zenoh link
    (samples dropped, sequence gaps seen in rmw_zenoh's attachments), its per-client send
    queues (frames dropped for a slow client).
    """
    print("per process, over the window (/healthz):")
    for kind, rows in after.items():
        for k, (a, b) in enumerate(zip(before[kind], rows, strict=True)):
            loop_a, loop_b = a["loop"], b["loop"]
            zenoh_a, zenoh_b = a.get("zenoh", {}), b.get("zenoh", {})

            def diff(x: dict[str, Any], y: dict[str, Any], key: str) -> int:
                return int(y.get(key, 0)) - int(x.get(key, 0))

            counts = {
                "ticks": diff(loop_a, loop_b, "ticks"),
                "late": diff(loop_a, loop_b, "late_ticks"),
                "skipped": diff(loop_a, loop_b, "skipped_ticks"),
                "published": diff(zenoh_a, zenoh_b, "published"),
                "received": diff(zenoh_a, zenoh_b, "received"),
                "missed": diff(zenoh_a, zenoh_b, "samples_missed"),
                "inbox dropped": diff(zenoh_a, zenoh_b, "samples_dropped"),
                "send dropped": diff(a, b, "dropped_frames"),
                "full passes": diff(zenoh_a, zenoh_b, "reconciles"),
            }
            shown = " ".join(f"{name} {v}" for name, v in counts.items() if v or name == "ticks")
            print(
                f"  {kind[:-1]} {k}: {shown}; tick lateness p99 {loop_b['lateness_ms_p99']} ms "
                f"max {loop_b['lateness_ms_max']} ms, work p99 {loop_b['work_ms_p99']} ms"
            )


def main(argv: list[str] | None = None) -> int:
    args = list(argv or [])
    parts = [a for a in args if a in ("hop", "outward", "classroom", "calls")] or ["hop", "outward"]
    numbers = [float(a) for a in args if a.replace(".", "", 1).isdigit()]
    seconds = numbers[0] if numbers else 20.0
    ok = True
    for part in parts:
        run = {"hop": hop, "outward": outward, "classroom": classroom, "calls": calls}[part]
        ok = run(seconds) and ok
        print()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
