"""rosbridge ``fragment`` messages: reassembly of incoming pieces, splitting of outgoing ones.

Shape (protocol reference section 2.16): ``{"op": "fragment", "id", "data", "num", "total"}``;
concatenating every ``data`` in ``num`` order gives the JSON text of the original message.
simbridge sends ``total`` as an integer (rosbridge sends a float; roslibjs 2.1 floors it) and
each fragmented message gets its own id.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simbridge.errors import ProtocolError
from simbridge.protocol.encoding import Frame, encode_json
from simbridge.protocol.ops import Fragment, OpId


__all__ = ["Defragmenter", "split_frame"]


@dataclass(slots=True)
class _Partial:
    total: int
    started: float
    pieces: dict[int, str] = field(default_factory=dict)
    size: int = 0


class Defragmenter:
    """Collects incoming fragments per id until a message is complete."""

    def __init__(self, *, max_bytes: int = 10_000_000, timeout: float = 60.0) -> None:
        #: Largest reassembled message, in characters.
        self.max_bytes = max_bytes
        #: Seconds an incomplete message may wait for its missing pieces.
        self.timeout = timeout
        self._partials: dict[OpId, _Partial] = {}

    def add(self, frag: Fragment, now: float) -> str | None:
        """Store one piece; return the whole JSON text once every piece has arrived.

        Raises:
            ProtocolError: pieces of one id disagree on ``total``, or the message is too big.
        """
        self.expire(now)
        partial = self._partials.get(frag.id)
        if partial is None:
            partial = self._partials[frag.id] = _Partial(frag.total, now)
        elif partial.total != frag.total:
            del self._partials[frag.id]
            msg = f"fragment {frag.id!r}: total changed from {partial.total} to {frag.total}"
            raise ProtocolError(msg)
        if frag.num not in partial.pieces:
            partial.pieces[frag.num] = frag.data
            partial.size += len(frag.data)
        if partial.size > self.max_bytes or self._buffered() > 4 * self.max_bytes:
            del self._partials[frag.id]
            msg = f"fragment {frag.id!r}: message larger than {self.max_bytes} bytes"
            raise ProtocolError(msg)
        if len(partial.pieces) < partial.total:
            return None
        del self._partials[frag.id]
        return "".join(partial.pieces[k] for k in range(partial.total))

    def expire(self, now: float) -> list[OpId]:
        """Forget incomplete messages older than the timeout; return their ids."""
        old = [k for k, p in self._partials.items() if now - p.started > self.timeout]
        for k in old:
            del self._partials[k]
        return old

    def _buffered(self) -> int:
        return sum(p.size for p in self._partials.values())


def split_frame(frame: Frame, size: int, frag_id: OpId) -> list[Frame]:
    """Split a JSON text frame into ``fragment`` frames of at most ``size`` characters of data.

    Binary frames and frames that fit are returned unchanged (as a one-element list).
    """
    if not frame.text or len(frame.data) <= size:
        return [frame]
    text = frame.data.decode("utf-8")
    pieces = [text[i : i + size] for i in range(0, len(text), size)]
    total = len(pieces)
    return [
        Frame(
            encode_json({"op": "fragment", "id": frag_id, "data": p, "num": n, "total": total}),
            True,
        )
        for n, p in enumerate(pieces)
    ]
