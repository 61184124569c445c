"""ROS 2 over DDS (issue 25): the library's costs, outward publishing, /odom latency.

``python -m bench dds [lib|outward|latency|relay|stopped] [SECONDS]`` (default: all, 10 s).
The whole benchmark runs inside a network namespace of its own (it re-runs itself under
``unshare -n``, ``lo`` up with multicast): DDS discovery is multicast and must not reach the
machine's network.

* ``lib``: per DDS library, in a fresh process each: import time, resident memory of a process
  with one participant (idle), and CPU per Odometry written to one reader in another process:
  Cyclone DDS writing simbridge's CDR bytes (what ``--dds`` does), Cyclone DDS serializing its
  own typed sample, and dust-dds (the other Python DDS library with wheels) where it can.
* ``outward``: 30 robots; the server's CPU (its user + system seconds over the window's wall
  seconds) while one rosbridge client subscribes to every robot's /odom and /scan and /tf, then
  while one DDS subscriber (another process, one raw Cyclone reader per topic, counting) does;
  ``ROUNDS`` (default 3) alternating rounds, the median of the ratios. Target: DDS <= 1.0x.
* ``relay``: ``simbridge --dds --no-sim`` in front of a Fast DDS stand-in robot (the test peer
  ``build/ddspeer/ddspeer --robot``: /odom 20 Hz, /scan 10 Hz) relaying to 10 pages
  (``bench.loadgen`` clients on /odom and /scan): the server's CPU and RSS, and the CPU in Pi 4B
  cores (``bench pi``'s budget: one Pi core is 0.194 of a core here, docs/deploy.md), against
  rosbridge_suite's published Pi 4B figures (57 % CPU and 59 MB for one Foxglove client,
  v-kiniv/rws README).
* ``stopped``: 30 robots to one DDS subscriber that stops acknowledging after 3 s (``SIGSTOP``,
  as a laptop that sleeps or a ``ros2 topic echo`` stopped with Ctrl-Z): the longest gap
  between two /r1/odom at a rosbridge client of the same server, before and after. Target: no
  gap over 150 ms after the stop (the writers keep the last samples, they do not wait for it).
* ``latency``: one robot; /odom latency (arrival minus the header stamp, the wall clock when
  the server published it) of a rosbridge client and of a DDS subscriber of the same server,
  side by side. Target: DDS p99 <= 1.0x rosbridge's.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import psutil
from websockets.asyncio.client import connect

from bench import ros2outward
from bench.procs import ROOT, collect, cpu_seconds, load_average, percentile, start_loadgens
from bench.zenoh import _simbridge, _wait_topic, _world


DOMAIN = 77

LIB = r"""
import json, os, resource, sys, time
which = sys.argv[1]
t0 = time.perf_counter()
if which == "dust-dds":
    import dust_dds
else:
    import cyclonedds.domain, cyclonedds.pub, cyclonedds.sub, cyclonedds.topic
imported = time.perf_counter() - t0
def rss():
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmRSS")) / 1024
out = {"import_s": imported}
if which == "dust-dds":
    f = dust_dds.DomainParticipantFactory.get_instance()
    p = f.create_participant(domain_id=int(os.environ["DOMAIN"]))
    from dataclasses import dataclass
    K = dust_dds.TypeKind
    time.sleep(2); out["idle_rss_mb"] = rss()
    T = dataclass(type("nav_msgs::msg::dds_::Odometry_", (), {"__annotations__": {"x": K.float64}}))
    w = p.create_publisher().create_datawriter(p.create_topic("rt/odom", T))
    try:
        w.write(T(1.0)); out["write"] = "ok"
    except BaseException as e:
        out["write"] = f"cannot write a float64 member: {e}"
else:
    from cyclonedds.core import Policy, Qos
    from cyclonedds._clayer import ddspy_write
    p = cyclonedds.domain.DomainParticipant(int(os.environ["DOMAIN"]))
    time.sleep(2); out["idle_rss_mb"] = rss()  # the participant alone, as dust-dds's
    from simbridge.msgs import TypeRegistry
    from simbridge.msgs.cdr import CdrWriter
    from simbridge.ros2.dds.types import IdlTypes
    reg = TypeRegistry(); Odom = IdlTypes(reg).get("nav_msgs/msg/Odometry")
    q = Qos(Policy.Reliability.Reliable(100_000_000), Policy.History.KeepLast(10))
    w = cyclonedds.pub.DataWriter(p, cyclonedds.topic.Topic(p, "rt/odom", Odom), qos=q)
    while w.get_publication_matched_status().current_count < 1:
        time.sleep(0.05)
    from simbridge.msgs.convert import Converter
    fields = {"header": {"frame_id": "odom"}, "child_frame_id": "base_link"}
    msg = Converter(reg, lambda: (1, 2)).from_json("nav_msgs/msg/Odometry", fields)
    cdr = CdrWriter(reg)
    data = cdr.serialize("nav_msgs/msg/Odometry", msg)
    sample = Odom.deserialize(data)
    n = 20000
    c0 = time.process_time()
    if which == "cyclonedds-raw":
        for _ in range(n):
            ddspy_write(w._ref, cdr.serialize("nav_msgs/msg/Odometry", msg))
    else:
        for _ in range(n):
            w.write(sample)
    out["us_per_message"] = (time.process_time() - c0) / n * 1e6
print(json.dumps(out), flush=True)
"""

READER = r"""
import os, sys, time
from cyclonedds.domain import DomainParticipant
from cyclonedds.core import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from simbridge.msgs import TypeRegistry
from simbridge.ros2.dds.types import IdlTypes
types = IdlTypes(TypeRegistry())
p = DomainParticipant(int(os.environ["DOMAIN"]))
q = Qos(Policy.Reliability.Reliable(100_000_000), Policy.History.KeepLast(10))
r = DataReader(p, Topic(p, "rt/odom", types.get("nav_msgs/msg/Odometry")), qos=q)
while True:
    r.take(100)
    time.sleep(0.01)
"""


def lib() -> bool:
    env = {**os.environ, "DOMAIN": str(DOMAIN), "PYTHONPATH": str(ROOT)}
    rows = []
    for which in ("cyclonedds-raw", "cyclonedds-typed", "dust-dds"):
        reader = None
        if which != "dust-dds":
            reader = subprocess.Popen([sys.executable, "-c", READER], cwd=ROOT, env=env)
        try:
            done = subprocess.run(
                [sys.executable, "-c", LIB, which],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                timeout=120,
            )
        finally:
            if reader is not None:
                reader.kill()
                reader.wait()
        lines = done.stdout.strip().splitlines()
        rows.append((which, json.loads(lines[-1]) if lines else {"error": done.stderr[-300:]}))
    print(f"dds lib: one participant per process, one reader in another process, {load_average()}")
    print(f"{'':18}{'import s':>10}{'idle RSS MB':>13}{'us/Odometry':>13}  notes")
    for which, out in rows:
        us = out.get("us_per_message")
        note = out.get("write", out.get("error", ""))
        print(
            f"{which:18}{out.get('import_s', float('nan')):>10.3f}"
            f"{out.get('idle_rss_mb', float('nan')):>13.1f}"
            f"{us if us is not None else float('nan'):>13.2f}  {note}"
        )
    return True


SUBSCRIBER = r"""
import json, os, sys, time, threading
from cyclonedds.domain import DomainParticipant
from cyclonedds.core import Policy, Qos, Listener
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds._clayer import ddspy_take
from simbridge.msgs import TypeRegistry
from simbridge.ros2.dds.types import IdlTypes
names = json.loads(sys.argv[1]); seconds = float(sys.argv[2]); stamps = sys.argv[3] == "1"
types = IdlTypes(TypeRegistry())
p = DomainParticipant(int(os.environ["DOMAIN"]))
q = Qos(Policy.Reliability.Reliable(100_000_000), Policy.History.KeepLast(10))
count = [0]; lat = []
def on_data(reader):
    for data, info in ddspy_take(reader._ref, 0x7F, 64):
        count[0] += 1
        if stamps and info.valid_data:
            sec = int.from_bytes(data[4:8], "little", signed=True)
            nsec = int.from_bytes(data[8:12], "little")
            lat.append(time.time() - (sec + nsec * 1e-9))
readers = [
    DataReader(p, Topic(p, "rt/" + n.strip("/"), types.get(t)), qos=q,
               listener=Listener(on_data_available=on_data))
    for n, t in names
]
time.sleep(3)
start = count[0]; lat.clear()
print("start", flush=True)
time.sleep(seconds)
print(json.dumps({"messages": count[0] - start, "latencies": lat}), flush=True)
# leave as a node that shuts down does: killed, its participant stayed matched until its lease
# ran out (10 s), and the server wrote to it through the next rosbridge round's window
p.__del__()
os._exit(0)
"""


def _dds_subscriber(names: list[tuple[str, str]], seconds: float, stamps: bool = False) -> Any:
    env = {**os.environ, "DOMAIN": str(DOMAIN), "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-c", SUBSCRIBER, json.dumps(names), str(seconds), "1" if stamps else "0"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )


@contextlib.contextmanager
def _robots(n: int) -> Iterator[tuple[psutil.Process, int, list[tuple[str, str]]]]:
    """A ``--dds`` server of ``n`` robots: its process, its port, every robot's topics."""
    os.environ["ROS_DOMAIN_ID"] = str(DOMAIN)
    with tempfile.TemporaryDirectory() as tmp:
        world = _world(Path(tmp), "r", n, "outward")
        with _simbridge("", "--world", str(world), "--dds", zenoh=False) as (proc, port):
            yield proc, port, ros2outward.robot_topics(n)


def outward(seconds: float) -> bool:
    n = 30
    rounds = int(os.environ.get("ROUNDS", "3"))
    with _robots(n) as (proc, port, topics):
        time.sleep(3)
        idle = ros2outward.cpu_share(proc, seconds)
        results = ros2outward.compare_outward(
            proc, port, topics, seconds, rounds, lambda: _dds_subscriber(topics, seconds)
        )
    title = f"dds outward: {n} robots' /odom, /scan and /tf, {rounds} alternating rounds of"
    title += f" {seconds:g} s"
    return ros2outward.report_outward(title, idle, results, label="DDS", target=1.0)


def latency(seconds: float) -> bool:
    os.environ["ROS_DOMAIN_ID"] = str(DOMAIN)
    with _simbridge("", "--dds", zenoh=False) as (_proc, port):
        rosbridge: list[float] = []
        sub = _dds_subscriber([("/odom", "nav_msgs/msg/Odometry")], seconds, stamps=True)
        asyncio.run(ros2outward.rosbridge_latencies(port, "/odom", seconds, rosbridge, warmup=3))
        assert sub.stdout is not None
        sub.stdout.readline()
        dds = json.loads(sub.stdout.readline())["latencies"]
        sub.wait(timeout=30)
    print(f"dds latency: /odom of one robot, {seconds:g} s, {load_average()}")
    ros2outward.print_latencies([("rosbridge client", rosbridge), ("DDS subscriber", dds)], 22)
    ratio = percentile(dds, 0.99) / max(percentile(rosbridge, 0.99), 1e-9)
    ok = ratio <= 1.0
    print(f"DDS / rosbridge p99: {ratio:.2f}x; target <= 1.0x: {'met' if ok else 'NOT met'}")
    return ok


async def _odom_gaps(
    port: int, topic: str, before: float, after: float, stop: Callable[[], None]
) -> tuple[list[float], list[int]]:
    """Return the longest /odom gaps (s) at a rosbridge client before and after ``stop()``."""
    async with connect(f"ws://127.0.0.1:{port}", max_size=None) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
        await ws.recv()
        worst = [0.0, 0.0]
        counts = [0, 0]
        last = t0 = time.monotonic()
        phase = 0
        while time.monotonic() - t0 < before + after:
            await ws.recv()
            now = time.monotonic()
            worst[phase] = max(worst[phase], now - last)
            counts[phase] += 1
            last = now
            if phase == 0 and now - t0 >= before:
                stop()
                phase = 1
    return worst, counts


def stopped(seconds: float) -> bool:
    """30 robots to a DDS subscriber that stops acknowledging (SIGSTOP): does the loop stall?"""
    with _robots(30) as (proc, port, topics):
        time.sleep(2)
        sub = _dds_subscriber(topics, 3 * seconds + 60)
        assert sub.stdout is not None
        sub.stdout.readline()  # matched and reading

        def stop() -> None:
            os.kill(sub.pid, signal.SIGSTOP)

        try:
            c0 = cpu_seconds(proc)
            worst, counts = asyncio.run(_odom_gaps(port, "/r1/odom", 3, seconds, stop))
            cpu = (cpu_seconds(proc) - c0) / (3 + seconds)
        finally:
            sub.kill()
            sub.wait()
    print(
        f"dds stopped: 30 robots' /odom, /scan and /tf to a DDS subscriber stopped (SIGSTOP)"
        f" after 3 s, then {seconds:g} s; {load_average()}"
    )
    print(f"{'':34}{'messages':>10}{'longest gap ms':>16}")
    print(f"{'/r1/odom at a rosbridge client, before':34}{counts[0]:>10}{1000 * worst[0]:>16.0f}")
    print(f"{'/r1/odom at a rosbridge client, after':34}{counts[1]:>10}{1000 * worst[1]:>16.0f}")
    print(f"server CPU over both: {100 * cpu:.1f} % of a core")
    ok = worst[1] <= 0.15
    print(f"longest gap after the stop <= 150 ms (3 periods): {'met' if ok else 'NOT met'}")
    return ok


#: One Raspberry Pi 4B core in cores of this machine (bench pi's fixed budget).
PI_CORE = 0.194


def relay(seconds: float) -> bool:
    peer_bin = ROOT / "build" / "ddspeer" / "ddspeer"
    if not peer_bin.exists():
        print("dds relay: build/ddspeer/ddspeer is not built (make deps): skipped")
        return True
    os.environ["ROS_DOMAIN_ID"] = str(DOMAIN)
    robot = subprocess.Popen(
        [str(peer_bin), "--domain", str(DOMAIN), "--robot", "--node", "robot"],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
    )
    try:
        with _simbridge("", "--dds", "--no-sim", zenoh=False) as (proc, port):
            _wait_topic(port, "/scan")
            time.sleep(2)
            t0, c0 = time.monotonic(), cpu_seconds(proc)
            time.sleep(seconds)
            idle = (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
            idle_rss = proc.memory_info().rss / 1e6
            clients = [{"subscribe": ["/odom", "/scan"], "drive": None} for _ in range(10)]
            start = time.time() + 3
            gens = start_loadgens(f"ws://127.0.0.1:{port}", clients, 1, start, start + seconds)
            time.sleep(max(0.0, start - time.time()))
            t0, c0 = time.monotonic(), cpu_seconds(proc)
            time.sleep(seconds)
            busy = (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
            rss = proc.memory_info().rss / 1e6
            results = collect(gens, seconds + 90)
    finally:
        robot.kill()
        robot.wait()
    odom = [len(r["stamps"].get("/odom", [])) / seconds for r in results]
    print(f"dds relay: --dds --no-sim in front of a Fast DDS robot, 10 pages, {seconds:g} s")
    print(f"{'':28}{'CPU % of a core':>16}{'Pi 4B cores':>13}{'RSS MB':>9}")
    print(f"{'idle (robot, no page)':28}{100 * idle:>16.1f}{idle / PI_CORE:>13.2f}{idle_rss:>9.1f}")
    print(f"{'10 pages on /odom + /scan':28}{100 * busy:>16.1f}{busy / PI_CORE:>13.2f}{rss:>9.1f}")
    print(f"/odom per page: {min(odom):.1f}-{max(odom):.1f} Hz")
    print("rosbridge_suite on a Pi 4B (v-kiniv/rws README): 57 % CPU and 59 MB for one client")
    return busy / PI_CORE <= 1.0


def _in_netns(argv: list[str]) -> int:
    """Run this benchmark again inside a new network namespace (lo only, multicast on)."""
    script = textwrap.dedent(
        """
        ip link set lo up multicast on && ip route add 224.0.0.0/4 dev lo && exec "$@"
        """
    )
    cmd = ["unshare", "-n", "sh", "-c", script, "sh", sys.executable, "-m", "bench.dds", *argv]
    return subprocess.run(cmd, cwd=ROOT, env={**os.environ, "BENCH_DDS_NETNS": "1"}).returncode


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not os.environ.get("BENCH_DDS_NETNS"):
        return _in_netns(argv)
    seconds = next((float(a) for a in argv if a.replace(".", "", 1).isdigit()), 10.0)
    every = ("lib", "outward", "latency", "relay", "stopped")
    names = [a for a in argv if a in every] or list(every)
    ok = True
    for name in names:
        run = {
            "lib": lambda _s: lib(),
            "outward": outward,
            "latency": latency,
            "relay": relay,
            "stopped": stopped,
        }
        ok = run[name](seconds) and ok
        print()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
