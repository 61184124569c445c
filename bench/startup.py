"""What the default server costs to start and to hold: idle memory and cold start (issue 24).

``python -m bench startup`` (about a minute; root for the Pi budget's cgroup, else that row is
skipped). Before/after a change in one run: ``python -m bench.baseline DIR startup`` (DIR: the
checkout before it, with a ``.venv``), which prints both and the ratios.

- **Idle memory**: the default server (default world, both ports, no client), settled (VmRSS
  readings 0.5 s apart within 0.1 MB), as tests/test_footprint.py measures it: VmRSS, RssAnon,
  RssFile in MiB, median of ``STARTUP_RUNS`` (3). Twice: with no ``SIMBRIDGE_*`` variable, and
  with one set (``SIMBRIDGE_LOG_LEVEL=info``, as a container's environment has them: the
  settings then read the environment too).
- **Cold start**: from spawning ``python -m simbridge`` to the first /odom on a client that
  keeps trying to connect (:func:`bench.pi.cold_start`), median of ``STARTUP_RUNS``; without a
  limit, and inside the Pi 4B budget (``PI_CORES``, default 0.194 of a core here: the
  calibration of docs/deploy.md; :class:`bench.pi.CpuBudget`).
"""

from __future__ import annotations

import os
import statistics
import sys

from bench.memory import idle_server
from bench.pi import CpuBudget, cold_start


#: Runs of each figure (the median is shown).
RUNS = int(os.environ.get("STARTUP_RUNS", "3"))
#: The Pi 4B budget, cores of this machine (docs/deploy.md's calibration).
PI_CORES = float(os.environ.get("PI_CORES", "0.194"))


def _memory(variables: dict[str, str]) -> tuple[float, float, float]:
    saved = dict(os.environ)
    os.environ.update(variables)
    try:
        runs = [idle_server([])[0] for _ in range(RUNS)]
    finally:
        os.environ.clear()
        os.environ.update(saved)
    return tuple(statistics.median(r[i] for r in runs) for i in range(3))  # type: ignore[return-value]


def main() -> int:
    print(f"startup: median of {RUNS} runs each")
    print(f"{'idle server':<40} {'RSS MB':>8} {'RssAnon':>8} {'RssFile':>8}")
    for label, variables in (
        ("no SIMBRIDGE_* variable", {}),
        ("SIMBRIDGE_LOG_LEVEL=info", {"SIMBRIDGE_LOG_LEVEL": "info"}),
    ):
        rss, anon, file = _memory(variables)
        print(f"{label:<40} {rss:>8.1f} {anon:>8.1f} {file:>8.1f}")
    print(f"{'cold start (spawn -> first /odom)':<40} {'s':>8}")
    plain = statistics.median(cold_start(None) for _ in range(RUNS))
    print(f"{'no CPU limit':<40} {plain:>8.2f}")
    try:
        budget = CpuBudget(PI_CORES)
    except OSError as err:
        print(f"{'Pi 4B budget':<40} skipped (no cgroup: {err.strerror})")
        return 0
    try:
        pi = statistics.median(cold_start(budget) for _ in range(RUNS))
    finally:
        budget.remove()
    print(f"{f'Pi 4B budget ({PI_CORES:g} core)':<40} {pi:>8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
