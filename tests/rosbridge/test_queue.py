from __future__ import annotations

from simbridge.rosbridge import Frame, SendQueue


def f(text: str) -> Frame:
    return Frame(text.encode(), True)


def drain(q: SendQueue) -> list[str]:
    out = []
    while (frame := q.pop()) is not None:
        out.append(frame.data.decode())
    return out


def test_frames_come_out_in_arrival_order() -> None:
    """The queue is FIFO across keys."""
    q = SendQueue(1000)
    for text, key in (("a1", "a"), ("b1", "b"), ("x", None), ("a2", "a")):
        q.push(f(text), key, 0)
    assert drain(q) == ["a1", "b1", "x", "a2"]
    assert len(q) == 0 and q.bytes == 0


def test_per_key_limit_drops_the_oldest_of_that_key_only() -> None:
    """queue_length 2 keeps the two newest of its subscription; others are untouched."""
    q = SendQueue(1000)
    q.push(f("a1"), "a", 2)
    q.push(f("b1"), "b", 2)
    q.push(f("a2"), "a", 2)
    assert q.push(f("a3"), "a", 2) == 1
    assert drain(q) == ["b1", "a2", "a3"]
    assert q.dropped == 1


def test_byte_budget_drops_oldest_keyed_frames_but_never_replies() -> None:
    """Over budget, the oldest subscription frames go; un-keyed replies stay."""
    q = SendQueue(10)
    q.push(f("reply"), None, 0)
    q.push(f("aaaa"), "a", 0)
    assert q.bytes == 9
    assert q.push(f("bbbb"), "b", 0) == 1
    assert q.bytes == 9
    assert drain(q) == ["reply", "bbbb"]


def test_stalled_queue_with_steady_input_stays_bounded() -> None:
    """A client that never reads: the queue holds at most its per-key limit, forever."""
    q = SendQueue(10_000_000)
    for i in range(10_000):
        q.push(f(f"m{i}"), "odom", 5)
    assert len(q) == 5
    assert len(q._fifo) <= 2 * 5 + 64  # tombstones are compacted
    assert drain(q) == [f"m{i}" for i in range(9995, 10_000)]


def test_clear_empties_everything() -> None:
    """clear() forgets pending frames and bytes."""
    q = SendQueue(100)
    q.push(f("x"), "k", 0)
    q.clear()
    assert (len(q), q.bytes, q.pop()) == (0, 0, None)


def test_byte_budget_covers_replies_too_the_newest_past_it_is_dropped() -> None:
    """Replies alone past the budget (a caller that never reads): new ones are dropped."""
    q = SendQueue(12)
    assert q.push(f("reply1"), None, 0) == 0
    assert q.push(f("reply2"), None, 0) == 0
    assert q.push(f("reply3"), None, 0) == 1
    assert q.bytes == 12 and q.dropped == 1
    assert drain(q) == ["reply1", "reply2"]
    assert q.push(f("a reply bigger than the budget"), None, 0) == 0  # alone: it goes out
