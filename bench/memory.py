"""Where an idle default server's memory goes: each import group's share, and what was cut.

``python -m bench memory`` (about a minute): five tables, each from fresh child processes.

1. **Import groups**, in the order ``simbridge`` imports them, in one child: VmRSS and its two
   parts after each group (RssAnon: the process's own memory; RssFile: the mapped pages of
   shared libraries), as the increase over the group before. The child imports asyncio the way
   the command does (without ssl when no TLS is served).
2. **Cut from the default path** (issue 16): what each module the default run no longer imports
   would add on top of the whole default path (same child, after the groups).
3. **The idle server**: ``simbridge`` with the default world and both ports, no client, settled
   (VmRSS readings 0.5 s apart within 0.1 MB), as tests/test_footprint.py measures it; beside the
   same server with the cut modules imported first (the default path as it was before the cuts),
   with the ratio. MB here are MiB (VmRSS / 1024), as in the test. Twice: with the page cache
   as found, then with the server's shared libraries evicted from it (read back from disk).
   "Before" only imports the cut modules (one not installed is skipped). pydantic is back on
   the default path since issue 24 (the settings are declared on it): its cost is the first
   table's row of the settings.
4. **Exclusive shares**: a child imports the modules the idle server imported, in its order
   (not simbridge's own), once with everything and once without each large package (and so
   without what only that package imports): the difference is what that package alone costs,
   where the first table charges a shared module to whichever imports it first. The idle
   server minus that child is simbridge's own code and what it builds at start.
5. **With a client**: the same server idle, then with a page's session (subscribed to /odom,
   /scan and /tf, publishing /cmd_vel, its first rosapi call made), settled, connected; and
   which of rosbags' modules it has imported by then (none: the definitions are shipped; rosbags'
   type store is made only for a type only rosbags serializes, a text not shipped parsed,
   ``--zenoh`` or a bag).

RssFile depends on the page cache: a library pip has just written is cached in large folios
(Linux 6.16+ ext4), and a fault maps a whole folio, so a fresh venv shows several MB more RssFile
than one whose libraries were read back from disk (see tests/test_footprint.py); the second
table shows the latter, what a venv shows once the libraries have left the cache (a reboot,
memory pressure). RssAnon does not depend on it.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any


ROOT = Path(__file__).resolve().parent.parent

#: The default path's import groups, in the order ``simbridge`` imports them.
GROUPS: list[tuple[str, list[str]]] = [
    ("simbridge.cli (argparse, logging)", ["simbridge.cli"]),
    ("hashlib, hmac, secrets (CPython's own hashes)", ["@hashlib", "secrets"]),
    ("simbridge.app.settings, simbridge.app.config (pydantic)", ["simbridge.app.config"]),
    ("importlib.metadata (websockets' version lookup)", ["importlib.metadata"]),
    ("asyncio (no ssl)", ["@asyncio"]),
    ("numpy", ["numpy"]),
    ("simbridge.msgs (orjson, the shipped definitions)", ["simbridge.msgs", "@definitions"]),
    ("simbridge.rosbridge", ["simbridge.rosbridge"]),
    ("simbridge.sim", ["simbridge.sim"]),
    ("simbridge.graph", ["simbridge.graph", "simbridge.robot.assembly"]),
    ("websockets", ["websockets.asyncio.server"]),
    ("server, web (httptools), runner", ["simbridge.rosbridge.server", "simbridge.app.runner"]),
]

#: Modules issue 16 took off the default path, and when a run still imports them.
CUT: list[tuple[str, str]] = [
    ("_hashlib", "never (OpenSSL's hashes; a TLS run loads libcrypto through ssl)"),
    ("ssl", "only with --certfile (asyncio's TLS)"),
    ("numpy.random", "only with LiDAR noise > 0"),
    ("cbor2", "only with a cbor / cbor-raw subscription"),
    ("simbridge.robot.tutorials", "only with --demo-nodes"),
    ("yaml", "only with a --world, --params or --client-tokens file (and the YAML tools)"),
    ("pydantic_settings", "only with a SIMBRIDGE_* variable set (the environment's reader)"),
    ("simbridge.msgs.cdr", "only with a cbor-raw subscription, --zenoh or a bag (the CDR codec)"),
    (
        "rosbags.typesys",
        "only to parse a .msg text not shipped parsed, or with the store (rosbags' parser, serde)",
    ),
    (
        "rosbags.typesys.stores.ros2_kilted",
        "only for a type only rosbags serializes (wstring to cbor-raw), --zenoh, bags (the store)",
    ),
]

_GROUPS_CHILD = r"""
import importlib, json, sys

def status():
    with open("/proc/self/status") as f:
        kb = {k: int(v.split()[0]) for k, _, v in (ln.partition(":") for ln in f)
              if k in ("VmRSS", "RssAnon", "RssFile")}
    return kb["VmRSS"] / 1024, kb["RssAnon"] / 1024, kb["RssFile"] / 1024

rows = [("interpreter (python -c)", status())]
for label, modules in json.loads(sys.argv[1]):
    for name in modules:
        if name == "@asyncio":
            from simbridge.app.tuning import import_asyncio
            import_asyncio(tls=False)
        elif name == "@hashlib":
            from simbridge.app.tuning import import_hashlib
            import_hashlib()
        elif name == "@definitions":  # loaded by the first registry, at start
            from simbridge.msgs.definitions import standard
            standard()
        else:
            importlib.import_module(name)
    rows.append((label, status()))
for name, _ in json.loads(sys.argv[2]):
    before = status()
    try:
        importlib.import_module(name)
    except ImportError:  # an optional package not installed
        rows.append(("+" + name + " (not installed)", (0.0, 0.0, 0.0)))
        continue
    after = status()
    rows.append(("+" + name, tuple(a - b for a, b in zip(after, before))))
print(json.dumps(rows))
"""

_SERVER_CHILD = r"""
import importlib, json, os, signal, socket, sys, threading, time

port, http_port, preload = int(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3])
for name in preload:  # the modules the default path no longer imports, as before the cuts
    try:
        importlib.import_module(name)
    except ImportError:  # an optional package not installed
        pass


def status():
    with open("/proc/self/status") as f:
        kb = {k: int(v.split()[0]) for k, _, v in (ln.partition(":") for ln in f)
              if k in ("VmRSS", "RssAnon", "RssFile")}
    return kb["VmRSS"] / 1024, kb["RssAnon"] / 1024, kb["RssFile"] / 1024


def watch():
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            time.sleep(0.05)
    last = status()[0]
    while time.monotonic() < deadline:
        time.sleep(0.5)
        now = status()[0]
        if abs(now - last) < 0.1:
            break
        last = now
    with open("/proc/self/maps") as f:
        files = sorted({ln.split()[5] for ln in f if len(ln.split()) > 5 and ".so" in ln})
    print("MEMORY " + json.dumps([status(), list(sys.modules), files]), file=sys.stderr, flush=True)
    os.kill(os.getpid(), signal.SIGINT)


threading.Thread(target=watch, daemon=True).start()
from simbridge.cli import main

sys.exit(main(["--host", "127.0.0.1", "--port", str(port), "--http-port", http_port]))
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def groups() -> list[tuple[str, tuple[float, float, float]]]:
    """Cumulative (RSS, anon, file) MB after each import group, then each cut module's delta."""
    proc = subprocess.run(
        [sys.executable, "-c", _GROUPS_CHILD, json.dumps(GROUPS), json.dumps(CUT)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=True,
    )
    return [(label, (r, a, f)) for label, (r, a, f) in json.loads(proc.stdout)]


def idle_server(
    preload: list[str], tree: Path | None = None
) -> tuple[tuple[float, float, float], list[str], list[str]]:
    """(RSS, anon, file) MB, the modules (in import order) and shared libraries of the server.

    ``tree``: that source tree's simbridge with this interpreter (first on ``PYTHONPATH``).
    """
    cmd = [sys.executable, "-c", _SERVER_CHILD, str(_free_port()), str(_free_port())]
    env = None
    if tree is not None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [env.get("PYTHONPATH")])])
    proc = subprocess.run(
        [*cmd, json.dumps(preload)],
        capture_output=True,
        text=True,
        cwd=tree or ROOT,
        env=env,
        timeout=180,
    )
    line = next((ln for ln in proc.stderr.splitlines() if ln.startswith("MEMORY ")), None)
    if line is None:
        raise RuntimeError(proc.stderr[-2000:])
    (rss, anon, file), modules, libraries = json.loads(line[len("MEMORY ") :])
    return (rss, anon, file), modules, libraries


def evict(paths: list[str]) -> int:
    """Drop the page-cache pages of ``paths`` that no process maps (``posix_fadvise``).

    The next run reads them back from disk, in the small folios a long-running system has:
    what a venv installed days ago (or before a reboot) shows, not what pip has just written.
    """
    dropped = 0
    for path in paths:
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            continue
        try:
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
            dropped += 1
        finally:
            os.close(fd)
    return dropped


#: Packages of the default path whose exclusive share the last table shows: what the idle
#: server's imports weigh without them (and without what only they import).
EXCLUSIVE: list[tuple[str, list[str]]] = [
    ("numpy (with OpenBLAS)", ["numpy"]),
    ("websockets", ["websockets"]),
    ("orjson", ["orjson"]),
    ("httptools", ["httptools"]),
]

_IMPORTS_CHILD = r"""
import ctypes, importlib, json, sys

modules, excluded, own = json.loads(sys.argv[1]), tuple(json.loads(sys.argv[2])), sys.argv[3]
skipped = ("__main__",) if own == "own" else ("__main__", "simbridge")
from simbridge.app.tuning import import_asyncio, import_hashlib  # as the command imports them
import_hashlib()
import_asyncio(tls=False)
for name in modules:
    if name.startswith(skipped) or name.split(".")[0] in excluded or any(
        name.startswith(e + ".") or name == e for e in excluded
    ):
        continue  # a module an excluded package alone imports is not imported at all
    try:
        importlib.import_module(name)
    except Exception:
        pass  # e.g. a Cython runtime module that registers itself without a spec
ctypes.CDLL(None).malloc_trim(0)
with open("/proc/self/status") as f:
    kb = {k: int(v.split()[0]) for k, _, v in (ln.partition(":") for ln in f)
          if k in ("VmRSS", "RssAnon", "RssFile")}
print(json.dumps([kb["VmRSS"] / 1024, kb["RssAnon"] / 1024, kb["RssFile"] / 1024]))
"""


def imports_only(
    modules: list[str], excluded: list[str], *, own: bool = False
) -> tuple[float, float, float]:
    """(RSS, anon, file) MB of a child importing ``modules`` but ``excluded``.

    simbridge's own modules only with ``own``; nothing runs.
    """
    args = [json.dumps(modules), json.dumps(excluded), "own" if own else "others"]
    proc = subprocess.run(
        [sys.executable, "-c", _IMPORTS_CHILD, *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=True,
    )
    rss, anon, file = json.loads(proc.stdout)
    return rss, anon, file


def _exclusive_table(modules: list[str], idle: tuple[float, float, float]) -> None:
    """Print what the idle server weighs by part: each package's exclusive share."""
    interpreter = groups()[0][1]
    everything = imports_only(modules, [])
    with_own = imports_only(modules, [], own=True)
    print("where the idle server's memory goes: exclusive shares (MB; libraries read from disk)")
    print(f"{'part':<52} {'RSS':>8} {'RssAnon':>8} {'RssFile':>8}")
    print(_row("the idle server (median above)", idle))
    print(_row("  the interpreter alone (python -c)", interpreter, "+"))
    shared = _minus(everything, interpreter)
    for label, excluded in EXCLUSIVE:
        share = _minus(everything, imports_only(modules, excluded))
        shared = _minus(shared, share)
        print(_row(f"  {label}", share, "+"))
    print(_row("  the standard library modules they share", shared, "+"))
    print(_row("  simbridge's own modules", _minus(with_own, everything), "+"))
    print(_row("  what simbridge builds at start and runs with", _minus(idle, with_own), "+"))


_SESSION_CHILD = r"""
import json, os, signal, sys, threading, time

port, http_port, work = int(sys.argv[1]), sys.argv[2], sys.argv[3]


def status():
    with open("/proc/self/status") as f:
        kb = {k: int(v.split()[0]) for k, _, v in (ln.partition(":") for ln in f)
              if k in ("VmRSS", "RssAnon", "RssFile")}
    return kb["VmRSS"] / 1024, kb["RssAnon"] / 1024, kb["RssFile"] / 1024


def settled():
    last = status()[0]
    for _ in range(60):
        time.sleep(0.5)
        now = status()[0]
        if abs(now - last) < 0.1:
            break
        last = now
    return status()


def serve():  # report-N.json when ask-N appears; stop at "stop"
    deadline, n = time.monotonic() + 300, 0
    while time.monotonic() < deadline and not os.path.exists(os.path.join(work, "stop")):
        if os.path.exists(os.path.join(work, f"ask-{n}")):
            values = settled()
            rosbags = sorted(m for m in sys.modules if m.startswith("rosbags"))
            with open(os.path.join(work, f"report-{n}.tmp"), "w") as out:
                json.dump([values, rosbags], out)
            os.rename(os.path.join(work, f"report-{n}.tmp"), os.path.join(work, f"report-{n}.json"))
            n += 1
        time.sleep(0.02)
    os.kill(os.getpid(), signal.SIGINT)


threading.Thread(target=serve, daemon=True).start()
from simbridge.cli import main

sys.exit(main(["--host", "127.0.0.1", "--port", str(port), "--http-port", http_port]))
"""


def _ask(work: Path, n: int) -> tuple[tuple[float, float, float], list[str]]:
    """Ask the session child for report ``n``; wait for it."""
    (work / f"ask-{n}").touch()
    path = work / f"report-{n}.json"
    deadline = time.monotonic() + 60
    while not path.exists():
        if time.monotonic() > deadline:
            raise RuntimeError("the server did not report")
        time.sleep(0.05)
    (rss, anon, file), rosbags = json.loads(path.read_text())
    return (rss, anon, file), rosbags


def _session(port: int, work: Path) -> tuple[tuple[float, float, float], list[str]]:
    """A page's session on the default world; the server's report while it is connected."""
    from websockets.sync.client import connect

    def until(conn: Any, wanted: Any) -> None:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            value = json.loads(conn.recv(timeout=deadline - time.monotonic()))
            if wanted(value):
                return
        raise RuntimeError("no answer")

    with connect(f"ws://127.0.0.1:{port}", max_size=None) as page:
        page.send(json.dumps({"op": "call_service", "id": "t", "service": "/rosapi/topics"}))
        until(page, lambda m: m.get("op") == "service_response")
        for topic in ("/odom", "/scan", "/tf"):
            page.send(json.dumps({"op": "subscribe", "topic": topic}))
            until(page, lambda m, t=topic: m.get("topic") == t)
        twist = {"linear": {"x": 0.2}, "angular": {"z": 0.5}}
        page.send(
            json.dumps({"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
        )
        for _ in range(20):
            page.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": twist}))
            until(page, lambda m: m.get("topic") == "/odom")

        def drain() -> None:  # the page keeps reading while the server settles
            with contextlib.suppress(Exception):
                while True:
                    page.recv()

        reader = threading.Thread(target=drain, daemon=True)
        reader.start()
        report = _ask(work, 1)
    reader.join(timeout=10)
    return report


def client_session() -> list[tuple[str, tuple[float, float, float], list[str]]]:
    """The server idle, then with a page connected: (RSS, anon, file) MB, rosbags modules."""
    with tempfile.TemporaryDirectory() as tmp:
        work, port = Path(tmp), _free_port()
        cmd = [sys.executable, "-c", _SESSION_CHILD, str(port), str(_free_port()), tmp]
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 120
            while True:
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=1).close()
                    break
                except OSError:
                    if time.monotonic() > deadline or proc.poll() is not None:
                        raise RuntimeError("the server did not start") from None
                    time.sleep(0.05)
            idle = _ask(work, 0)
            session = _session(port, work)
        finally:
            (work / "stop").touch()
            proc.wait(timeout=60)
    return [("idle", *idle), ("a page connected (its session done)", *session)]


def _client_table() -> None:
    print("the server with a client: a page subscribed to /odom, /scan, /tf, publishing /cmd_vel")
    print(f"{'case':<52} {'RSS':>8} {'RssAnon':>8} {'RssFile':>8}  rosbags modules imported")
    for label, values, rosbags in client_session():
        store = "the ROS 2 store" if any(".stores.ros2" in m for m in rosbags) else "no store"
        print(f"{_row(label, values)}  {len(rosbags)} ({store})")


def _minus(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> tuple[float, float, float]:
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


def _row(label: str, values: tuple[float, float, float], sign: str = "") -> str:
    rss, anon, file = values
    return f"{label:<52} {rss:{sign}8.1f} {anon:{sign}8.1f} {file:{sign}8.1f}"


def _idle_table(title: str) -> tuple[tuple[float, float, float], list[str], list[str]]:
    """Run the idle server 3 times as now and as before the cuts; print medians and ratios.

    Returns the median now, the modules it imported (in order) and the libraries mapped.
    """
    cases = (
        ("before the cuts (cut modules imported first)", [name for name, _ in CUT]),
        ("now", []),
    )
    runs = {name: [idle_server(preload) for _ in range(3)] for name, preload in cases}
    print(f"the idle server, {title} (MB; median of 3)")
    print(f"{'case':<52} {'RSS':>8} {'RssAnon':>8} {'RssFile':>8} {'modules':>8}")
    medians = []
    for name, results in runs.items():
        values, modules, _ = sorted(results)[len(results) // 2]
        medians.append(values)
        print(f"{_row(name, values)} {len(modules):>8}")
    before, now = medians
    print(
        f"{'ratio now / before':<52} {now[0] / before[0]:8.2f} {now[1] / before[1]:8.2f} "
        f"{now[2] / before[2]:8.2f}"
    )
    libraries = sorted({lib for results in runs.values() for _, _, libs in results for lib in libs})
    return now, runs["now"][0][1], libraries


def main(argv: list[str] | None = None) -> int:
    del argv
    rows = groups()
    print("idle default server: each import group's share (MB; one child, in import order)")
    print(f"{'group':<52} {'RSS':>8} {'RssAnon':>8} {'RssFile':>8}")
    groups_rows = rows[: len(GROUPS) + 1]
    previous = (0.0, 0.0, 0.0)
    for label, values in groups_rows:
        share = tuple(v - p for v, p in zip(values, previous, strict=True))
        print(_row(label, share, "+") if previous[0] else _row(label, values))
        previous = values
    print(_row("= the default path's imports, together", previous))
    print()
    print("cut from the default path (issue 16): what each would add on top (MB), and when")
    for (label, values), (_name, when) in zip(rows[len(GROUPS) + 1 :], CUT, strict=True):
        print(f"{_row(label, values, '+')}  {when}")
    print()
    print(f"simbridge, default world, both ports, no client (load average {_load()})")
    _, _, libraries = _idle_table("page cache as found")
    print()
    dropped = evict(libraries)
    print(f"evicted {dropped} shared libraries from the page cache (read back from disk)")
    idle, modules, _ = _idle_table("libraries read back from disk (a venv not freshly installed)")
    print("target (issue 16): <= 40 MB RSS")
    print()
    _exclusive_table(modules, idle)
    print()
    _client_table()
    return 0


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


if __name__ == "__main__":
    sys.exit(main())
