"""A client's bounded outgoing queue: drop-oldest per subscription, and a byte budget.

rosbridge semantics (protocol reference section 2.4): with ``queue_length`` N > 0 a
subscription keeps at most N pending messages and drops the oldest. simbridge applies that
bound to what is waiting for a slow client's socket, and adds a byte budget per client so that a
client that stops reading can never grow the server's memory without bound (rosbridge #212).

Messages without a key (service responses, status) are never dropped by the per-key bound; the
byte budget drops the oldest *keyed* messages first, and covers every frame: when unkeyed frames
alone fill it (a client that calls services without reading the answers), a new unkeyed frame is
dropped instead of queued.

Dropping from the middle of a FIFO is done with tombstones: each entry also sits in the deque of
its key, and a dropped entry is marked dead and skipped when popped.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable

from simbridge.rosbridge.encoding import Frame


__all__ = ["SendQueue"]


class _Entry:
    __slots__ = ("frame", "key", "size")

    def __init__(self, frame: Frame, key: Hashable | None) -> None:
        self.frame: Frame | None = frame
        self.key = key
        self.size = len(frame.data)


class SendQueue:
    """FIFO of frames waiting for one client's socket."""

    def __init__(self, max_bytes: int) -> None:
        #: Byte budget of pending frames; above it the oldest keyed frames are dropped.
        self.max_bytes = max_bytes
        #: Pending bytes.
        self.bytes = 0
        #: Frames dropped so far (per-key bound and byte budget together).
        self.dropped = 0
        self._fifo: deque[_Entry] = deque()
        self._by_key: dict[Hashable, deque[_Entry]] = {}
        #: Frames waiting (``len(queue)``; a plain attribute for the send path's checks).
        self.pending = 0

    def __len__(self) -> int:
        return self.pending

    def push(self, frame: Frame, key: Hashable | None = None, limit: int = 0) -> int:
        """Append a frame; return how many older frames were dropped to make room.

        Args:
            frame: what to send.
            key: the subscription it belongs to, or ``None`` for replies that must not be
                dropped by the per-key bound.
            limit: at most this many pending frames of ``key`` (0 = no per-key bound).
        """
        entry = _Entry(frame, key)
        self._fifo.append(entry)
        self.pending += 1
        self.bytes += entry.size
        dropped = 0
        if key is not None:
            same = self._by_key.get(key)
            if same is None:
                same = self._by_key[key] = deque()
            same.append(entry)
            while limit and len(same) > limit:
                self._kill(same.popleft())
                dropped += 1
        if self.bytes > self.max_bytes:
            dropped += self._shed()
            if self.bytes > self.max_bytes and key is None and self.pending > 1:
                self._fifo.pop()  # the entry just appended: nothing older may be dropped
                self._kill(entry)
                dropped += 1
        if len(self._fifo) > 2 * self.pending + 64:
            self._fifo = deque(e for e in self._fifo if e.frame is not None)
        self.dropped += dropped
        return dropped

    def pop(self) -> Frame | None:
        """Remove and return the oldest pending frame, or ``None`` when empty."""
        fifo = self._fifo
        while fifo:
            entry = fifo.popleft()
            frame = entry.frame
            if frame is None:
                continue
            entry.frame = None
            self.pending -= 1
            self.bytes -= entry.size
            if entry.key is not None:
                same = self._by_key[entry.key]
                same.popleft()  # FIFO order: this entry is the oldest of its key
                if not same:
                    del self._by_key[entry.key]
            return frame
        return None

    def clear(self) -> None:
        """Drop everything pending (the client is gone)."""
        self._fifo.clear()
        self._by_key.clear()
        self.pending = 0
        self.bytes = 0

    def _kill(self, entry: _Entry) -> None:
        entry.frame = None
        self.pending -= 1
        self.bytes -= entry.size

    def _shed(self) -> int:
        """Drop the oldest keyed frames until within the byte budget (keep the newest one)."""
        dropped = 0
        for entry in self._fifo:
            if self.bytes <= self.max_bytes or self.pending <= 1:
                break
            if entry.frame is None or entry.key is None:
                continue
            same = self._by_key[entry.key]
            same.remove(entry)
            if not same:
                del self._by_key[entry.key]
            self._kill(entry)
            dropped += 1
        return dropped
