"""Cyclone DDS's own warnings, read back: the samples it refused before simbridge saw them.

Cyclone checks each sample from the network against the reader's type (its ``normalize`` of
the CDR) on its receive thread and drops one that does not fit, saying so in a warning of its
log, never to the application. A DDS node that carries no XTypes type information (rmw_fastrtps
and rmw_cyclonedds do not) matches simbridge's reader by the type's name alone, so a payload of
another layout under that name (a message of another distro's definition, a node's own type of
the same name) ends there. :class:`CycloneTrace` gives Cyclone a pipe as its trace file
(``Tracing/OutputFile``, warnings and errors only) and hands the refusals it reads to the event
loop; :func:`refused_sample` reads one line.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import os
import re
import select
import threading
from collections.abc import Callable
from dataclasses import dataclass


__all__ = ["CycloneTrace", "RefusedSample", "refused_sample"]

#: Cyclone's line for a sample it could not read (``ddsi_receive.c``):
#: ``data(application, vendor 1.15): 10f7f01:b038bf5c:0:203 #1: deserialization
#: rt/cmd_vel/geometry_msgs::msg::dds_::Twist_ failed (for reasons unknown)``
_REFUSED = re.compile(
    r"data\(application, vendor [^)]*\): ((?:[0-9a-f]+:){3}[0-9a-f]+) #\d+: "
    r"deserialization (\S*)/([^/\s]+) failed \(([^)]*)\)"
)
#: Bytes of the pipe read at once, and lines kept for the event loop at most between two of
#: its callbacks (a flood of refusals is counted, not queued).
_READ = 65536
_PENDING = 1000
#: Linux's fcntl to size a pipe, and the size asked for.
F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)
PIPE_BYTES = 1 << 20


@dataclass(frozen=True, slots=True)
class RefusedSample:
    """A sample Cyclone refused: whose, on which DDS topic, of which DDS type, and why."""

    writer: bytes  # the writer's GUID (16 bytes)
    topic: str  # ``rt/cmd_vel``
    type: str  # ``geometry_msgs::msg::dds_::Twist_``
    reason: str


def refused_sample(line: str) -> RefusedSample | None:
    """Return the refusal a line of Cyclone's log says, or None for any other line."""
    match = _REFUSED.search(line)
    if match is None:
        return None
    words = match.group(1).split(":")
    writer = b"".join(int(word, 16).to_bytes(4, "big") for word in words)
    return RefusedSample(writer, match.group(2), match.group(3), match.group(4))


class CycloneTrace:
    """A pipe that Cyclone writes its trace to, read by a thread of its own.

    Give :attr:`path` to Cyclone (its ``OutputFile``) before the domain is made, then call
    :meth:`opened`; each refused sample reaches ``take`` on ``loop`` (at most
    :data:`_PENDING` waiting: past that they are counted in :attr:`missed` only). :meth:`close`
    stops the thread.
    """

    def __init__(
        self, loop: asyncio.AbstractEventLoop, take: Callable[[list[RefusedSample], int], None]
    ) -> None:
        self._loop = loop
        self._take = take
        self._read_fd, self._write_fd = os.pipe()
        # room for a burst of Cyclone's lines while this thread waits for the GIL (a full pipe
        # would hold Cyclone's receive thread): 1 MiB, Linux's default most
        with contextlib.suppress(OSError):
            fcntl.fcntl(self._write_fd, F_SETPIPE_SZ, PIPE_BYTES)
        #: Where Cyclone writes (this process's end of the pipe).
        self.path = f"/proc/self/fd/{self._write_fd}"
        self._lock = threading.Lock()
        self._pending: list[RefusedSample] = []
        #: Refusals past :data:`_PENDING` since the last hand-over.
        self.missed = 0
        self._rung = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="simbridge-dds-trace", daemon=True)

    def opened(self) -> None:
        """Cyclone opened :attr:`path` (or failed to): start reading."""
        os.close(self._write_fd)  # Cyclone holds its own; the pipe ends when it closes it
        self._write_fd = -1
        self._thread.start()

    def close(self) -> None:
        """Stop reading (the thread ends within half a second)."""
        self._stop.set()
        if self._write_fd >= 0:  # never opened
            os.close(self._write_fd)
            self._write_fd = -1
            os.close(self._read_fd)
        elif self._thread.is_alive():
            self._thread.join(1.0)

    def _run(self) -> None:
        rest = b""
        try:
            while not self._stop.is_set():
                ready, _, _ = select.select([self._read_fd], [], [], 0.5)
                if not ready:
                    continue
                data = os.read(self._read_fd, _READ)
                if not data:
                    break  # Cyclone closed its trace
                *lines, rest = (rest + data).split(b"\n")
                found = [r for r in map(refused_sample, map(_text, lines)) if r is not None]
                if found:
                    self._hand_over(found)
        finally:
            os.close(self._read_fd)

    def _hand_over(self, found: list[RefusedSample]) -> None:
        with self._lock:
            room = _PENDING - len(self._pending)
            self._pending.extend(found[:room])
            self.missed += max(0, len(found) - room)
            ring = not self._rung
            self._rung = True
        if ring:
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        with self._lock:
            found, self._pending = self._pending, []
            missed, self.missed = self.missed, 0
            self._rung = False
        if not self._stop.is_set():
            self._take(found, missed)


def _text(line: bytes) -> str:
    return line.decode(errors="replace")
