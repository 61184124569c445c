"""Classroom: 30 robots, 30 clients each driving one robot, for 60 s.

A simbridge server process runs a 12 m x 10 m room with 30 named robots (r1..r30, 2 m apart).
Two load-generator processes (separate from the server) run 30 clients; client k publishes
``/rk/cmd_vel`` at 10 Hz (a slowly turning drive, so robots meet walls and each other) and
subscribes to ``/rk/odom``, ``/rk/scan`` and ``/tf`` (all 30 transforms, 20 Hz). Measured over
the window: publish-to-receive latency of every message, the inter-arrival of each client's
``/odom``, the server's CPU (its own user + system seconds), the server's RSS idle (before any
client) and with the 30 clients, and losses (gaps in each client's /odom stamps, and
``dropped_frames`` of /healthz).

Targets (issue 6): p99 <= 20 ms; /odom inter-arrival within 50 +- 5 ms at p99 (1st and 99th
percentiles); server <= 25 % of one core; RSS reported.
"""

from __future__ import annotations

import itertools
import json
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import yaml

from bench.procs import collect, cpu_seconds, load_average, percentile, server, start_loadgens


N = 30


def world_file(directory: Path) -> Path:
    """Write the classroom world: a 12 m x 10 m room, 30 robots on a 2 m grid."""
    robots = [
        {"name": f"r{k + 1}", "pose": [-5.0 + 2.0 * (k % 6), -4.0 + 2.0 * (k // 6), 0.0]}
        for k in range(N)
    ]
    spec = {
        "name": "classroom-bench",
        "walls": [[-6, -5, 6, -5], [6, -5, 6, 5], [6, 5, -6, 5], [-6, 5, -6, -5]],
        "robots": robots,
    }
    path = directory / "classroom.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def main(argv: list[str] | None = None) -> int:
    args = argv or []
    seconds = float(args[0]) if args else 60.0
    with (
        tempfile.TemporaryDirectory() as tmp,
        server("simbridge", world=world_file(Path(tmp))) as (
            proc,
            port,
        ),
    ):
        time.sleep(2.0)
        idle_rss = proc.memory_info().rss
        clients = [
            {
                "subscribe": [f"/r{k}/odom", f"/r{k}/scan", "/tf"],
                "drive": f"/r{k}/cmd_vel",
            }
            for k in range(1, N + 1)
        ]
        start = time.time() + 4.0
        end = start + seconds
        procs = start_loadgens(f"ws://127.0.0.1:{port}", clients, 2, start, end)
        time.sleep(max(0.0, start - time.time()))
        cpu0 = cpu_seconds(proc)
        time.sleep(max(0.0, end - time.time()))
        cpu1 = cpu_seconds(proc)
        busy_rss = proc.memory_info().rss
        load = load_average()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=5) as r:
            health = json.load(r)
        results = collect(procs, timeout=seconds + 60)
    latencies = [x for r in results for x in r.get("latencies", [])]
    gaps: list[float] = []
    stamp_gaps: list[float] = []  # the same, on the server's publish stamps
    missing = 0
    received: dict[str, int] = {"odom": 0, "scan": 0, "tf": 0}
    for _k, r in enumerate(results):
        for topic, stamps in r.get("stamps", {}).items():
            received[topic.rsplit("/", 1)[-1]] += len(stamps)
        odom = next((t for t in r.get("arrivals", {}) if t.endswith("/odom")), None)
        if odom is None:
            continue
        arrivals = r["arrivals"][odom]
        gaps += [(b - a) * 1e3 for a, b in itertools.pairwise(arrivals)]
        stamps = r["stamps"][odom]
        missing += sum(max(0, round((b - a) / 50e6) - 1) for a, b in itertools.pairwise(stamps))
        stamp_gaps += [(b - a) / 1e6 for a, b in itertools.pairwise(stamps)]
    errors = [r["error"] for r in results if r.get("error")]
    cpu = (cpu1 - cpu0) / seconds
    p99 = percentile(latencies, 0.99) * 1e3
    g1, g99 = percentile(gaps, 0.01), percentile(gaps, 0.99)
    print(
        f"classroom: {N} robots, {N} clients (drive 10 Hz; odom, scan, /tf), {seconds:g} s; {load}"
    )
    print(
        f"latency ms: p50 {percentile(latencies, 0.5) * 1e3:.2f}  p99 {p99:.2f}  "
        f"max {max(latencies, default=float('nan')) * 1e3:.1f}  ({len(latencies)} messages: "
        f"{received['odom']} odom, {received['scan']} scan, {received['tf']} tf)"
    )
    print(
        f"/odom inter-arrival ms: p1 {g1:.1f}  p50 {percentile(gaps, 0.5):.1f}  p99 {g99:.1f}  "
        f"min {min(gaps, default=float('nan')):.1f}  max {max(gaps, default=float('nan')):.1f}"
    )
    print(
        f"/odom publish interval (stamps) ms: p1 {percentile(stamp_gaps, 0.01):.1f}  "
        f"p99 {percentile(stamp_gaps, 0.99):.1f}  (the server's share of the inter-arrival)"
    )
    print(
        f"server CPU: {cpu * 100:.1f} % of one core; loop work p99 "
        f"{health.get('loop', {}).get('work_ms_p99')} ms, late ticks "
        f"{health.get('loop', {}).get('late_ticks')}"
    )
    print(f"server RSS: idle {idle_rss / 1e6:.1f} MB, with {N} clients {busy_rss / 1e6:.1f} MB")
    print(
        f"losses: {missing} /odom stamps missing, {health.get('dropped_frames')} frames dropped "
        f"by the server, {len(errors)} client errors {errors[:2]}"
    )
    checks = [
        ("p99 latency <= 20 ms", p99 <= 20.0, f"{p99:.2f} ms"),
        (
            "/odom inter-arrival 50 +- 5 ms at p99",
            g1 >= 45.0 and g99 <= 55.0,
            f"{g1:.1f}..{g99:.1f}",
        ),
        ("server <= 25 % of one core", cpu <= 0.25, f"{cpu * 100:.1f} %"),
    ]
    ok = True
    for what, passed, figure in checks:
        ok &= passed
        print(f"target: {what}: {'PASS' if passed else 'MISS'} ({figure})")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
