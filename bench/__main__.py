"""Run the benchmarks: ``python -m bench [NAME ...]`` (default: the quick ones)."""

from __future__ import annotations

import importlib
import sys


#: Benchmarks run by default (quick, under a minute together): module name -> what it measures.
QUICK = {
    "encoding": "/scan and /odom frames for N subscribers vs stdlib json.dumps per subscriber",
    "raycast": "one 360-ray scan against 20, 100 and 500 walls",
    "headless": "headless simulation speed-up over real time",
}


def main(argv: list[str]) -> int:
    names = argv or list(QUICK)
    failed = 0
    for name in names:
        module = importlib.import_module(f"bench.{name}")
        failed += int(module.main() != 0)
        print()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
