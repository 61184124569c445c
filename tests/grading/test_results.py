"""The results journal survives a torn last line and records cut attempts as interrupted."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import sys
import threading
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import orjson

from simbridge.app.runner import offload
from simbridge.grading.results import ResultsLog
from simbridge.tools.client import RosbridgeClient
from tests.helpers import ROOT, TIMEOUT_FACTOR


def test_a_torn_last_line_and_an_unfinished_attempt_after_a_crash(tmp_path: Path) -> None:
    path = tmp_path / "results.jsonl"
    log = ResultsLog(path)
    log.open()
    for attempt in ("a1", "a2"):
        log.start(attempt, {"task_id": "t", "robot": "r1"})
        log.finish(attempt, {"status": "passed", "passed": True})
    log.start(log.new_id(), {"task_id": "t", "robot": "r1"})  # a3: the crash comes now
    log.publish("t", True)
    log.close()
    with path.open("ab") as f:
        f.write(b'{"kind": "result", "attempt": "a3", "sta')  # torn mid-write
    again = ResultsLog(path)
    assert again.open() == ["a3"]
    assert again.bad_lines == 1
    assert [r["status"] for r in again.attempts.values()] == ["passed", "passed", "interrupted"]
    assert again.published == ["t"]
    assert again.new_id() == "a4"
    again.start("a4", {"task_id": "t"})
    again.close()
    lines = path.read_bytes().splitlines()
    parsed = []
    for raw in lines:
        try:
            parsed.append(orjson.loads(raw))
        except orjson.JSONDecodeError:
            assert raw.startswith(b'{"kind": "result", "attempt": "a3", "sta')
    assert parsed[-1]["attempt"] == "a4"  # the next line starts clean after the torn one
    assert sum(1 for p in parsed if p.get("status") == "interrupted") == 1


def test_without_a_file_results_stay_in_memory() -> None:
    log = ResultsLog(None)
    assert log.open() == []
    log.start("a1", {})
    assert log.attempts["a1"]["status"] == "running"


QUICK = """
name: quick turn
goal: {heading: 0.5}
time_limit: 0.5
rubric: {overshoot_pct: {max: 50}}
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextlib.asynccontextmanager
async def _server(results: Path, tasks: Path) -> AsyncIterator[str]:
    """A simbridge process on a free port (killed with SIGKILL on exit); yields its URL."""
    port = _free_port()
    proc = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "simbridge", "--host", "127.0.0.1", "--port", str(port)),
        *("--no-http", "--results", str(results), "--tasks", str(tasks)),
        cwd=ROOT,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
    )
    try:
        assert proc.stdout is not None
        line = await asyncio.wait_for(proc.stdout.readline(), 20 * TIMEOUT_FACTOR)
        assert b"rosbridge ws://" in line, line
        yield f"ws://127.0.0.1:{port}"
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGKILL)
        await proc.wait()


async def _call(ros: RosbridgeClient, service: str, **args: str) -> Any:
    values = await ros.call_service(f"/simbridge/grade/{service}", args)
    return orjson.loads(values["message"])


async def _attempt(url: str, *, finish: bool) -> str:
    async with RosbridgeClient.connect(url) as ros:
        attempt = str((await _call(ros, "start", task="quick"))["attempt"])
        if not finish:
            return attempt
        twist = {"linear": {"x": 0.0}, "angular": {"z": 1.0}}
        await ros.publish("/cmd_vel", twist, "geometry_msgs/msg/Twist")
        for _ in range(100):
            if (await _call(ros, "status", attempt=attempt))["status"] not in (
                "waiting",
                "running",
            ):
                return attempt
            await asyncio.sleep(0.05)
    raise AssertionError(f"attempt {attempt} did not end")


async def test_kill_9_between_two_attempts_and_during_a_third(tmp_path: Path) -> None:
    """Two server processes, each killed with SIGKILL; the file is read back as at a start."""
    tasks = tmp_path / "tasks"
    tasks.mkdir()
    (tasks / "quick.yaml").write_text(QUICK)
    results = tmp_path / "results.jsonl"
    async with _server(results, tasks) as url:
        first = await _attempt(url, finish=True)
    async with _server(results, tasks) as url:  # the first server was killed after one attempt
        async with RosbridgeClient.connect(url) as ros:
            after_restart = (await _call(ros, "results"))["attempts"]
        second = await _attempt(url, finish=True)
        third = await _attempt(url, finish=False)  # waiting for its controller: killed now
    assert [(a["attempt"], a["status"]) for a in after_restart] == [(first, "passed")]
    lines = [orjson.loads(raw) for raw in results.read_bytes().splitlines()]  # every line parses
    assert [line["kind"] for line in lines] == ["start", "result"] * 2 + ["start"]
    log = ResultsLog(results)  # what the next start does
    assert log.open() == [third]
    log.close()
    statuses = {a: r["status"] for a, r in log.attempts.items()}
    assert statuses == {first: "passed", second: "passed", third: "interrupted"}
    assert len(results.read_bytes().splitlines()) == 6


async def test_on_the_loop_the_fsync_runs_off_it_and_every_line_is_kept(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """An attempt's start and end are written in order; their fsync never holds the loop."""
    synced: list[int] = []
    real_fsync = os.fsync

    def fsync(fd: int) -> None:
        synced.append(threading.get_ident())
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    path = tmp_path / "results.jsonl"
    log = ResultsLog(path, offload=offload)
    log.open()
    for attempt in ("a1", "a2", "a3"):
        log.start(attempt, {"task_id": "t"})
        log.finish(attempt, {"status": "passed", "passed": True})
    async with asyncio.timeout(5 * TIMEOUT_FACTOR):
        while getattr(log, "_syncing", False):
            await asyncio.sleep(0.01)
    assert synced and threading.get_ident() not in synced
    log.close()
    again = ResultsLog(path)
    assert again.open() == []
    assert again.bad_lines == 0
    assert list(again.attempts) == ["a1", "a2", "a3"]
    assert [r["status"] for r in again.attempts.values()] == ["passed"] * 3
