from __future__ import annotations

import json
import sys
import tracemalloc

import pytest

from simbridge.errors import ProtocolError
from simbridge.rosbridge import Defragmenter, Frame, Pool, Refusal, split_frame
from simbridge.rosbridge.fragments import MESSAGE_COST, PIECE_COST
from simbridge.rosbridge.ops import Fragment


def test_split_frame_pieces_concatenate_to_the_original() -> None:
    """Pieces of at most `size` characters, integer total, num from 0, one id."""
    frame = Frame(
        json.dumps({"op": "publish", "topic": "/t", "msg": {"data": "x" * 50}}).encode(), True
    )
    pieces = [json.loads(p.data) for p in split_frame(frame, 20, "id1")]
    assert all(p["op"] == "fragment" and p["id"] == "id1" for p in pieces)
    assert [p["num"] for p in pieces] == list(range(len(pieces)))
    assert all(p["total"] == len(pieces) and isinstance(p["total"], int) for p in pieces)
    assert "".join(p["data"] for p in pieces).encode() == frame.data


def test_small_and_binary_frames_are_not_split() -> None:
    """Only text frames larger than the size are fragmented."""
    assert split_frame(Frame(b"{}", True), 10, 1) == [Frame(b"{}", True)]
    assert split_frame(Frame(b"x" * 50, False), 10, 1) == [Frame(b"x" * 50, False)]


def test_defragmenter_rejects_changing_totals_and_oversized_messages() -> None:
    """A total that changes mid-message, or more data than allowed, is an error."""
    d = Defragmenter(max_bytes=10_000)
    d.add(Fragment("a", "12", 0, 3), 0.0)
    with pytest.raises(ProtocolError, match="total changed"):
        d.add(Fragment("a", "34", 1, 4), 0.0)
    with pytest.raises(ProtocolError, match="more than 10000 bytes"):
        d.add(Fragment("b", "x" * 10_001, 0, 2), 0.0)


def test_incomplete_messages_expire() -> None:
    """Pieces older than the timeout are forgotten."""
    d = Defragmenter(timeout=5.0)
    d.add(Fragment("a", "1", 0, 2), 0.0)
    assert d.expire(10.0) == ["a"]
    assert d.add(Fragment("a", "2", 1, 2), 10.0) is None


def _message_cost(frag_id: str) -> int:
    return MESSAGE_COST + sys.getsizeof(frag_id)


def test_defragmenter_counts_utf8_bytes_and_the_shared_pool() -> None:
    """Four-byte characters cost four bytes each, against the client and the pool."""
    first = _message_cost("x") + 16 + PIECE_COST  # 4 characters, 16 bytes
    pool = Pool({"fragment_bytes": 2 * first})
    a = Defragmenter(max_bytes=first + 100, pool=pool)
    b = Defragmenter(max_bytes=10_000, pool=pool)
    a.add(Fragment("x", "\U0001f600" * 4, 0, 2), 0.0)
    assert a.buffered == first == pool.used["fragment_bytes"]
    with pytest.raises(Refusal, match="max_fragment_bytes"):
        a.add(Fragment("y", "\U0001f600" * 2, 0, 2), 0.0)
    b.add(Fragment("z", "abcdefghijkl", 0, 2), 0.0)
    with pytest.raises(Refusal, match="global_fragment_bytes"):
        b.add(Fragment("w", "abc", 0, 2), 0.0)
    a.clear()
    assert pool.used["fragment_bytes"] == _message_cost("z") + 12 + PIECE_COST


def test_many_tiny_pieces_cost_what_python_holds_for_them() -> None:
    """A piece of one byte costs its bytes object and dict slot too (PIECE_COST), not 1.

    A client that sent 1-byte pieces used to hold a hundred times its counted budget: the
    charged cost is at least the memory tracemalloc measures for the pieces.
    """
    d = Defragmenter(max_bytes=10_000_000)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for n in range(20_000):
            d.add(Fragment("m", "x", n, 100_000), 0.0)
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert d.buffered == _message_cost("m") + 20_000 * (1 + PIECE_COST)
    assert d.buffered >= held, (d.buffered, held)


def test_pieces_are_kept_as_utf8_not_as_wide_strings() -> None:
    """A mostly-ASCII piece holding one 4-byte character is kept in UTF-8, not as a str.

    Such a str stores every character in 4 bytes; the piece comes back as the same text.
    """
    d = Defragmenter(max_bytes=10_000_000)
    piece = "a" * 100_000 + "\U0001f600"
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        d.add(Fragment("m", piece, 0, 2), 0.0)
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert held < 110_000 < sys.getsizeof(piece)
    assert d.buffered == _message_cost("m") + 100_004 + PIECE_COST
    whole = d.add(Fragment("m", "b", 1, 2), 0.0)
    assert whole is not None and whole.decode() == piece + "b"


def test_defragmenter_bounds_open_sets_and_expires_the_oldest_first() -> None:
    """At most max_sets incomplete messages; expiry frees them in arrival order."""
    d = Defragmenter(max_sets=2, timeout=10.0)
    d.add(Fragment("a", "1", 0, 2), 0.0)
    d.add(Fragment("b", "1", 0, 2), 5.0)
    with pytest.raises(Refusal, match="max_fragment_sets"):
        d.add(Fragment("c", "1", 0, 2), 6.0)
    assert d.expire(10.5) == ["a"] and len(d) == 1
    assert d.add(Fragment("c", "1", 0, 2), 11.0) is None and len(d) == 2
