"""The Docker deployment's footprint: image size, RSS and CPU of the bridge container.

    python -m bench docker          (root: starts dockerd if needed, like the smoke test)

Brings docker-compose.yml up (with tests/deploy/compose.test.yml: local images, free loopback
ports), then measures the ros2-web-bridge container's simbridge process from the host (its
``/proc`` counters: user + system CPU seconds, resident memory), with load-generator processes
as clients (bench/loadgen.py: raw rosbridge subscribe ops):

- idle: no client;
- one client subscribed to /odom (20 Hz) and /scan (10 Hz, 360 rays);
- ten such clients.

Side by side, the baseline: the same simbridge run natively on the host (``python -m simbridge``
from this checkout's venv, same default world and parameters) under the same loads, and the
ratio container / native. The image is built on the tests' local base (Debian bookworm, Python
3.11, made with debootstrap; the default python:3.12-slim-bookworm base cannot be pulled here).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil

from bench.procs import collect, cpu_seconds, load_average, server, start_loadgens
from tests.deploy import stack as docker


WINDOW = 15.0  # seconds per measurement
SETTLE = 3.0
TOPICS = ["/odom", "/scan"]
BENCH_OVERRIDE = Path(__file__).resolve().parent / "compose.bench.yml"


class Cgroup:
    """The container's cgroup (v1, cgroupfs): CPU of every process in it, memory charged."""

    def __init__(self, pid: int) -> None:
        self.paths: dict[str, Path] = {}
        for line in Path(f"/proc/{pid}/cgroup").read_text().splitlines():
            _, controllers, path = line.split(":", 2)
            for name in controllers.split(","):
                self.paths[name] = Path("/sys/fs/cgroup") / name / path.lstrip("/")

    def cpu_seconds(self) -> float:
        """CPU seconds of the container (simbridge and its healthcheck probes)."""
        path = self.paths.get("cpuacct")
        if path is None or not (path / "cpuacct.usage").exists():
            return float("nan")
        return int((path / "cpuacct.usage").read_text()) / 1e9

    def memory(self) -> float:
        """Memory charged to the container (resident memory and page cache), bytes."""
        path = self.paths.get("memory")
        if path is None or not (path / "memory.usage_in_bytes").exists():
            return float("nan")
        return float((path / "memory.usage_in_bytes").read_text())


@contextlib.contextmanager
def container() -> Iterator[tuple[psutil.Process, int, str]]:
    """The compose stack up and healthy; yield (simbridge process, WS port, image tag)."""
    reason = docker.start_engine()
    if reason is not None:
        raise RuntimeError(reason)
    docker.reap_stale_projects()
    docker.ensure_base_image()
    image = docker.build_images()
    compose = docker.COMPOSE_COMMANDS["docker-compose"]
    stack = docker.Stack(compose, image, "bench", extra=[BENCH_OVERRIDE])
    try:
        stack("up", "-d", timeout=300)
        stack.wait_healthy(["ros2-web-bridge", "web-interface"])
        pid = int(stack.inspect("ros2-web-bridge")["State"]["Pid"])
        yield psutil.Process(pid), stack.ws_port, image
    finally:
        stack("down", "--timeout", "10", check=False)


def measure(proc: psutil.Process, port: int, group: Cgroup | None) -> dict[str, Any]:
    """CPU % and RSS of ``proc`` idle, with one client and with ten (/odom + /scan each)."""
    out: dict[str, Any] = {}
    time.sleep(SETTLE)
    c0, t0 = cpu_seconds(proc), time.monotonic()
    g0 = group.cpu_seconds() if group else float("nan")
    time.sleep(2 * WINDOW)  # two healthcheck intervals and more
    elapsed = time.monotonic() - t0
    out["cpu_idle"] = 100 * (cpu_seconds(proc) - c0) / elapsed
    out["group_cpu_idle"] = 100 * ((group.cpu_seconds() if group else float("nan")) - g0) / elapsed
    out["rss_idle"] = proc.memory_info().rss
    out["group_mem_idle"] = group.memory() if group else float("nan")
    for n in (1, 10):
        start = time.time() + SETTLE
        end = start + WINDOW
        clients = [{"subscribe": TOPICS, "drive": None} for _ in range(n)]
        gens = start_loadgens(f"ws://127.0.0.1:{port}", clients, 1, start, end)
        time.sleep(max(0.0, start - time.time()))
        c0, t0 = cpu_seconds(proc), time.monotonic()
        time.sleep(max(0.0, end - time.time()))
        out[f"cpu_{n}"] = 100 * (cpu_seconds(proc) - c0) / (time.monotonic() - t0)
        out[f"rss_{n}"] = proc.memory_info().rss
        out[f"group_mem_{n}"] = group.memory() if group else float("nan")
        results = collect(gens, timeout=WINDOW + 30)
        errors = [r["error"] for r in results if r.get("error")]
        if errors:
            raise RuntimeError(f"load generator: {errors[0]}")
        got = [len(r["stamps"]["/odom"]) / WINDOW for r in results]
        out[f"odom_hz_{n}"] = min(got)
        out[f"scan_hz_{n}"] = min(len(r["stamps"]["/scan"]) / WINDOW for r in results)
    return out


def mib(n: float) -> str:
    return f"{n / 2**20:.1f} MiB"


def main() -> int:
    print("docker: the ros2-web-bridge container vs simbridge run natively (same machine)")
    with container() as (proc, port, image):
        size = int(docker.run(["docker", "image", "inspect", "-f", "{{.Size}}", image]).stdout)
        base = docker.run(["docker", "image", "inspect", "-f", "{{.Size}}", docker.BASE_IMAGE])
        print(
            f"image {image}: {size / 1e6:.0f} MB, of which the local Debian/Python base "
            f"{int(base.stdout) / 1e6:.0f} MB and the Dockerfile's layers "
            f"{(size - int(base.stdout)) / 1e6:.0f} MB"
        )
        boxed = measure(proc, port, Cgroup(proc.pid))
    with server("simbridge") as (native_proc, native_port):
        native = measure(native_proc, native_port, None)
    rows = [
        ("RSS idle", "rss_idle", mib),
        ("RSS, 10 clients /odom+/scan", "rss_10", mib),
        ("container memory (cgroup) idle", "group_mem_idle", mib),
        ("container memory (cgroup) 10 clients", "group_mem_10", mib),
        ("CPU % idle", "cpu_idle", lambda v: f"{v:.1f} %"),
        ("CPU % idle, cgroup (+healthchecks)", "group_cpu_idle", lambda v: f"{v:.1f} %"),
        ("CPU %, 1 client /odom+/scan", "cpu_1", lambda v: f"{v:.1f} %"),
        ("CPU %, 10 clients /odom+/scan", "cpu_10", lambda v: f"{v:.1f} %"),
        ("/odom Hz per client (min of 10)", "odom_hz_10", lambda v: f"{v:.1f}"),
        ("/scan Hz per client (min of 10)", "scan_hz_10", lambda v: f"{v:.1f}"),
    ]
    print(f"{'':38} {'container':>11} {'native':>11} {'ratio':>7}")
    for label, key, fmt in rows:
        if math.isnan(native[key]):  # the container's cgroup: no native counterpart
            print(f"{label:38} {fmt(boxed[key]):>11} {'n/a':>11} {'n/a':>7}")
            continue
        ratio = boxed[key] / native[key] if native[key] else float("nan")
        print(f"{label:38} {fmt(boxed[key]):>11} {fmt(native[key]):>11} {ratio:>7.2f}")
    print(
        f"({WINDOW:.0f} s windows, idle {2 * WINDOW:.0f} s; CPU = the simbridge process's "
        f"user+system seconds; {load_average()})"
    )
    return 0
