"""Before/after: benchmarks of a baseline checkout and of this one, side by side in one run.

``python -m bench quick --baseline DIR`` (or ``python -m bench.baseline DIR NAME ...``) runs each
named benchmark in fresh processes, alternating (``BASELINE_ROUNDS`` runs of each, default 1;
each figure is then the median of its runs): "before" as the checkout at
``DIR`` has it (its own code and virtualenv: ``DIR/.venv/bin/python -m bench.NAME`` in ``DIR``)
and "after" here. A benchmark the baseline does not have runs from this checkout's
``bench/NAME.py`` against the baseline's ``simbridge`` (``PYTHONPATH=DIR``), when it imports
only what the baseline has; otherwise it is shown for "after" only.

The outputs are then set side by side: every line both runs print with the same words (numbers
aside) is shown as ``before``, ``after`` and ``ratio``, the ratio being after / before of each
figure that differs (a figure printed the same in both, such as a client count, is shown as it
is). Whether a ratio above 1 is better depends on the column: times and CPU want below 1,
speed-ups and rates above 1.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
from collections import defaultdict, deque
from pathlib import Path

from bench.procs import ROOT


#: A figure in a benchmark's output: a number, with an ``x`` or ``%`` after it, if any.
_FIGURE = re.compile(r"(?<![\w.])(-?\d+(?:\.\d+)?)(?=[x%]?(?![\w.]))")


def python_of(checkout: Path) -> str:
    """Return the Python of a checkout's virtualenv (``make deps`` made it)."""
    python = checkout / ".venv" / "bin" / "python"
    if not python.exists():
        msg = f"{checkout} has no .venv: run 'make deps' there first"
        raise SystemExit(msg)
    return str(python)


def describe(checkout: Path) -> str:
    """Return ``DIR (commit)`` for the heading."""
    head = subprocess.run(
        ["git", "-C", str(checkout), "log", "-1", "--format=%h"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return f"{checkout} ({head or '?'})"


def run(name: str, checkout: Path, args: list[str]) -> tuple[int, str]:
    """Run ``bench.NAME`` as ``checkout`` has it; return its exit code and its output."""
    env = dict(os.environ)
    if checkout == ROOT:
        cmd = [sys.executable, "-m", f"bench.{name}", *args]
    elif (checkout / "bench" / f"{name}.py").exists():
        cmd = [python_of(checkout), "-m", f"bench.{name}", *args]
    else:  # a benchmark newer than the baseline: ours, on the baseline's simbridge
        # run_path, not the script itself: bench/ first on sys.path would shadow the stdlib's
        # http with bench/http.py
        path = str(ROOT / "bench" / f"{name}.py")
        code = "import runpy, sys; sys.argv[0] = sys.argv[1]; del sys.argv[1]; "
        code += "runpy.run_path(sys.argv[0], run_name='__main__')"
        cmd = [python_of(checkout), "-c", code, path, *args]
        env["PYTHONPATH"] = os.pathsep.join([str(checkout), str(ROOT)])
    proc = subprocess.run(cmd, cwd=checkout, env=env, capture_output=True, text=True, check=False)
    out = proc.stdout
    if proc.returncode != 0 and proc.stderr:
        out += "".join(f"  ! {line}\n" for line in proc.stderr.strip().splitlines()[-3:])
    return proc.returncode, out


def _shape(line: str) -> str:
    """The line's words with its figures as ``#``, spacing ignored (columns are padded)."""
    return " ".join(_FIGURE.sub("#", line).split())


def _ratio_line(before: str, after: str) -> str:
    """``after`` with each figure that differs from ``before`` replaced by after / before.

    A ratio ends in the column where its figure ended (taking spaces before it), so that the
    columns of the table stay aligned.
    """
    old = [float(m.group(1)) for m in _FIGURE.finditer(before)]
    line = after
    for k, m in reversed(list(enumerate(_FIGURE.finditer(after)))):
        new = float(m.group(1))
        start, end = m.span(1)
        if after[end : end + 1] in ("x", "%"):
            end += 1
        if new == old[k]:
            continue
        text = f"{new / old[k]:.2f}x" if old[k] else "n/a"
        left = start
        while left > 0 and line[left - 1] == " " and end - left < len(text) + 1:
            left -= 1
        if end - left >= len(text) + 1:  # room for the ratio and one space before it
            line = line[:left] + text.rjust(end - left) + line[end:]
        else:
            line = line[:start] + text + line[end:]
    return line


def side_by_side(before: str, after: str) -> str:
    """Return the two outputs as before / after / ratio rows (see the module docstring)."""
    waiting: dict[str, deque[str]] = defaultdict(deque)
    for line in before.splitlines():
        waiting[_shape(line)].append(line)
    rows: list[str] = []
    for line in after.splitlines():
        queue = waiting.get(_shape(line))
        if not queue:
            rows.append(f"after  | {line}")
            continue
        old = queue.popleft()
        if old == line:
            rows.append(f"       | {line}")
            continue
        rows.append(f"before | {old}")
        rows.append(f"after  | {line}")
        rows.append(f"ratio  | {_ratio_line(old, line)}")
    left = [line for queue in waiting.values() for line in queue]
    rows.extend(f"before | {line}" for line in left)
    return "\n".join(rows)


def median_output(outputs: list[str]) -> str:
    """Return the first output with each figure replaced by its median over ``outputs``.

    A line's figures are taken from the same-shaped line of each output (the first, second...
    of that shape); a line some output lacks is kept as the first output printed it.
    """
    if len(outputs) == 1:
        return outputs[0]
    shaped: list[dict[str, list[str]]] = []
    for out in outputs:
        by_shape: dict[str, list[str]] = defaultdict(list)
        for line in out.splitlines():
            by_shape[_shape(line)].append(line)
        shaped.append(by_shape)
    seen: dict[str, int] = defaultdict(int)
    lines = []
    for line in outputs[0].splitlines():
        shape = _shape(line)
        k = seen[shape]
        seen[shape] += 1
        peers = [by_shape[shape][k] for by_shape in shaped if len(by_shape[shape]) > k]
        if len(peers) < len(outputs):
            lines.append(line)
            continue
        columns = [[float(m.group(1)) for m in _FIGURE.finditer(p)] for p in peers]
        figures = list(zip(_FIGURE.finditer(line), zip(*columns, strict=True), strict=True))
        for m, values in reversed(figures):
            token = m.group(1)
            decimals = len(token.partition(".")[2])
            text = f"{statistics.median(values):.{decimals}f}"
            start, end = m.span(1)
            line = line[:start] + text.rjust(len(token)) + line[end:]
        lines.append(line)
    return "\n".join(lines)


def compare(
    names: list[str], baseline: Path, args: list[str] | None = None, rounds: int | None = None
) -> int:
    """Run each benchmark before and after; print them side by side; return 1 if one failed.

    ``rounds`` (default ``BASELINE_ROUNDS``, 1): runs of each, the order alternating (before
    first, then after first...), each figure the median of its runs.
    """
    rounds = rounds or int(os.environ.get("BASELINE_ROUNDS", "1"))
    print(f"before: {describe(baseline)}")
    print(f"after:  {describe(ROOT)}")
    print(f"{rounds} run(s) of each, alternating; ratio = after / before of each figure")
    failed = 0
    for name in names:
        outs: dict[Path, list[str]] = {baseline: [], ROOT: []}
        codes: dict[Path, int] = {baseline: 0, ROOT: 0}
        for r in range(rounds):
            for checkout in (baseline, ROOT) if r % 2 == 0 else (ROOT, baseline):
                code, out = run(name, checkout, args or [])
                codes[checkout] = max(codes[checkout], code)
                outs[checkout].append(out)
        failed += int(codes[ROOT] != 0)
        print(f"\n=== {name} (exit codes: before {codes[baseline]}, after {codes[ROOT]}) ===")
        print(side_by_side(median_output(outs[baseline]), median_output(outs[ROOT])), flush=True)
    return 1 if failed else 0


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print("usage: python -m bench.baseline DIR NAME [NAME ...]", file=sys.stderr)
        return 2
    return compare(argv[1:], Path(argv[0]).resolve())


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
