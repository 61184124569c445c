"""Run the benchmarks: ``python -m bench [NAME ...]`` (default: all; ``quick``: the quick ones).

``python -m bench quick --baseline DIR`` runs them before (the checkout at ``DIR``, with its own
``.venv``) and after (this checkout), side by side with ratios (:mod:`bench.baseline`).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path


#: Benchmarks run by default (quick, under a minute together): module name -> what it measures.
QUICK = {
    "encoding": "/scan and /odom frames for N subscribers vs stdlib json.dumps per subscriber",
    "raycast": "one 360-ray scan against 20, 100 and 500 walls",
    "headless": "headless simulation speed-up over real time",
    "simtime": "server loop real-time factor achieved vs requested (1x to 20x)",
    "cbor": "cbor frames of /scan and /odom: cbor2 + numpy hook vs the hand-written encoder",
    "cdr": "/odom, /scan and a 30-transform /tf to CDR (the ROS 2 links) beside orjson JSON",
    "http": "page and /healthz requests/s: httptools server vs the hand-written one (+ h11 parse)",
    "publish": "a client publish through the graph: /cmd_vel to the robot, a topic to 10 clients",
}


#: The classroom-scale benchmarks (issue 6; about 10 minutes together, server and clients in
#: separate processes; ``pip install -e '.[bench]'`` for the ir-sim baseline of ``raycast``).
SCALE = {
    "fleet": "robots in real time on one core (step, collisions, batched scans, messages)",
    "fanout": "100 and 500 clients on /odom + /scan vs a bare websockets broadcaster",
    "classroom": "30 robots driven by 30 clients for 60 s: latency, /odom rate, CPU, RSS",
}

#: The deployment benchmark (issue 5; root with Docker: ``python -m bench docker``, ~3 minutes,
#: not in the default run): image size, container RSS and CPU vs simbridge run natively.
DEPLOY = {
    "docker": "the ros2-web-bridge container: image size, RSS idle / 10 clients, CPU % vs native",
}

#: The Raspberry Pi 4B figures (issue 16; root, for a cgroup: ``python -m bench pi``, ~8 minutes,
#: not in the default run): a Pi core's worth of CPU derived from published Pi 4B benchmarks.
PI = {
    "pi": "one page, 10 pages, the 30-robot classroom inside a Pi 4B core's CPU budget vs no "
    "limit; where the budget runs out; cold start; idle RSS",
}

#: Where an idle server's memory goes (issue 16; ``python -m bench memory``, about 20 s, not in
#: the default run): each import group's share, the modules cut from the default path.
MEMORY = {
    "memory": "idle default server: RSS / RssAnon / RssFile per import group; before/after the "
    "issue-16 cuts",
}

#: Start-up cost (issue 24; ``python -m bench startup``, about a minute; before/after with
#: ``--baseline DIR``): idle memory without and with a SIMBRIDGE_* variable, cold start.
STARTUP = {
    "startup": "idle default server RSS / RssAnon / RssFile; cold start to the first /odom, "
    "without a limit and in the Pi 4B budget",
}

#: Reliability figures of issue 7, run by name (``python -m bench hostile stall churn soak``).
RELIABILITY = {
    "hostile": "hostile frames against a real server: crashes, /odom rate quiet vs under attack",
    "stall": "p99 latency of normal clients without and with stalled clients",
    "churn": "server RSS and fds over 1,000 connect/subscribe/disconnect cycles",
    "soak": "10 minutes of churn (SOAK_SECONDS): RSS and fds before and after",
}


#: ROS 2 over Zenoh (issue 15), run by name (``python -m bench.zenoh [hop|outward|classroom]``).
ZENOH = {
    "zenoh": "/odom latency through a Zenoh hop; server CPU to one ROS 2 vs one rosbridge client",
}


#: ROS 2 over DDS (issue 25), run by name (``python -m bench dds [lib|outward|latency|relay]``;
#: root: it runs itself in a network namespace of its own).
DDS = {
    "dds": "DDS libraries' costs; 30 robots to one DDS subscriber vs one rosbridge client (CPU); "
    "/odom p99 DDS vs rosbridge; --dds --no-sim relaying a Fast DDS robot to 10 pages",
}


#: The Foxglove port (issue 30), run by name (``python -m bench foxglove [SECONDS [N [ROUNDS]]]``).
FOXGLOVE = {
    "foxglove": "100 Foxglove vs 100 rosbridge clients on /odom + /scan: server CPU, p99, bytes/s; "
    "idle RSS without and with --foxglove-port",
}


#: Issue 24's figures before and after the restructure (``python -m bench restructure``, about
#: 10 minutes, not in the default run; ``--only fanout,publish`` for some): the baseline is a
#: git revision (``--baseline REV``, default main before it) checked out by the benchmark itself.
RESTRUCTURE = {
    "restructure": "fan-out, publish, headless, Zenoh outward and hop, idle RSS, cold start: "
    "a baseline commit vs this checkout, alternated, medians and ratios",
}


def runs(argv: list[str]) -> list[tuple[str, list[str]]]:
    """Split ``argv`` into benchmarks and their arguments.

    A word that is not a module of ``bench/`` is an argument of the benchmark before it:
    ``hostile state7 tf_goals stall`` runs ``hostile`` with ``[state7, tf_goals]``, then
    ``stall``.

    Raises:
        SystemExit: the first word is not a benchmark.
    """
    out: list[tuple[str, list[str]]] = []
    for word in argv:
        if importlib.util.find_spec(f"bench.{word}") is not None:
            out.append((word, []))
        elif out:
            out[-1][1].append(word)
        else:
            raise SystemExit(f"bench: no benchmark named {word!r} (see bench/__main__.py)")
    return out


def _module(name: str) -> object:
    """The benchmark module ``bench.NAME``, or None when there is none."""
    if name.startswith("-") or importlib.util.find_spec(f"bench.{name}") is None:
        return None
    return importlib.import_module(f"bench.{name}")


def main(argv: list[str]) -> int:
    # a benchmark that reads every argument after its name itself (bench.restructure: its
    # --baseline is a git revision, --only names measurements that are benchmarks here too)
    first = _module(argv[0]) if argv else None
    if getattr(first, "OWN_ARGUMENTS", False):
        code: int = first.main(argv[1:])  # type: ignore[union-attr]
        return code
    baseline = None
    if "--baseline" in argv:
        at = argv.index("--baseline")
        baseline, argv = argv[at + 1], argv[:at] + argv[at + 2 :]
    names = argv or [*QUICK, *SCALE]
    if names == ["quick"]:
        names = list(QUICK)
    if baseline is not None:
        from bench.baseline import compare

        return compare(names, Path(baseline).resolve())
    failed = 0
    for name, args in runs(names):
        module = importlib.import_module(f"bench.{name}")
        failed += int((module.main(args) if args else module.main()) != 0)
        print()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
