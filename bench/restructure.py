"""Issue 24's figures, before and after the restructure, side by side in one run with ratios.

    python -m bench restructure [--baseline REV] [--current REV] [--only NAME,...]
                                [--rounds N] [--seconds S] [--zenoh-rounds N] [--zenoh-seconds S]

The baseline (default ``e8f8787``, main before the restructure) is checked out by this
benchmark with ``git worktree add --detach`` into a temporary directory, removed afterwards;
the current tree is this checkout (as it is on disk), or ``--current REV`` checked out the same
way. Both run with this interpreter (and its virtualenv's packages), each tree first on
``PYTHONPATH`` and as the working directory (:func:`bench.procs.tree_env`), so that each runs
its own ``simbridge``; every measurement runs in fresh processes, so the two trees never share
one. The runs alternate (baseline first, then current first...) ``--rounds`` times (default 3;
the machine is shared and noisy; ``--zenoh-rounds``, default 2, for the Zenoh benchmark, the
longest), and each figure is the median of its runs. About 10 minutes with the defaults.

Only what both trees have in common is used: the ``simbridge`` command (``python -m
simbridge``, ``simbridge zenohd``), ``simbridge.cli.main``, ``simbridge.headless.Simulation``
and the rosbridge wire; where a measurement needs the package's insides (the in-process publish,
the Zenoh benchmark's ROS 2 subscriber) each tree's own ``bench`` module runs and its output is
read. The measurements (``--only`` picks some, comma-separated):

* ``fanout``: 100 clients on /odom + /scan for ``--seconds`` (default 10; two load-generator
  processes, :func:`bench.fanout.phase`): the server's CPU (its own user + system seconds per
  second), latency p50 and p99 (receive minus the header stamp), messages lost.
* ``publish``: one ``/cmd_vel`` publish op in microseconds, twice: in-process through the graph
  (each tree's ``bench.publish``: median us per op, no sockets), and over the wire (10 clients
  publishing /cmd_vel at 150 Hz each to a server process for 6 s: the server's CPU while they
  publish minus its CPU idle over as long, per publish).
* ``headless``: ``Simulation.step`` steps per CPU second of the process (the best of 7
  batches of at least 0.1 s: a busy neighbour only slows a batch down; 3x ``--rounds`` runs),
  with no subscriber and with /odom + /scan + /tf + /clock subscribed.
* ``zenoh``: each tree's ``bench.zenoh outward`` for ``--zenoh-seconds`` (default 6;
  ``ROUNDS`` 2 inside each run, alternating which client goes first) and ``bench.zenoh hop``
  for 12 s (a p99 of 240 /odom messages): the server CPU to one ROS 2 subscriber vs one
  rosbridge client of 30 robots' topics (issue 24's target: <= 1.0x once the JSON round trip
  is gone), and the /odom p99 through a Zenoh hop.
* ``memory``: the idle default server's RSS (both ports, no client, settled: :func:`bench.
  memory.idle_server`), MB = MiB as in tests/test_footprint.py; which pydantic modules it
  imported. Issue 24's target: under 60 MB with pydantic back.
* ``pi``: cold start (spawn ``simbridge`` -> the first /odom on a client, :func:`bench.pi.
  cold_start`; the median of 3 in each run) without a limit and inside a Raspberry Pi 4B core's
  CPU budget (root, for the cgroup): 0.194 of a core here, docs/deploy.md's calibration, so that
  runs of this benchmark at different times compare (``PI_CORES=N`` another budget,
  ``PI_CORES=calibrate`` :func:`bench.pi.calibrate` now).

Ratios are current / baseline: times, CPU and memory want below 1, rates above 1 (the column
``better`` says which).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.procs import ROOT, cpu_seconds, load_average, server, tree_env


#: main before the restructure of issue 24.
DEFAULT_BASELINE = "e8f8787"

#: The measurements, in the order they run: name -> what it measures.
MEASUREMENTS = {
    "fanout": "100 clients on /odom + /scan: server CPU, latency p50 / p99",
    "publish": "a /cmd_vel publish: in-process (us per op) and over the wire (server CPU us)",
    "headless": "headless steps per CPU second",
    "zenoh": "server CPU to a ROS 2 subscriber vs a rosbridge client; the Zenoh hop's p99",
    "memory": "idle RSS of the default server; pydantic modules it imports",
    "pi": "cold start without a limit and in a Pi 4B core's CPU budget",
}


@dataclass
class Tree:
    """A source tree of simbridge: ``label`` (baseline or current), where, which commit."""

    label: str
    path: Path
    commit: str
    subject: str


@dataclass
class Figure:
    """One figure's runs in both trees."""

    name: str
    unit: str
    better: str  # "lower" or "higher"
    digits: int = 1
    runs: dict[str, list[float]] = field(default_factory=lambda: {"baseline": [], "current": []})
    errors: dict[str, str] = field(default_factory=dict)

    def median(self, label: str) -> float | None:
        values = self.runs[label]
        return statistics.median(values) if values else None

    def row(self) -> str:
        b, c = self.median("baseline"), self.median("current")
        if b is not None and b == c:
            ratio = "same"
        else:
            ratio = f"{c / b:.2f}x" if b and c is not None else "n/a"
        cells = [_cell(v, self.digits) for v in (b, c)]
        runs = " | ".join(
            " ".join(_cell(v, self.digits).strip() for v in self.runs[label]) or "-"
            for label in ("baseline", "current")
        )
        label = f"{self.name} ({self.unit})"
        return f"{label:<56} {cells[0]:>9} {cells[1]:>9} {ratio:>7}  {self.better:<6}  runs {runs}"


def _cell(value: float | None, digits: int) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


HEADER = f"{'figure (unit)':<56} {'baseline':>9} {'current':>9} {'ratio':>7}  better"


# -- the trees -----------------------------------------------------------------------------------


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(
        ["git", *args], cwd=cwd, capture_output=True, text=True, check=True
    ).stdout.strip()


def _describe(label: str, path: Path) -> Tree:
    commit = _git("rev-parse", "--short", "HEAD", cwd=path)
    if label == "current" and _git("status", "--porcelain", "--untracked-files=no", cwd=path):
        commit += "+changes"
    subject = _git("log", "-1", "--format=%s", cwd=path)
    return Tree(label, path, commit, subject[:70])


@contextlib.contextmanager
def checkout(rev: str) -> Iterator[Path]:
    """``rev`` checked out (detached) into a temporary directory; removed afterwards."""
    parent = Path(tempfile.mkdtemp(prefix="simbridge-restructure-"))
    path = parent / "tree"
    _git("worktree", "add", "--detach", "--quiet", str(path), rev)
    try:
        yield path
    finally:
        subprocess.run(
            ["git", "worktree", "remove", "--force", str(path)],
            cwd=ROOT,
            capture_output=True,
            check=False,
        )
        shutil.rmtree(parent, ignore_errors=True)
        subprocess.run(["git", "worktree", "prune"], cwd=ROOT, capture_output=True, check=False)


def _check_import(tree: Tree) -> None:
    """Fail unless ``python -c 'import simbridge'`` in ``tree``'s environment imports its own."""
    cwd, env = tree_env(tree.path)
    out = subprocess.run(
        [sys.executable, "-c", "import simbridge; print(simbridge.__file__)"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    if not Path(out).resolve().is_relative_to(tree.path.resolve()):
        msg = f"the {tree.label} tree imports simbridge from {out}, not from {tree.path}"
        raise SystemExit(msg)


def _run_python(tree: Tree, args: list[str], *, timeout: float, **env: str) -> str:
    """Run this interpreter with ``args`` in ``tree``'s environment; return its stdout.

    Raises:
        RuntimeError: it exited non-zero with nothing on stdout (its stderr's last lines).
    """
    cwd, environ = tree_env(tree.path)
    environ.update(env)
    proc = subprocess.run(
        [sys.executable, *args],
        cwd=cwd,
        env=environ,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    if proc.returncode != 0 and not proc.stdout.strip():
        tail = " / ".join(proc.stderr.strip().splitlines()[-2:])
        msg = f"exit {proc.returncode}: {tail}"
        raise RuntimeError(msg)
    return proc.stdout


# -- the measurements: each runs once in one tree and returns its figures ------------------------


@dataclass
class Options:
    seconds: float = 10.0  # the fanout's window
    wire_seconds: float = 6.0  # the wire publish's (idle, then publishing)
    zenoh_seconds: float = 6.0  # bench.zenoh outward's window
    hop_seconds: float = 12.0  # bench.zenoh hop's (its p99 from 20 Hz of /odom)
    zenoh_rounds: int = 2  # runs of bench.zenoh in each tree (each with ROUNDS 2 inside)
    #: the Pi 4B budget in cores here: docs/deploy.md's calibration, the same in every run
    #: (``PI_CORES`` sets another; ``PI_CORES=calibrate`` measures it now, bench.pi.calibrate)
    pi_cores: float | None = 0.194
    budget: Any = None  # bench.pi.CpuBudget, made once


def measure_fanout(tree: Tree, opts: Options) -> dict[str, float]:
    from bench.fanout import phase

    r = phase("simbridge", 100, opts.seconds, tree=tree.path)
    return {
        "cpu": r["cpu"] * 100,
        "p50": r["p50"],
        "p99": r["p99"],
        "lost": float(r["missing"] + (r["dropped"] or 0) + r["errors"]),
    }


_PUBLISH_ROW = re.compile(r"^(/cmd_vel|/chatter x10|bad payload)\s+(\d+(?:\.\d+)?)\s*$", re.M)


def measure_publish(tree: Tree, opts: Options) -> dict[str, float]:
    out = _run_python(tree, ["-m", "bench.publish"], timeout=120)
    rows = {name: float(value) for name, value in _PUBLISH_ROW.findall(out)}
    if "/cmd_vel" not in rows:
        msg = f"bench.publish printed no /cmd_vel row: {out.strip()[-200:]!r}"
        raise RuntimeError(msg)
    figures = {"inproc": rows["/cmd_vel"]}
    if "/chatter x10" in rows:
        figures["chatter"] = rows["/chatter x10"]
    figures.update(_wire_publish(tree, opts.wire_seconds))
    return figures


#: Clients and rate of the wire publish (under the per-client limit, 200/s).
WIRE_CLIENTS, WIRE_RATE = 10, 150.0


def _wire_publish(tree: Tree, seconds: float) -> dict[str, float]:
    """Server CPU per /cmd_vel publish over the wire, its idle CPU over as long subtracted."""
    from websockets.asyncio.client import connect

    twist = {"linear": {"x": 0.1, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.2}}
    frame = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": twist})
    advertise = json.dumps({"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})

    async def client(port: int, start: float, end: float, counts: list[int]) -> None:
        async with connect(f"ws://127.0.0.1:{port}", max_size=None) as ws:
            await ws.send(advertise)

            async def read() -> None:
                with contextlib.suppress(Exception):
                    async for raw in ws:
                        message = json.loads(raw)
                        if message.get("op") == "status" and message.get("level") == "error":
                            counts[1] += 1

            reader = asyncio.create_task(read())
            await asyncio.sleep(max(0.0, start - time.time()))
            k = 0
            while (now := time.time()) < end:
                due = start + k / WIRE_RATE
                if due > now:
                    await asyncio.sleep(due - now)
                await ws.send(frame)
                counts[0] += 1
                k += 1
            await asyncio.sleep(0.5)  # the refusals of the last ones, if any
            reader.cancel()

    with server("simbridge", tree=tree.path) as (proc, port):
        time.sleep(1.0)
        t0, c0 = time.monotonic(), cpu_seconds(proc)
        time.sleep(seconds)
        idle = (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
        counts = [0, 0]  # sent, refused

        async def all_clients() -> float:
            start = time.time() + 2.0  # connected and advertised by then
            end = start + seconds
            tasks = [
                asyncio.create_task(client(port, start, end, counts)) for _ in range(WIRE_CLIENTS)
            ]
            await asyncio.sleep(max(0.0, start - time.time()))
            c0 = cpu_seconds(proc)
            await asyncio.sleep(max(0.0, end - time.time()))
            used = cpu_seconds(proc) - c0
            await asyncio.gather(*tasks)
            return used

        sent0 = counts[0]
        used = asyncio.run(all_clients())
    sent = counts[0] - sent0
    return {
        "wire": (used - idle * seconds) / max(1, sent) * 1e6,
        "wire_refused": float(counts[1]),
    }


_HEADLESS_CHILD = r"""
import json, sys, time
import simbridge
from simbridge.headless import Simulation

topics = json.loads(sys.argv[1])
sim = Simulation()
for topic in topics:
    sim.subscribe(topic, maxlen=10)
sim.command(0.2, 0.3)
sim.step(40)  # first use: registries, encoders
n = 20
while True:  # a batch of at least 0.1 CPU seconds
    t0 = time.process_time()
    sim.step(n)
    if time.process_time() - t0 >= 0.1:
        break
    n *= 2
rates = []
for _ in range(7):
    t0 = time.process_time()
    sim.step(n)
    rates.append(n / (time.process_time() - t0))
print(json.dumps({"file": simbridge.__file__, "rate": max(rates)}))
"""

HEADLESS_CASES = {
    "bare": [],
    "full": ["/odom", "/scan", "/tf", "/clock"],
}


def measure_headless(tree: Tree, opts: Options) -> dict[str, float]:
    figures = {}
    for key, topics in HEADLESS_CASES.items():
        args = ["-c", _HEADLESS_CHILD, json.dumps(topics)]
        result = json.loads(_run_python(tree, args, timeout=180).strip().splitlines()[-1])
        figures[key] = float(result["rate"])
    return figures


_FLOAT = r"(-?\d+(?:\.\d+)?)"


def measure_zenoh(tree: Tree, opts: Options) -> dict[str, float]:
    out = _run_python(tree, ["-m", "bench.zenoh", "hop", f"{opts.hop_seconds:g}"], timeout=300)
    args = ["-m", "bench.zenoh", "outward", f"{opts.zenoh_seconds:g}"]
    out += _run_python(tree, args, timeout=600, ROUNDS="2")
    figures = {}
    hop = re.search(rf"via B through the router\s+\d+\s+{_FLOAT}\s+{_FLOAT}", out)
    same = re.search(rf"same process \(A\)\s+\d+\s+{_FLOAT}\s+{_FLOAT}", out)
    added = re.search(rf"p99 added by the hop: {_FLOAT} ms", out)
    if hop and same and added:
        figures["hop_p99"] = float(hop.group(2))
        figures["same_p99"] = float(same.group(2))
        figures["hop_added"] = float(added.group(1))
    rounds = re.findall(rf"^\d+\s+{_FLOAT}\s+\d+\s+{_FLOAT}\s+\d+\s+{_FLOAT}x$", out, re.M)
    ratio = re.search(rf"ROS 2 / rosbridge server CPU, median of \d+ rounds: {_FLOAT}x", out)
    if rounds and ratio:
        figures["rosbridge_cpu"] = statistics.median(float(r[0]) for r in rounds)
        figures["ros2_cpu"] = statistics.median(float(r[1]) for r in rounds)
        figures["outward"] = float(ratio.group(1))
    if not figures:
        msg = f"bench.zenoh printed none of its figures: {out.strip()[-300:]!r}"
        raise RuntimeError(msg)
    return figures


def measure_memory(tree: Tree, opts: Options) -> dict[str, float]:
    from bench.memory import idle_server

    (rss, anon, file), modules, _ = idle_server([], tree.path)
    return {
        "rss": rss,
        "anon": anon,
        "file": file,
        "modules": float(len(modules)),
        "pydantic": float(sum(1 for m in modules if m.split(".")[0].startswith("pydantic"))),
    }


def measure_pi(tree: Tree, opts: Options) -> dict[str, float]:
    from bench.pi import cold_start

    figures = {"cold": statistics.median(cold_start(None, tree.path) for _ in range(3))}
    if opts.budget is not None:
        figures["cold_pi"] = statistics.median(cold_start(opts.budget, tree.path) for _ in range(3))
    return figures


#: name -> (measure, [(key, figure, unit, better, digits)]).
FIGURES: dict[
    str,
    tuple[Callable[[Tree, Options], dict[str, float]], list[tuple[str, str, str, str, int]]],
] = {
    "fanout": (
        measure_fanout,
        [
            ("cpu", "fanout 100 clients: server CPU", "% of a core", "lower", 1),
            ("p50", "fanout 100 clients: latency p50", "ms", "lower", 2),
            ("p99", "fanout 100 clients: latency p99", "ms", "lower", 2),
            ("lost", "fanout 100 clients: messages lost", "count", "lower", 0),
        ],
    ),
    "publish": (
        measure_publish,
        [
            ("inproc", "publish /cmd_vel, in-process (bench.publish)", "us/op", "lower", 1),
            ("chatter", "publish /chatter to 10 subscribers, in-process", "us/op", "lower", 1),
            ("wire", "publish /cmd_vel over the wire: server CPU", "us/op", "lower", 1),
            ("wire_refused", "publish over the wire: refused", "count", "lower", 0),
        ],
    ),
    "headless": (
        measure_headless,
        [
            ("bare", "headless, no subscriber", "steps/CPU s", "higher", 0),
            ("full", "headless, /odom+/scan+/tf+/clock", "steps/CPU s", "higher", 0),
        ],
    ),
    "zenoh": (
        measure_zenoh,
        [
            (
                "rosbridge_cpu",
                "zenoh outward: CPU, one rosbridge client",
                "% of a core",
                "lower",
                1,
            ),
            ("ros2_cpu", "zenoh outward: CPU, one ROS 2 subscriber", "% of a core", "lower", 1),
            ("outward", "zenoh outward: ROS 2 / rosbridge CPU", "ratio", "lower", 2),
            ("same_p99", "zenoh hop: /odom p99, same process", "ms", "lower", 2),
            ("hop_p99", "zenoh hop: /odom p99, via the hop", "ms", "lower", 2),
            ("hop_added", "zenoh hop: p99 added by the hop", "ms", "lower", 2),
        ],
    ),
    "memory": (
        measure_memory,
        [
            ("rss", "idle RSS, default server", "MiB", "lower", 1),
            ("anon", "idle RssAnon", "MiB", "lower", 1),
            ("file", "idle RssFile", "MiB", "lower", 1),
            ("modules", "idle server: modules imported", "count", "lower", 0),
            ("pydantic", "idle server: pydantic modules imported", "count", "lower", 0),
        ],
    ),
    "pi": (
        measure_pi,
        [
            ("cold", "cold start -> first /odom, no limit", "s", "lower", 2),
            ("cold_pi", "cold start -> first /odom, Pi 4B budget", "s", "lower", 2),
        ],
    ),
}


# -- the run -------------------------------------------------------------------------------------


def _pi_budget(opts: Options) -> None:
    """Make the Pi budget's cgroup (root only; calibrated here with ``PI_CORES=calibrate``)."""
    from bench.pi import CpuBudget, calibrate

    if os.geteuid() != 0:
        print("pi: not root, no cgroup: cold start without a limit only")
        return
    if opts.pi_cores is None:
        cal = calibrate()
        for line in cal.detail:
            print(f"pi: {line}")
        opts.pi_cores = cal.cores
    opts.budget = CpuBudget(opts.pi_cores)
    print(f"pi: budget {opts.pi_cores:.3f} of one core here ({opts.budget.version})")


def _rounds(name: str, rounds: int, opts: Options) -> int:
    """Runs of measurement ``name`` in each tree.

    Zenoh's, the longest, ``--zenoh-rounds``; headless steps, a few seconds a run and the
    noisiest figure (a whole run of the same code 0.6x another on this shared machine), 3x.
    """
    if name == "zenoh":
        return opts.zenoh_rounds
    return 3 * rounds if name == "headless" else rounds


def run(names: list[str], baseline: Tree, current: Tree, rounds: int, opts: Options) -> int:
    """Run each measurement ``rounds`` times per tree, alternating; print the medians."""
    print(f"baseline: {baseline.commit} {baseline.subject}")
    print(f"current:  {current.commit} {current.subject}")
    print(
        f"{rounds} run(s) of each in each tree ({_rounds('headless', rounds, opts)} of headless, "
        f"{opts.zenoh_rounds} of zenoh), alternating (baseline first, then current first...); "
        f"medians; ratio = current / baseline; {sys.executable}"
    )
    figures: list[Figure] = []
    failed = 0
    for name in names:
        measure, specs = FIGURES[name]
        mine = {
            key: Figure(label, unit, better, digits) for key, label, unit, better, digits in specs
        }
        if name == "pi":
            _pi_budget(opts)
        started = time.monotonic()
        for r in range(_rounds(name, rounds, opts)):
            for tree in (baseline, current) if r % 2 == 0 else (current, baseline):
                try:
                    values = measure(tree, opts)
                except Exception as err:  # one failed run: reported, the others go on
                    failed += 1
                    text = f"{type(err).__name__}: {err}"[:300]
                    for figure in mine.values():
                        figure.errors[tree.label] = text
                    print(f"  {name} {tree.label} round {r + 1}: FAILED {text}", flush=True)
                    continue
                for key, value in values.items():
                    if key in mine:
                        mine[key].runs[tree.label].append(value)
                shown = ", ".join(f"{k} {v:.4g}" for k, v in values.items())
                print(f"  {name} {tree.label} round {r + 1}: {shown}", flush=True)
        print(f"=== {name}: {time.monotonic() - started:.0f} s, {load_average()}")
        print(HEADER)
        for figure in mine.values():
            print(figure.row())
        print(flush=True)
        figures += mine.values()
    if opts.budget is not None:
        opts.budget.remove()
    print("=== all figures (medians; ratio = current / baseline)")
    print(HEADER)
    for figure in figures:
        print(figure.row())
    for figure in figures:
        for label, text in figure.errors.items():
            print(f"  {figure.name}: {label} failed at least once: {text}")
    _targets(figures)
    return 1 if failed else 0


def _targets(figures: list[Figure]) -> None:
    """Issue 24's targets, judged on the current tree's medians."""
    by_name = {f.name: f for f in figures}
    checks = [
        ("zenoh outward: ROS 2 / rosbridge CPU", "<= 1.0x", lambda v: v <= 1.0),
        ("idle RSS, default server", "< 60 MiB", lambda v: v < 60.0),
    ]
    for name, target, holds in checks:
        figure = by_name.get(name)
        value = figure.median("current") if figure else None
        if value is None:
            continue
        verdict = "met" if holds(value) else "NOT met"
        print(f"target (issue 24): {name} {target}: {verdict} ({value:.2f}, current)")


OPTIONS = (
    "--baseline",
    "--current",
    "--only",
    "--rounds",
    "--seconds",
    "--zenoh-rounds",
    "--zenoh-seconds",
)


def _parse(argv: list[str]) -> tuple[str, str | None, list[str], int, Options]:
    baseline, current, names, rounds = DEFAULT_BASELINE, None, list(MEASUREMENTS), 3
    opts = Options()
    args = list(argv)
    while args:
        word = args.pop(0)
        if word not in OPTIONS:
            raise SystemExit(f"bench restructure: unknown argument {word!r} (see the docstring)")
        if not args:
            raise SystemExit(f"bench restructure: {word} needs a value")
        if word == "--baseline":
            baseline = args.pop(0)
        elif word == "--current":
            current = args.pop(0)
        elif word == "--only":
            names = [n.strip() for n in args.pop(0).split(",") if n.strip()]
            unknown = [n for n in names if n not in MEASUREMENTS]
            if unknown:
                raise SystemExit(
                    f"bench restructure: no measurement {unknown[0]!r}; "
                    f"choose from {', '.join(MEASUREMENTS)}"
                )
        elif word == "--rounds":
            rounds = max(1, int(args.pop(0)))
        elif word == "--seconds":
            opts.seconds = float(args.pop(0))
        elif word == "--zenoh-rounds":
            opts.zenoh_rounds = max(1, int(args.pop(0)))
        elif word == "--zenoh-seconds":
            opts.zenoh_seconds = float(args.pop(0))
    if os.environ.get("PI_CORES") == "calibrate":
        opts.pi_cores = None
    elif os.environ.get("PI_CORES"):
        opts.pi_cores = float(os.environ["PI_CORES"])
    return baseline, current, names, rounds, opts


def main(argv: list[str] | None = None) -> int:
    rev, current_rev, names, rounds, opts = _parse(argv or [])
    with contextlib.ExitStack() as stack:
        baseline = _describe("baseline", stack.enter_context(checkout(rev)))
        path = ROOT if current_rev is None else stack.enter_context(checkout(current_rev))
        current = _describe("current", path)
        for tree in (baseline, current):
            _check_import(tree)
            # bytecode written before the first run: a fresh checkout's first start compiles
            # every module (the first cold start of the baseline would count it)
            for part in ("simbridge", "bench"):
                subprocess.run(
                    [sys.executable, "-m", "compileall", "-q", str(tree.path / part)],
                    capture_output=True,
                    check=False,
                )
        return run(names, baseline, current, rounds, opts)


#: ``python -m bench restructure ARGS``: every argument is this benchmark's own (bench/__main__.py
#: hands them over as they are): ``--baseline REV`` is a git revision, not the ``--baseline DIR``
#: of ``python -m bench``, and ``--only zenoh`` names a measurement, not the benchmark ``zenoh``.
OWN_ARGUMENTS = True


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
