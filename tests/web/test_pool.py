"""The HTTP connection pool's decisions, without sockets (simbridge/web/pool.py)."""

from __future__ import annotations

import pytest

from simbridge.web.pool import Pool, Slot, client_address


class Closed:
    """What the pool closed, with the answer each got."""

    def __init__(self) -> None:
        self.log: list[tuple[str, int, str]] = []

    def slot(self, address: str, name: str = "") -> Slot:
        return Slot(address, lambda status, text: self.log.append((name, status, text)))


def test_a_newcomer_over_its_address_budget_queues_then_gets_the_503_by_name() -> None:
    pool, closed = Pool(limit=10, per_address=2), Closed()
    for _ in range(2):
        slot = closed.slot("10.0.0.1")
        pool.admit(slot, 0.0)
        pool.mark(slot, "request", 0.0)
    newcomer = closed.slot("10.0.0.1")
    pool.admit(newcomer, 0.5)
    assert newcomer.reserved and newcomer not in pool.members
    refusal = pool.claim(newcomer, admin=False, now=0.5)
    assert refusal is not None and "max_http_connections_per_address" in refusal
    assert newcomer.queued and newcomer in pool.waiting and pool.refused == 0
    other = closed.slot("10.0.0.2")
    pool.admit(other, 0.5)
    assert other in pool.members and not other.reserved  # another address still gets in
    assert pool.give_up(newcomer) == refusal  # no place freed in time: its 503
    assert not closed.log and pool.refused == 1 and not pool.waiting


def test_at_its_address_budget_a_newcomer_takes_the_place_of_its_own_idle_connection() -> None:
    pool, closed = Pool(limit=3, per_address=2), Closed()
    other = closed.slot("10.0.0.9", "other")
    pool.admit(other, 0.0)  # idle, and older than the address's own
    pool.mark(other, "idle", 0.0)
    mine = [closed.slot("10.0.0.1", f"mine{n}") for n in range(2)]
    for n, slot in enumerate(mine):
        pool.admit(slot, 1.0 + n)
        pool.mark(slot, "idle", 1.0 + n)  # served, waiting for its next request
    pool.admit(closed.slot("10.0.0.1", "new"), 3.0)
    assert closed.log == [("mine0", 0, "")]  # its own longest idle, not the other address's
    assert other in pool.members and mine[0].evicted


def test_when_full_a_slow_request_gives_way_with_408_and_a_young_one_does_not() -> None:
    pool, closed = Pool(limit=2, per_address=10, slow=1.0), Closed()
    old, young = closed.slot("10.0.0.1", "old"), closed.slot("10.0.0.2", "young")
    pool.admit(old, 0.0)
    pool.mark(old, "request", 0.0)
    pool.admit(young, 0.9)
    pool.mark(young, "request", 0.9)
    newcomer = closed.slot("10.0.0.3")
    pool.admit(newcomer, 1.5)
    assert newcomer in pool.members
    pool.mark(newcomer, "busy", 1.5)
    assert [(name, status) for name, status, _ in closed.log] == [("old", 408)]
    last = closed.slot("10.0.0.4")
    pool.admit(last, 1.6)  # young's request is 0.7 s old: nothing gives way
    assert last.reserved and len(closed.log) == 1
    refusal = pool.claim(last, admin=False, now=1.6)
    assert refusal is not None and "(max_http_connections)" in refusal


def test_a_new_connection_has_a_second_to_begin_its_request_before_it_gives_way() -> None:
    pool, closed = Pool(limit=1, per_address=10, slow=1.0), Closed()
    first = closed.slot("10.0.0.1", "first")
    pool.admit(first, 0.0)  # connected, nothing sent yet
    early = closed.slot("10.0.0.2")
    pool.admit(early, 0.5)
    assert early.reserved and not closed.log  # the first has not had its second yet
    late = closed.slot("10.0.0.3")
    pool.admit(late, 1.5)
    assert late in pool.members and closed.log == [("first", 0, "")]  # closed quietly


def test_busy_connections_never_give_way() -> None:
    pool, closed = Pool(limit=1, per_address=10), Closed()
    busy = closed.slot("10.0.0.1")
    pool.admit(busy, 0.0)
    pool.mark(busy, "busy", 0.0)
    newcomer = closed.slot("10.0.0.2")
    pool.admit(newcomer, 60.0)
    assert pool.claim(newcomer, admin=False, now=60.0) is not None
    assert not closed.log and busy in pool.members


def test_the_instructor_gets_in_from_the_reserve_and_anyone_else_gets_the_503() -> None:
    pool, closed = Pool(limit=2, per_address=2, slow=1.0), Closed()
    for n in range(2):
        slot = closed.slot("10.0.0.1", f"student{n}")
        pool.admit(slot, 0.0)
        pool.mark(slot, "request", 0.0)
    student, instructor = closed.slot("10.0.0.2", "s"), closed.slot("10.0.0.3", "i")
    pool.admit(student, 0.5)
    pool.admit(instructor, 0.5)
    assert student.reserved and instructor.reserved
    refusal = pool.claim(student, admin=False, now=0.6)
    assert refusal is not None and "(max_http_connections)" in refusal
    assert pool.claim(instructor, admin=True, now=0.6) is None  # young requests give way to it
    assert instructor in pool.members and instructor.admin and not instructor.reserved
    assert [(name, status) for name, status, _ in closed.log] == [("student0", 408)]
    assert len(pool.members) == 2 and list(pool.waiting) == [student]  # it queues on


def test_the_instructor_gets_in_even_over_the_budget_when_everyone_is_busy() -> None:
    pool, closed = Pool(limit=1, per_address=1), Closed()
    busy = closed.slot("10.0.0.1")
    pool.admit(busy, 0.0)
    pool.mark(busy, "busy", 0.0)
    instructor = closed.slot("10.0.0.1")  # the same address: over both budgets
    pool.admit(instructor, 0.1)
    assert instructor.reserved
    assert pool.claim(instructor, admin=True, now=0.1) is None
    assert len(pool.members) == 2 and not closed.log


def test_one_address_flooding_the_reserve_pushes_out_only_its_own_waiters() -> None:
    pool, closed = Pool(limit=1, per_address=1, reserve=6, reserve_per_address=2), Closed()
    member = closed.slot("10.0.0.1")
    pool.admit(member, 0.0)
    pool.mark(member, "busy", 0.0)
    instructor = closed.slot("10.0.0.5", "instructor")
    pool.admit(instructor, 0.1)
    flood = [closed.slot("10.0.0.6", f"flood{n}") for n in range(10)]
    for slot in flood:
        pool.admit(slot, 0.2)
    assert instructor in pool.waiting and len(pool.waiting) == 3
    assert {name for name, status, _ in closed.log} == {f"flood{n}" for n in range(8)}
    assert all(status == 503 for _, status, _ in closed.log)
    others = [closed.slot(f"10.1.0.{n}", f"other{n}") for n in range(4)]
    for slot in others:
        pool.admit(slot, 0.3)
    # the reserve's 6 places; then the oldest waiter of the address with the most gives way
    assert closed.log[-1][0] == "flood8" and len(pool.waiting) == 6
    assert instructor in pool.waiting and all(slot in pool.waiting for slot in others)


class Woken:
    """Counts a queued slot's wake-ups."""

    def __init__(self, slot: Slot) -> None:
        self.count = 0
        slot.wake = self

    def __call__(self) -> None:
        self.count += 1


def test_a_queued_request_gets_the_place_a_member_of_its_address_frees() -> None:
    pool, closed = Pool(limit=10, per_address=2), Closed()
    members = [closed.slot("10.0.0.1", f"m{n}") for n in range(2)]
    for slot in members:
        pool.admit(slot, 0.0)
        pool.mark(slot, "busy", 0.0)
    first, second = closed.slot("10.0.0.1", "q1"), closed.slot("10.0.0.1", "q2")
    for slot in (first, second):
        pool.admit(slot, 0.1)
        assert pool.claim(slot, admin=False, now=0.1) is not None and slot.queued
    woken = [Woken(first), Woken(second)]
    pool.leave(members[0], 0.2)  # answered and closed: its place goes to the oldest waiter
    assert first in pool.members and not first.queued and [w.count for w in woken] == [1, 0]
    pool.mark(members[1], "idle", 0.3)  # answered, kept alive: the page may still use it
    assert not pool.retry(second, 1.0) and second.queued
    assert pool.retry(second, 1.3)  # idle for its grace second: it gives way to the waiter
    assert second in pool.members and [w.count for w in woken] == [1, 0]
    assert closed.log == [("m1", 0, "")] and not pool.waiting and pool.refused == 0
    assert dict(pool.per) == {"10.0.0.1": 2}


def test_a_place_in_the_full_pool_goes_to_the_oldest_waiter_of_any_address() -> None:
    pool, closed = Pool(limit=2, per_address=2), Closed()
    members = [closed.slot(f"10.0.0.{n}", f"m{n}") for n in (1, 2)]
    for slot in members:
        pool.admit(slot, 0.0)
        pool.mark(slot, "busy", 0.0)
    waiter = closed.slot("10.0.0.3", "w")
    pool.admit(waiter, 0.1)
    pool.claim(waiter, admin=False, now=0.1)
    woken = Woken(waiter)
    pool.leave(members[0], 0.2)  # another address's place: the pool's budget freed one
    assert waiter in pool.members and woken.count == 1 and not closed.log


def test_a_queued_request_pushed_out_of_the_reserve_is_told_and_woken() -> None:
    pool, closed = Pool(limit=1, per_address=1, reserve=4, reserve_per_address=1), Closed()
    member = closed.slot("10.0.0.1")
    pool.admit(member, 0.0)
    pool.mark(member, "busy", 0.0)
    waiter = closed.slot("10.0.0.2", "w")
    pool.admit(waiter, 0.1)
    pool.claim(waiter, admin=False, now=0.1)
    woken = Woken(waiter)
    pool.admit(closed.slot("10.0.0.2", "newer"), 0.2)  # its address's reserve holds one
    assert waiter.evicted and woken.count == 1 and closed.log[0][:2] == ("w", 503)


def test_leaving_frees_the_place() -> None:
    pool, closed = Pool(limit=1, per_address=1), Closed()
    slot = closed.slot("10.0.0.1")
    pool.admit(slot, 0.0)
    pool.mark(slot, "busy", 0.0)
    waiter = closed.slot("10.0.0.1")
    pool.admit(waiter, 0.1)
    assert waiter.reserved
    pool.leave(waiter)
    pool.leave(slot)
    again = closed.slot("10.0.0.1")
    pool.admit(again, 0.2)
    assert not again.reserved and not pool.waiting
    assert dict(pool.per) == {"10.0.0.1": 1}


@pytest.mark.parametrize(
    ("peer", "address"),
    [
        (("192.168.1.20", 50000), "192.168.1.20"),
        (("2001:db8:1:2:aaaa:bbbb:cccc:dddd", 50000, 0, 0), "2001:db8:1:2::/64"),
        (("2001:db8:1:2::1", 50000, 0, 0), "2001:db8:1:2::/64"),
        (("::ffff:10.0.0.7", 50000, 0, 0), "10.0.0.7"),
        (("fe80::1%eth0", 50000, 0, 2), "fe80::/64"),
        ("", "local"),
        (None, "local"),
    ],
)
def test_client_address_counts_ipv6_by_its_64(peer: object, address: str) -> None:
    assert client_address(peer) == address


def test_an_address_shares_one_budget_of_loop_time_kept_while_it_is_in_debt() -> None:
    pool, closed = Pool(limit=10, per_address=10, work_share=0.25, work_burst=0.01), Closed()
    a, b = closed.slot("10.0.0.1"), closed.slot("10.0.0.1")
    pool.admit(a, 0.0)
    pool.admit(b, 0.0)
    share = pool.share("10.0.0.1", 0.0)
    assert pool.share("10.0.0.1", 0.0) is share  # both connections spend the same share
    assert share.charge(0.0, 0.005) == 0.0  # within the burst
    assert share.charge(0.0, 0.015) == pytest.approx(0.04)  # 10 ms in debt at a quarter
    pool.leave(a, 0.01)
    pool.leave(b, 0.01)
    assert pool.share("10.0.0.1", 0.01) is share  # reconnecting does not clear a debt
    assert share.owed(0.05) == 0.0
    again = closed.slot("10.0.0.1")
    pool.admit(again, 0.05)
    pool.leave(again, 0.05)
    assert "10.0.0.1" not in pool.shares  # paid up and gone: forgotten
