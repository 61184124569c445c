"""Cyclone DDS's own log, read back: the samples it refused, and whatever else it had to say.

Cyclone checks each sample from the network against the reader's type (its ``normalize`` of
the CDR) on its receive thread and drops one that does not fit, saying so in a warning of its
log, never to the application. A DDS node that carries no XTypes type information (rmw_fastrtps
and rmw_cyclonedds do not) matches simbridge's reader by the type's name alone, so a payload of
another layout under that name (a message of another distro's definition, a node's own type of
the same name) ends there, one warning per sample.

A domain's log (its errors and warnings) goes to the C library's ``stderr`` as it is when the
domain is made (``ddsi_config_open_trace`` in ``ddsi_init.c``, ``q_init.c`` in 0.10: its
``dds_log_cfg_init`` takes ``stderr`` for the log and the ``Tracing/OutputFile`` for the trace,
and ``ddsrt/src/log.c``'s ``vlog1`` writes every message of those categories to the log, traced
or not); the library's log sinks (``dds_set_log_sink``) are not exported by the binding's
Cyclone 11. So :meth:`CycloneTrace.domain_log` points ``stderr`` at a pipe while the domain is
made: that domain's log then reaches simbridge only, and none of it reaches stderr, whatever a
sender does. The library's own global messages (``DDS_FATAL``, configuration errors,
``DDS_ILOG``) keep stderr. A thread reads the pipe and hands the refusals (:func:`refused_sample`)
and the other lines (:func:`cyclone_line`, counted by kind) to the event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import fcntl
import os
import re
import select
import threading
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any


__all__ = ["CycloneLine", "CycloneTrace", "RefusedSample", "cyclone_line", "refused_sample"]

#: Cyclone's line for a sample it could not read (``ddsi_receive.c``):
#: ``data(application, vendor 1.15): 10f7f01:b038bf5c:0:203 #1: deserialization
#: rt/cmd_vel/geometry_msgs::msg::dds_::Twist_ failed (for reasons unknown)``
_REFUSED = re.compile(
    r"data\(application, vendor [^)]*\): ((?:[0-9a-f]+:){3}[0-9a-f]+) #\d+: "
    r"deserialization (\S*)/([^/\s]+) failed \(([^)]*)\)"
)
#: The header ``log.c`` puts before each line: seconds.micros, [domain], the thread's name.
_HEADER = re.compile(r"^\s*\d+\.\d+ \[\d*\]\s+\S+: ")
#: What varies between two lines of one kind: numbers, GUIDs, addresses.
_VARIES = re.compile(r"[0-9a-fA-Fx.:]*[0-9][0-9a-fA-Fx.:]*")
#: Characters of a line that make its kind at most.
_KIND = 80
#: Bytes of the pipe read at once, and lines kept for the event loop at most between two of
#: its callbacks (a flood is counted, not queued): refusals, and kinds of other lines.
_READ = 65536
_PENDING = 1000
KINDS = 100
#: Linux's fcntl to size a pipe, and the size asked for.
F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)
PIPE_BYTES = 1 << 20

_libc = ctypes.CDLL(None, use_errno=True)
_libc.fdopen.restype = ctypes.c_void_p
_libc.fdopen.argtypes = [ctypes.c_int, ctypes.c_char_p]
_libc.fclose.argtypes = [ctypes.c_void_p]
#: The C library's ``stderr`` (a ``FILE *``), which Cyclone reads when it makes a domain.
_stderr = ctypes.c_void_p.in_dll(_libc, "stderr")
#: One domain made at a time while ``stderr`` is pointed elsewhere.
_swap = threading.Lock()


@dataclass(frozen=True, slots=True)
class RefusedSample:
    """A sample Cyclone refused: whose, on which DDS topic, of which DDS type, and why."""

    writer: bytes  # the writer's GUID (16 bytes)
    topic: str  # ``rt/cmd_vel``
    type: str  # ``geometry_msgs::msg::dds_::Twist_``
    reason: str


@dataclass(frozen=True, slots=True)
class CycloneLine:
    """Another line of Cyclone's log: its kind (the text without what varies) and its text."""

    kind: str
    text: str


def refused_sample(line: str) -> RefusedSample | None:
    """Return the refusal a line of Cyclone's log says, or None for any other line."""
    match = _REFUSED.search(line)
    if match is None:
        return None
    words = match.group(1).split(":")
    writer = b"".join(int(word, 16).to_bytes(4, "big") for word in words)
    return RefusedSample(writer, match.group(2), match.group(3), match.group(4))


def cyclone_line(line: str) -> CycloneLine | None:
    """Return a line of Cyclone's log without its header, with its kind; None if blank."""
    text = _HEADER.sub("", line, count=1).strip()
    if not text:
        return None
    return CycloneLine(_VARIES.sub("#", text)[:_KIND], text)


class CycloneTrace:
    """A pipe that Cyclone writes a domain's log to, read by a thread of its own.

    Make the domain inside :meth:`domain_log`, then call :meth:`opened`; what Cyclone says
    reaches ``take(refused, lines, missed)`` on ``loop``: the refused samples (at most
    :data:`_PENDING` waiting; past that they are counted in ``missed`` only) and the other
    lines, by kind (a count and the last line of each, :data:`KINDS` kinds at most, the rest
    under ``"other"``). :meth:`close` stops the thread, once the domain is deleted.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        take: Callable[[list[RefusedSample], dict[str, tuple[int, str]], int], None],
        ddsc: Any,
    ) -> None:
        self._loop = loop
        self._take = take
        self._ddsc = ddsc  # the binding's libddsc (ctypes)
        self._read_fd, self._write_fd = os.pipe()
        # room for a burst of Cyclone's lines while this thread waits for the GIL (a full pipe
        # would hold Cyclone's receive thread): 1 MiB, Linux's default most
        with contextlib.suppress(OSError):
            fcntl.fcntl(self._write_fd, F_SETPIPE_SZ, PIPE_BYTES)
        #: The ``FILE *`` Cyclone writes to (it owns the pipe's write end).
        self._file: int | None = _libc.fdopen(self._write_fd, b"w")
        if not self._file:
            os.close(self._write_fd)
            os.close(self._read_fd)
            raise OSError(ctypes.get_errno(), "fdopen of Cyclone's log pipe failed")
        #: False once a domain failed to start inside :meth:`domain_log`: Cyclone may then
        #: keep the file as its global log (``ddsi_config_fini``), so it is never closed.
        self._closable = True
        self._lock = threading.Lock()
        self._pending: list[RefusedSample] = []
        self._lines: dict[str, tuple[int, str]] = {}
        #: Refusals past :data:`_PENDING` since the last hand-over.
        self.missed = 0
        self._rung = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="simbridge-dds-trace", daemon=True)

    @contextlib.contextmanager
    def domain_log(self) -> Iterator[None]:
        """Make a domain in this block: its log goes to the pipe, not to stderr."""
        with _swap:
            # ddsrt's log takes the C library's stderr for its global sinks the first time it
            # is used (log.c ``init_lock``): make that happen before stderr is swapped
            self._ddsc.dds_set_log_mask(self._ddsc.dds_get_log_mask())
            saved = _stderr.value
            _stderr.value = self._file
            try:
                yield
            except BaseException:
                # a domain that fails past its configuration (``dds_domain_init``) ends with
                # ``ddsi_config_fini``, which makes stderr as it is now (this file) Cyclone's
                # global log: the file stays open for good, on stderr itself (which closes the
                # pipe: this thread reads what the domain said, then stops)
                self._closable = False
                os.dup2(2, self._write_fd)
                raise
            finally:
                _stderr.value = saved

    def opened(self) -> None:
        """The domain is made (or failed to be): start reading."""
        self._thread.start()

    def close(self, domain: int | None = None) -> None:
        """Stop reading; close the pipe once ``domain`` (its entity) is deleted.

        Until then (a domain that is not deleted) the write end stays open and Cyclone's
        writes fail (EPIPE): they never block it.
        """
        done = self._file is not None and self._closable and self._unused(domain)
        self._stop.set()
        if done:
            _libc.fclose(self._file)
            self._file = None
        if self._thread.is_alive():
            self._thread.join(1.0)
        os.close(self._read_fd)

    def _unused(self, domain: int | None) -> bool:
        """Whether Cyclone is done with the file: the domain is gone, and did not close it.

        A user's ``Tracing/OutputFile`` of ``stderr`` makes the file the domain's trace too,
        which Cyclone closes with the domain (``ddsi_config_fini``): then the write end is no
        longer this pipe's (whose read end is still open here, so no other pipe has its inode).
        """
        if domain is not None:
            domain_id = ctypes.c_uint32()
            if self._ddsc.dds_get_domainid(domain, ctypes.byref(domain_id)) >= 0:
                return False  # still there
        try:
            return os.fstat(self._write_fd).st_ino == os.fstat(self._read_fd).st_ino
        except OSError:
            return False

    def _run(self) -> None:
        rest = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._read_fd], [], [], 0.5)
            if not ready:
                continue
            data = os.read(self._read_fd, _READ)
            if not data:
                return  # the pipe is closed
            *lines, rest = (rest + data).split(b"\n")
            self._hand_over(list(map(_text, lines)))

    def _hand_over(self, lines: list[str]) -> None:
        found: list[RefusedSample] = []
        said: Counter[str] = Counter()
        last: dict[str, str] = {}
        for text in lines:
            refused = refused_sample(text)
            if refused is not None:
                found.append(refused)
            elif (line := cyclone_line(text)) is not None:
                said[line.kind] += 1
                last[line.kind] = line.text
        if not found and not said:
            return
        with self._lock:
            room = _PENDING - len(self._pending)
            self._pending.extend(found[:room])
            self.missed += max(0, len(found) - room)
            for kind, count in said.items():
                key = kind if kind in self._lines or len(self._lines) < KINDS else "other"
                before = self._lines.get(key, (0, ""))[0]
                self._lines[key] = (before + count, last[kind])
            ring = not self._rung
            self._rung = True
        if ring:
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        with self._lock:
            found, self._pending = self._pending, []
            lines, self._lines = self._lines, {}
            missed, self.missed = self.missed, 0
            self._rung = False
        if not self._stop.is_set():
            self._take(found, lines, missed)


def _text(line: bytes) -> str:
    return line.decode(errors="replace")
