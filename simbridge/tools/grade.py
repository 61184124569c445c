"""``simbridge grade``: run a task file on a server (or headless) and write its report.

::

    simbridge grade TASK.yaml --url ws://HOST:9090 [--robot NAME] [--token T] [-o DIR] [-- CMD ...]
    simbridge grade TASK.yaml --headless --controller FILE.py:NAME [--world FILE] [--params FILE]

On a server, the task goes to ``/simbridge/grade/start`` (the server runs it and scores it on
the true pose, as for the page); ``CMD``, if given, is started as the controller once the robot
is at the start pose, with ``SIMBRIDGE_URL``, ``SIMBRIDGE_ROBOT``, ``SIMBRIDGE_TOKEN`` and
``SIMBRIDGE_GOAL`` (the goal in world coordinates, JSON) in its environment, and stopped when
the run ends. ``--headless`` runs the same grader on a :class:`~simbridge.headless.Simulation`
in sim time, as fast as the controller allows: ``NAME(sim, robot, goal)`` (from ``FILE.py``
or a module; ``goal`` as ``SIMBRIDGE_GOAL``) is called once, with the robot at the start pose,
and returns the function called before every step.

Writes ``report.json`` and ``report.html`` (the response with the thresholds drawn) into
``-o DIR`` (default: the current directory) and prints the verdict of each rubric line. Exit
code: 0 passed, 1 failed (or the run ended without a controller, or was cut), 2 the task or
the options are wrong, or the server refused or could not be reached.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib
import importlib.util
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import orjson

from simbridge.errors import ConfigError, SimbridgeError
from simbridge.grading.report import report_html
from simbridge.grading.task import load_task
from simbridge.tools.client import ClientError, RosbridgeClient, run_tool
from simbridge.tools.rostool import DEFAULT_URL


__all__ = ["grade_headless", "grade_main", "grade_remote", "write_report"]

#: Seconds between two status calls while a run goes on.
POLL = 0.25
#: Seconds a controller command gets to stop after SIGTERM before it is killed.
STOP_GRACE = 3.0


def _with_token(url: str, token: str | None) -> str:
    if not token:
        return url
    parts = urlsplit(url)
    query = [(k, v) for k, v in parse_qsl(parts.query) if k != "token"] + [("token", token)]
    return urlunsplit(parts._replace(path=parts.path or "/", query=urlencode(query)))


def write_report(record: dict[str, Any], out: Path) -> tuple[Path, Path]:
    """Write ``report.json`` and ``report.html`` of an attempt into ``out``; return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    report = {k: v for k, v in record.items() if k != "plot_svg"}
    report.setdefault("task", {})
    report["task_id"] = record.get("task_id") or report["task"].get("id")
    json_path, html_path = out / "report.json", out / "report.html"
    json_path.write_bytes(orjson.dumps(report, option=orjson.OPT_INDENT_2) + b"\n")
    html_path.write_text(report_html(report), encoding="utf-8")
    return json_path, html_path


def _print(record: dict[str, Any]) -> None:
    verdict = "PASSED" if record.get("passed") else "FAILED"
    task = record.get("task") or {}
    robot = record.get("robot") or "(default)"
    print(f"{task.get('id', '?')} on robot {robot}: {verdict} ({record.get('status')})")
    if record.get("reason"):
        print(f"  {record['reason']}")
    for line in record.get("rubric") or []:
        print(f"  {'ok  ' if line['passed'] else 'FAIL'} {line['text']}")


async def _stop(proc: asyncio.subprocess.Process | None) -> None:
    if proc is None or proc.returncode is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        proc.send_signal(signal.SIGTERM)
    try:
        await asyncio.wait_for(proc.wait(), STOP_GRACE)
    except TimeoutError:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        await proc.wait()


async def grade_remote(
    url: str,
    task_path: Path,
    *,
    robot: str = "",
    token: str | None = None,
    command: Sequence[str] = (),
    timeout: float = 5.0,
) -> dict[str, Any]:
    """Run the task file on the server at ``url``; return the attempt's record.

    Raises:
        ConfigError: the task file is invalid.
        ClientError: the server cannot be reached, or refused the run.
    """
    task = load_task(task_path)
    text = task_path.read_text(encoding="utf-8")
    async with RosbridgeClient.connect(_with_token(url, token), timeout) as ros:
        started = await ros.call_service(
            "/simbridge/grade/start", {"task": task.id, "task_yaml": text, "robot": robot}
        )
        state = orjson.loads(started.get("message") or "{}")
        attempt = str(state["attempt"])
        robot = str(state.get("robot", robot))
        print(
            f"attempt {attempt}: task '{task.id}' on robot '{robot or '(default)'}'"
            + ("" if state.get("official") else " (not an official copy of a published task)"),
            file=sys.stderr,
            flush=True,
        )
        proc = None
        if command:
            env = {
                **os.environ,
                "SIMBRIDGE_URL": url,
                "SIMBRIDGE_ROBOT": robot,
                "SIMBRIDGE_GOAL": orjson.dumps(state.get("goal")).decode(),
            }
            if token:
                env["SIMBRIDGE_TOKEN"] = token
            proc = await asyncio.create_subprocess_exec(*command, env=env)
        deadline = time.monotonic() + task.wait_for_controller + task.time_limit + 30.0
        try:
            while True:
                values = await ros.call_service("/simbridge/grade/status", {"attempt": attempt})
                record: dict[str, Any] = orjson.loads(values.get("message") or "{}")
                if record.get("status") not in ("waiting", "running"):
                    return record
                if time.monotonic() > deadline:
                    msg = f"attempt {attempt} did not end in time (status {record.get('status')})"
                    raise ClientError(msg)
                await asyncio.sleep(POLL)
        finally:
            await _stop(proc)


def _load_controller(spec: str) -> Callable[..., Any]:
    target, _, name = spec.rpartition(":")
    if not target or not name:
        msg = f"--controller {spec!r}: expected FILE.py:NAME or MODULE:NAME"
        raise ConfigError(msg)
    try:
        if target.endswith(".py"):
            found = importlib.util.spec_from_file_location("simbridge_controller", target)
            if found is None or found.loader is None:
                raise ImportError(target)
            module = importlib.util.module_from_spec(found)
            found.loader.exec_module(module)
        else:
            module = importlib.import_module(target)
    except (ImportError, OSError) as err:
        msg = f"--controller {spec!r}: cannot load {target}: {err}"
        raise ConfigError(msg) from None
    func = getattr(module, name, None)
    if not callable(func):
        msg = f"--controller {spec!r}: {target} has no function {name}"
        raise ConfigError(msg)
    return func  # type: ignore[no-any-return]


def grade_headless(
    task_path: Path,
    controller: Callable[..., Any],
    *,
    world: str | None = None,
    params: str | None = None,
    robot: str | None = None,
    bags: Path | None = None,
) -> dict[str, Any]:
    """Run the task on a headless simulation driven by ``controller``; return the record.

    ``controller(sim, robot, goal)`` returns the function called before every step.

    Raises:
        ConfigError: the task, world or parameter file is invalid.
    """
    from simbridge.headless import Simulation

    task = load_task(task_path)
    if world is None and task.world is not None:
        world = str((task_path.parent / task.world).resolve())
    sim = Simulation(world, params, bags=bags)
    grader = sim.grader
    name = robot if robot is not None else next(iter(sim.world.robots))
    run = grader.start(None, name, task, official=False)
    step = controller(sim, name, run.goal.as_dict())
    if not callable(step):
        msg = "the controller must return the function to call before every step"
        raise ConfigError(msg)
    limit = round((task.wait_for_controller + task.time_limit) / sim.dt) + 10
    for _ in range(limit):
        if name not in grader.runs:
            break
        step()
        sim.step()
    if name in grader.runs:
        grader.cancel(name, "the run did not end")
    return grader.results.attempts[run.attempt]


def grade_main(argv: Sequence[str]) -> int:
    """Run ``simbridge grade``; return the exit code."""
    argv = list(argv)
    command: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, command = argv[:i], argv[i + 1 :]
    parser = argparse.ArgumentParser(
        prog="simbridge grade",
        description="Run a task file on a simbridge server (or headless) and score it on the "
        "true pose: report.json and report.html, exit 0 on pass, 1 on fail, 2 on an error.",
        epilog="-- CMD ...: the controller to start once the robot is at the start pose "
        "(it gets SIMBRIDGE_URL, SIMBRIDGE_ROBOT, SIMBRIDGE_TOKEN, SIMBRIDGE_GOAL)",
    )
    parser.add_argument("task", help="the task file (YAML)")
    parser.add_argument(
        "--url",
        default=os.environ.get("SIMBRIDGE_URL", DEFAULT_URL),
        help=f"rosbridge server (default: $SIMBRIDGE_URL or {DEFAULT_URL})",
    )
    parser.add_argument("--robot", default=None, help="robot to run on (default: your own)")
    parser.add_argument(
        "--token",
        default=os.environ.get("SIMBRIDGE_TOKEN"),
        help="your token (default: $SIMBRIDGE_TOKEN)",
    )
    parser.add_argument("-o", "--output", default=".", help="report directory (default: .)")
    parser.add_argument("--timeout", type=float, default=5.0, help="connect timeout, seconds")
    parser.add_argument(
        "--headless", action="store_true", help="no server: a headless simulation, sim time"
    )
    parser.add_argument(
        "--controller",
        help="with --headless: FILE.py:NAME or MODULE:NAME, NAME(sim, robot, goal)",
    )
    parser.add_argument("--world", help="with --headless: world file (default: the task's)")
    parser.add_argument("--params", help="with --headless: parameter file")
    args = parser.parse_args(argv)
    out = Path(args.output)
    try:
        if args.headless:
            if not args.controller:
                parser.error("--headless needs --controller FILE.py:NAME")
            record = grade_headless(
                Path(args.task),
                _load_controller(args.controller),
                world=args.world,
                params=args.params,
                robot=args.robot,
                bags=out / "bags",
            )
        else:
            record = run_tool(
                grade_remote(
                    args.url,
                    Path(args.task),
                    robot=args.robot or "",
                    token=args.token,
                    command=command,
                    timeout=args.timeout,
                )
            )
    except (ConfigError, ClientError) as err:
        print(f"simbridge grade: {err}", file=sys.stderr)
        return 2
    except SimbridgeError as err:
        print(f"simbridge grade: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    json_path, html_path = write_report(record, out)
    _print(record)
    print(f"report: {json_path} {html_path}")
    return 0 if record.get("passed") else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(grade_main(sys.argv[1:]))
