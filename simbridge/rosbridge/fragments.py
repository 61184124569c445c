"""rosbridge ``fragment`` messages: reassembly of incoming pieces, splitting of outgoing ones.

Shape (protocol reference section 2.16): ``{"op": "fragment", "id", "data", "num", "total"}``;
concatenating every ``data`` in ``num`` order gives the JSON text of the original message.
simbridge sends ``total`` as an integer (rosbridge sends a float; roslibjs 2.1 floors it) and
each fragmented message gets its own id.

Incoming pieces are held within budgets counted in what they cost in memory: each piece is
kept as its UTF-8 bytes (a ``str`` holding one 4-byte character stores every character in 4
bytes) and costs its length plus :data:`PIECE_COST`, each open message :data:`MESSAGE_COST`
plus its id; at most ``max_sets`` messages open at once and ``max_bytes`` buffered per client,
and whatever the shared :class:`~simbridge.rosbridge.budget.Pool` allows for every client
together. Each piece costs O(1) work plus its own length: the open messages are kept in
arrival order, so expiry looks only at the oldest.
"""

from __future__ import annotations

import sys
from collections import OrderedDict
from dataclasses import dataclass, field

from simbridge.errors import ProtocolError
from simbridge.rosbridge.budget import Pool
from simbridge.rosbridge.encoding import Frame, encode_json
from simbridge.rosbridge.ops import Fragment, OpId, Refusal


__all__ = ["MESSAGE_COST", "PIECE_COST", "Defragmenter", "split_frame", "utf8_size"]

#: Bytes a stored piece costs beyond its data: its ``bytes`` object's header, its slot in the
#: message's dict and its ``num`` key (119 bytes measured with tracemalloc, CPython 3.11).
PIECE_COST = 128
#: Bytes an open message costs beyond its id and pieces: its record, dict and queue entry.
MESSAGE_COST = 1024


def utf8_size(text: str) -> int:
    """Return the UTF-8 size of ``text`` in bytes (O(1) for ASCII text)."""
    return len(text) if text.isascii() else len(text.encode("utf-8", "surrogatepass"))


@dataclass(slots=True)
class _Partial:
    total: int
    started: float
    #: What the message's id costs (part of ``cost``).
    id_cost: int
    pieces: dict[int, bytes] = field(default_factory=dict)
    #: Bytes of UTF-8 data received.
    size: int = 0
    #: Bytes charged for it: data, per-piece and per-message costs.
    cost: int = 0


class Defragmenter:
    """Collects incoming fragments per id until a message is complete."""

    def __init__(
        self,
        *,
        max_bytes: int = 10_000_000,
        timeout: float = 60.0,
        max_sets: int = 16,
        pool: Pool | None = None,
    ) -> None:
        #: Largest reassembled message (UTF-8 bytes), and most bytes held at once (its pieces
        #: with their costs).
        self.max_bytes = max_bytes
        #: Seconds an incomplete message may wait for its missing pieces.
        self.timeout = timeout
        #: Incomplete messages open at once.
        self.max_sets = max_sets
        #: The budget shared with every other client (``fragment_bytes``).
        self.pool = pool or Pool()
        #: Bytes held now (data, per-piece and per-message costs).
        self.buffered = 0
        self._partials: OrderedDict[OpId, _Partial] = OrderedDict()

    def __len__(self) -> int:
        return len(self._partials)

    def add(self, frag: Fragment, now: float) -> bytes | None:
        """Store one piece; return the whole JSON text (UTF-8) once every piece has arrived.

        Raises:
            Refusal: pieces of one id disagree on ``total``, the message is too big, or a
                budget (open messages, bytes of this client, bytes of every client) is spent.
        """
        self.expire(now)
        partial = self._partials.get(frag.id)
        if partial is None:
            if len(self._partials) >= self.max_sets:
                msg = (
                    f"fragment {frag.id!r}: refused, {self.max_sets} fragmented messages are "
                    "already incomplete (the server's max_fragment_sets); finish them first"
                )
                raise Refusal(msg, op="fragment", cause="max_fragment_sets")
            id_cost = MESSAGE_COST + sys.getsizeof(frag.id)
            partial = self._partials[frag.id] = _Partial(frag.total, now, id_cost)
        elif partial.total != frag.total:
            self._drop(frag.id)
            msg = f"fragment {frag.id!r}: total changed from {partial.total} to {frag.total}"
            raise ProtocolError(msg)
        if frag.num in partial.pieces:
            return None
        data = frag.data.encode("utf-8", "surrogatepass")
        size = len(data)
        cost = size + PIECE_COST + (0 if partial.pieces else partial.id_cost)
        if partial.size + size > self.max_bytes or self.buffered + cost > self.max_bytes:
            self._drop(frag.id)
            msg = (
                f"fragment {frag.id!r}: refused, more than {self.max_bytes} bytes of "
                "fragments (the server's max_fragment_bytes, the same as max_message_size)"
            )
            raise Refusal(msg, op="fragment", cause="max_fragment_bytes")
        if not self.pool.take("fragment_bytes", cost):
            self._drop(frag.id)
            msg = (
                f"fragment {frag.id!r}: refused, the server holds its limit of "
                f"{self.pool.limit('fragment_bytes')} bytes of incomplete fragments for all "
                "clients (global_fragment_bytes); try again later"
            )
            raise Refusal(msg, op="fragment", cause="global_fragment_bytes")
        partial.pieces[frag.num] = data
        partial.size += size
        partial.cost += cost
        self.buffered += cost
        if len(partial.pieces) < partial.total:
            return None
        self._drop(frag.id)
        return b"".join(partial.pieces[k] for k in range(partial.total))

    def expire(self, now: float) -> list[OpId]:
        """Forget incomplete messages older than the timeout; return their ids."""
        old: list[OpId] = []
        partials = self._partials
        while partials:
            key, partial = next(iter(partials.items()))
            if now - partial.started <= self.timeout:
                break
            self._drop(key)
            old.append(key)
        return old

    def clear(self) -> None:
        """Forget every incomplete message (the client left) and give back its bytes."""
        for key in list(self._partials):
            self._drop(key)

    def _drop(self, key: OpId) -> None:
        partial = self._partials.pop(key, None)
        if partial is not None and partial.cost:
            self.buffered -= partial.cost
            self.pool.give("fragment_bytes", partial.cost)


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
