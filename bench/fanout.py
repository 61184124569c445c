"""Fan-out: N clients subscribed to /odom (20 Hz) and /scan (10 Hz), simbridge vs the floor.

In the same run, the same load-generator processes (two, separate from the server) connect N
clients first to a simbridge server process and then to a bare websockets broadcaster process
sending the same bytes at the same rates (``bench/broadcaster.py``, the physical floor). For
each: server CPU (its own user + system seconds per second), publish-to-receive latency
(receive wall time minus the message's header stamp, set at publish), and losses: a message
any client received must reach every client, and the server must drop nothing
(``dropped_frames`` of /healthz).

``python -m bench.fanout [SECONDS [N ...]]`` (default 20 s, N = 100 and 500). A full run
also reports, without a target, the 100-client ratio while one client drives the robot (the
default rows keep it parked, as the floor has no robot to move).

``python -m bench.fanout --baseline DIR [SECONDS [N ...]]`` adds simbridge as the checkout at
``DIR`` has it (its code and ``.venv``; row ``before``) to the alternation (4 rounds at 100
clients, the order rotating), and prints for each N the medians of before and after (this
checkout) with the ratios after / before.

Targets (issue 6): 100 clients: p99 <= 20 ms, nothing lost, CPU <= 1.3x the broadcaster's;
500 clients: nothing lost.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

from bench.procs import (
    ROOT,
    collect,
    cpu_seconds,
    load_average,
    losses,
    percentile,
    server,
    start_loadgens,
)


TOPICS = ["/odom", "/scan"]


def phase(
    kind: str,
    n: int,
    seconds: float,
    processes: int = 2,
    *,
    drive: bool = False,
    checkout: Path | None = None,
    tree: Path | None = None,
) -> dict[str, Any]:
    """Run ``n`` clients against one server kind for ``seconds``; return the figures.

    With ``drive``, the first client also publishes /cmd_vel at 10 Hz (the broadcaster reads
    and ignores it), so that simbridge moves its robot, casts a new scan each time and resolves
    contacts with the walls the robot slides along. ``checkout``: simbridge as that checkout
    has it (the row is then labelled ``before``); ``tree``: that source tree's simbridge with
    this interpreter (:func:`bench.procs.tree_env`; the row keeps its label).
    """
    with server(kind, checkout=checkout, tree=tree) as (proc, port):
        clients: list[dict[str, Any]] = [{"subscribe": TOPICS} for _ in range(n)]
        if drive:
            clients[0]["drive"] = "/cmd_vel"
        start = time.time() + 3.0 + n / 60.0
        end = start + seconds
        procs = start_loadgens(f"ws://127.0.0.1:{port}", clients, processes, start, end)
        time.sleep(max(0.0, start - time.time()))
        cpu0 = cpu_seconds(proc)
        time.sleep(max(0.0, end - time.time()))
        cpu1 = cpu_seconds(proc)
        rss = proc.memory_info().rss
        load = load_average()
        dropped = None
        if kind == "simbridge":  # before and after
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=5) as r:
                dropped = json.load(r).get("dropped_frames")
        results = collect(procs, timeout=seconds + 60)
    latencies = [x for r in results for x in r.get("latencies", [])]
    expected, missing, errors = losses(results, TOPICS)
    return {
        "kind": ("before" if checkout is not None else kind) + ("+drive" if drive else ""),
        "n": n,
        "cpu": (cpu1 - cpu0) / seconds,
        "p50": percentile(latencies, 0.5) * 1e3,
        "p99": percentile(latencies, 0.99) * 1e3,
        "max": max(latencies, default=float("nan")) * 1e3,
        "received": len(latencies),
        "expected": expected,
        "missing": missing,
        "errors": errors,
        "dropped": dropped,
        "rss_mb": rss / 1e6,
        "load": load,
    }


HEADER = (
    f"{'server':<17} {'N':>4} {'CPU':>7} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7} "
    f"{'received':>8} {'missing':>7} {'dropped':>7} {'errors':>6} {'RSS MB':>6}"
)


def row(r: dict[str, Any]) -> str:
    return (
        f"{r['kind']:<17} {r['n']:>4} {r['cpu'] * 100:>6.1f}% {r['p50']:>7.2f} {r['p99']:>7.2f} "
        f"{r['max']:>7.1f} {r['received']:>8} {r['missing']:>7} "
        f"{'-' if r['dropped'] is None else r['dropped']:>7} {r['errors']:>6} "
        f"{r['rss_mb']:>6.0f}  {r['load']}"
    )


def before_after(baseline: Path, seconds: float, counts: list[int]) -> int:
    """Before (``baseline``), after (this checkout) and the floor, alternated; ratios."""
    print(f"fanout before/after: before = {baseline}, after = {ROOT}; {seconds:g} s per row")
    print(HEADER)
    runs: dict[tuple[str, int], list[dict[str, Any]]] = {}
    servers: list[tuple[str, Path | None]] = [
        ("simbridge", baseline),
        ("simbridge", None),
        ("broadcaster", None),
    ]
    for n in counts:
        for k in range(4 if n <= 100 else 1):
            # each server first, second and last in turn: load from other programs and the
            # machine's warm-up land on all of them
            for kind, checkout in servers[k % 3 :] + servers[: k % 3]:
                r = phase(kind, n, seconds, checkout=checkout)
                runs.setdefault((r["kind"], n), []).append(r)
                print(row(r), flush=True)
    print("medians of the rounds; ratio = after / before (below 1: after costs less)")
    print(f"{'N':>4} {'figure':<8} {'before':>9} {'after':>9} {'ratio':>7} {'floor':>9}")
    for n in counts:
        for key, unit, scale in (("cpu", "%", 100.0), ("p50", "ms", 1.0), ("p99", "ms", 1.0)):
            b, a, f = (
                statistics.median(r[key] for r in runs[(kind, n)]) * scale
                for kind in ("before", "simbridge", "broadcaster")
            )
            print(f"{n:>4} {key + ' ' + unit:<8} {b:>9.2f} {a:>9.2f} {a / b:>6.2f}x {f:>9.2f}")
        lost = {
            kind: sum(r["missing"] + (r["dropped"] or 0) + r["errors"] for r in runs[(kind, n)])
            for kind in ("before", "simbridge")
        }
        print(f"{n:>4} {'lost':<8} {lost['before']:>9} {lost['simbridge']:>9}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = list(argv or [])
    if args[:1] == ["--baseline"]:
        if len(args) < 2:
            print("usage: python -m bench.fanout --baseline DIR [SECONDS [N ...]]")
            return 2
        baseline = Path(args[1]).resolve()
        rest = args[2:]
        return before_after(
            baseline, float(rest[0]) if rest else 20.0, [int(a) for a in rest[1:]] or [100]
        )
    seconds = float(args[0]) if args else 20.0
    counts = [int(a) for a in args[1:]] or [100, 500]
    print(f"fanout: clients subscribed to /odom + /scan, {seconds:g} s measured per row")
    print(HEADER)
    runs: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for n in counts:
        # Alternate the two servers (3 rounds at 100 clients) so that a burst of load from
        # other programs on the machine does not land on one of them only.
        for _ in range(3 if n <= 100 else 1):
            for kind in ("simbridge", "broadcaster"):
                r = phase(kind, n, seconds)
                runs.setdefault((kind, n), []).append(r)
                print(row(r), flush=True)
    if (("simbridge", 100) not in runs) or (("simbridge", 500) not in runs):
        return 0  # a partial run (other client counts): figures only
    # For the record, not a target: the same 100 clients while one of them drives the robot.
    driven = {}
    for _ in range(2):
        for kind in ("simbridge", "broadcaster"):
            r = phase(kind, 100, seconds, drive=True)
            driven.setdefault(kind, []).append(r["cpu"])
            print(row(r), flush=True)
    s_cpu = statistics.median(r["cpu"] for r in runs[("simbridge", 100)])
    b_cpu = statistics.median(r["cpu"] for r in runs[("broadcaster", 100)])
    ratio = s_cpu / b_cpu
    print(
        f"100 clients, median CPU: simbridge {s_cpu * 100:.1f} %, broadcaster "
        f"{b_cpu * 100:.1f} %: {ratio:.2f}x"
    )
    d_ratio = statistics.median(driven["simbridge"]) / statistics.median(driven["broadcaster"])
    print(
        f"100 clients, robot driven (no target; the floor has no robot): median CPU "
        f"{d_ratio:.2f}x the broadcaster's"
    )
    s100 = {
        "p99": statistics.median(r["p99"] for r in runs[("simbridge", 100)]),
        "missing": sum(r["missing"] for r in runs[("simbridge", 100)]),
        "dropped": sum(r["dropped"] or 0 for r in runs[("simbridge", 100)]),
        "errors": sum(r["errors"] for r in runs[("simbridge", 100)]),
    }
    s500 = runs[("simbridge", 500)][0]
    checks = [
        (
            "100 clients: p99 <= 20 ms (median of rounds)",
            s100["p99"] <= 20.0,
            f"{s100['p99']:.2f} ms",
        ),
        (
            "100 clients: nothing lost",
            s100["missing"] == 0 and not s100["dropped"] and not s100["errors"],
            f"{s100['missing']} missing, {s100['dropped']} dropped",
        ),
        ("100 clients: CPU <= 1.3x the broadcaster", ratio <= 1.3, f"{ratio:.2f}x"),
        (
            "500 clients: nothing lost",
            s500["missing"] == 0 and not s500["dropped"] and not s500["errors"],
            f"{s500['missing']} missing, {s500['dropped']} dropped, {s500['errors']} errors",
        ),
    ]
    ok = True
    for what, passed, figure in checks:
        ok &= passed
        print(f"target: {what}: {'PASS' if passed else 'MISS'} ({figure})")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
