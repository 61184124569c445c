"""The class's results: an append-only journal of JSON lines, read back at start.

Every event is one line, written with a single ``write`` on a file opened for appending, so
that a crash or ``kill -9`` can at worst leave the last line incomplete, never an earlier one,
and flushed to disk (``fsync``). Given an ``offload`` (the server's: a worker thread of its
event loop), the ``fsync`` runs there (on an SD card it took long enough to stall the
simulation's tick): the lines are written in order by the caller, and one ``fsync`` at a time
flushes all those written before it; :meth:`close` flushes what is left. Without one, or when
it cannot run, the ``fsync`` runs before the call returns:

* ``{"kind": "start", "attempt": "a7", "task": ..., "robot": ..., "student": ..., "time": ...}``
  when a run begins;
* ``{"kind": "result", "attempt": "a7", "status": "passed" | "failed" | "interrupted" | ...,
  ...}`` when it ends (the whole report);
* ``{"kind": "publish" | "withdraw", "task": ID, "time": ...}`` when the instructor publishes
  or withdraws a task.

Reading back (:meth:`ResultsLog.open`): a line that does not parse (the torn last line of a
crash) is skipped and counted; the file is first ended with a newline so that the next line
starts clean. A ``start`` without its ``result`` is an attempt the restart cut: it is recorded
(appended) as ``interrupted``.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson


__all__ = ["Offload", "ResultsLog"]

logger = logging.getLogger(__name__)

#: Attempt statuses that end a run.
FINISHED = frozenset({"passed", "failed", "interrupted", "no_controller", "cancelled", "error"})


#: Runs ``work`` off the caller's thread, then ``done(error)`` back on it (``error``: what
#: ``work`` raised, or None); returns False, having run nothing, when it cannot.
Offload = Callable[[Callable[[], None], Callable[[BaseException | None], None]], bool]


def _fsync_and_close(fd: int) -> None:
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class ResultsLog:
    """The attempts and published tasks, kept in memory and (with a path) in a journal file.

    Args:
        path: the journal; None keeps results in memory only (lost on restart).
        clock: wall-clock seconds (Unix time), for the lines' ``time``.
        offload: where each ``fsync`` runs (None: in the call that wrote the line).
    """

    def __init__(
        self,
        path: Path | None = None,
        *,
        clock: Any = time.time,
        offload: Offload | None = None,
    ) -> None:
        self.path = path
        self.clock = clock
        self.offload = offload
        #: Attempts by id, oldest first: their start line merged with their result line.
        self.attempts: dict[str, dict[str, Any]] = {}
        #: Task ids published, in the order they were published.
        self.published: list[str] = []
        #: Lines that did not parse when the file was read.
        self.bad_lines = 0
        self._next = 1
        self._fd: int | None = None
        #: An ``fsync`` runs on a worker thread; lines were written since it began.
        self._syncing = False
        self._dirty = False

    # -- the file -------------------------------------------------------------------------

    def open(self) -> list[str]:
        """Read the journal back and open it for appending; return the attempts it cut short.

        Raises:
            OSError: the file cannot be read or created.
        """
        if self.path is None:
            return []
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists():
            data = self.path.read_bytes()
            for raw in data.splitlines():
                if not raw.strip():
                    continue
                try:
                    line = orjson.loads(raw)
                except orjson.JSONDecodeError:
                    self.bad_lines += 1
                    continue
                if isinstance(line, dict):
                    self._apply(line)
                else:
                    self.bad_lines += 1
            torn = bool(data) and not data.endswith(b"\n")
        else:
            torn = False
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        if torn:
            os.write(self._fd, b"\n")  # the torn line stays a line of its own
        if self.bad_lines:
            logger.warning(
                "results file %s: %d line(s) did not parse and were skipped (a crash mid-write)",
                self.path,
                self.bad_lines,
            )
        cut = [a for a, rec in self.attempts.items() if rec.get("status") == "running"]
        for attempt in cut:
            self.finish(
                attempt,
                {
                    "status": "interrupted",
                    "passed": False,
                    "reason": "the server stopped during this attempt",
                },
            )
        logger.info(
            "results file %s: %d attempts read back (%d interrupted by the restart)",
            self.path,
            len(self.attempts),
            len(cut),
        )
        return cut

    def close(self) -> None:
        """Close the journal."""
        if self._fd is not None:
            if self._syncing or self._dirty:
                os.fsync(self._fd)  # what the worker thread has not flushed yet
            os.close(self._fd)
            self._fd = None
            self._dirty = False

    def _append(self, line: dict[str, Any]) -> None:
        self._apply(line)
        if self._fd is None:
            return
        data = orjson.dumps(line, option=orjson.OPT_SERIALIZE_NUMPY) + b"\n"
        os.write(self._fd, data)  # one write on an O_APPEND file: never interleaved
        self._sync()

    def _sync(self) -> None:
        """Flush the lines written to disk: off the loop when there is one, one at a time."""
        if self._fd is None:
            return
        if self._syncing:
            self._dirty = True  # flushed by the next fsync, once this one ends
            return
        if self.offload is None:
            os.fsync(self._fd)
            return
        fd = os.dup(self._fd)  # the worker's own: close() never pulls it from under it
        if not self.offload(lambda: _fsync_and_close(fd), self._synced):
            os.close(fd)  # it cannot run now (no loop, or its executor shut down): flush here
            os.fsync(self._fd)
            return
        self._syncing, self._dirty = True, False

    def _synced(self, err: BaseException | None) -> None:
        self._syncing = False
        if err is not None:
            logger.error("results file %s: fsync failed: %s", self.path, err)
        if self._dirty:
            self._sync()

    def _apply(self, line: dict[str, Any]) -> None:
        kind = line.get("kind")
        if kind == "start":
            attempt = str(line.get("attempt"))
            self.attempts[attempt] = {**line, "status": "running"}
            self._bump(attempt)
        elif kind == "result":
            attempt = str(line.get("attempt"))
            self.attempts[attempt] = {**self.attempts.get(attempt, {}), **line}
            self._bump(attempt)
        elif kind == "publish":
            task = str(line.get("task"))
            if task not in self.published:
                self.published.append(task)
        elif kind == "withdraw":
            task = str(line.get("task"))
            if task in self.published:
                self.published.remove(task)

    def _bump(self, attempt: str) -> None:
        digits = attempt.lstrip("a")
        if digits.isdigit():
            self._next = max(self._next, int(digits) + 1)

    # -- events ---------------------------------------------------------------------------

    def new_id(self) -> str:
        """Return an attempt id not used before (also across restarts)."""
        attempt = f"a{self._next}"
        self._next += 1
        return attempt

    def start(self, attempt: str, fields: dict[str, Any]) -> None:
        """Record that ``attempt`` began."""
        self._append({"kind": "start", "attempt": attempt, "time": self.clock(), **fields})

    def finish(self, attempt: str, fields: dict[str, Any]) -> None:
        """Record how ``attempt`` ended (``fields`` holds its ``status`` and report)."""
        self._append({"kind": "result", "attempt": attempt, "ended": self.clock(), **fields})

    def publish(self, task: str, published: bool) -> None:
        """Record that the instructor published (or withdrew) ``task``."""
        if (task in self.published) == published:
            return
        kind = "publish" if published else "withdraw"
        self._append({"kind": kind, "task": task, "time": self.clock()})
