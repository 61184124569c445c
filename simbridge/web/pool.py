"""The HTTP port's connections and their budgets (sans-I/O: no sockets, no event loop).

Two budgets bound how many connections HTTP clients can make the server hold, and one promise
keeps the instructor's console usable whatever they do (``docs/security.md``, "HTTP"):

- ``limit`` connections in all (``max_http_connections``) and ``per_address`` from one client
  address (``max_http_connections_per_address``; an IPv6 address counts by its /64, the block
  one machine gets). A newcomer over a budget takes the place of a connection that holds a slot
  for nothing: the longest idle keep-alive one (closed; the browser reconnects), else one that
  has been connected for longer than ``slow`` seconds without a request (closed) or whose
  request has been arriving for that long (408): a browser sends a request's head in one go.
  Within the per-address budget only that address's own connections give way.
- When no place can be made, the newcomer is not refused at once: it waits in the **reserve**
  (``reserve`` connections, ``reserve_per_address`` from one address) until its request's head
  shows whether it carries the admin token. The instructor's request is then admitted, making
  room if it must (any client's idle or unfinished request gives way); so an admin request is
  never refused because students or outsiders filled the pool. Anyone else's **queues** for up
  to ``queue_for`` seconds: a place that frees (a connection of its address, or any when the
  pool is full, closes) goes to the oldest waiter it can serve (:attr:`Slot.wake`), and the
  server looks again every quarter second (:meth:`Pool.retry`: a connection may have been idle
  or slow long enough to give way by then); only a request still without a place then gets the
  503 naming the budget. A page is a burst of requests on up to six connections a browser, and
  a class behind one address (a school's NAT) is thirty browsers: they wait their turn instead
  of losing the page's scripts to 503s. An idle keep-alive connection gives way only after
  ``idle_grace`` seconds idle: a page's requests follow each other on the same connections, and
  one closed between two of them (the browser's next request already on its way) fails that
  request. Measured with 30 Chromium pages from one address (docs/security.md, "A class behind
  one address"): the default budget loads only some of them; 6 per browser loads them all. The
  reserve is bounded per address (one machine flooding it pushes out only its own waiters) and
  in all: when it is full, the oldest waiter of the address with the most gives way, and a
  newcomer always gets to show its head.

:class:`Pool` only keeps the books and decides; the server (:mod:`simbridge.web.http`) reads,
answers and closes. Each decision costs at most one pass over the open connections.
"""

from __future__ import annotations

import ipaddress
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Literal


__all__ = ["Phase", "Pool", "Share", "Slot", "client_address"]

#: What a connection is doing: waiting for its first request (``new``), waiting for its next
#: one (``idle``: keep-alive), receiving one (``request``: its head or body is on its way) or
#: being answered (``busy``).
Phase = Literal["new", "idle", "request", "busy"]


def client_address(peername: object) -> str:
    """Return the address a connection's budget counts by (an IPv6 address: its /64)."""
    host = peername[0] if isinstance(peername, tuple) and peername else peername
    if not isinstance(host, str) or not host:
        return "local"  # a Unix socket: one local client
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return host
    if isinstance(ip, ipaddress.IPv6Address):
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.IPv6Network((ip, 64), strict=False))
    return str(ip)


@dataclass(slots=True)
class Share:
    """One client address's share of the loop's time: ``rate`` seconds a second, ``burst`` ahead.

    Parsing and answering its requests is charged here, by all of that address's connections
    together; in debt, its connections wait (unread: TCP slows the client down) while the loop
    and everyone else run, as a rosbridge client's frames do (``client_work_share``).
    """

    rate: float
    burst: float
    balance: float = 0.0
    last: float = 0.0

    def charge(self, now: float, spent: float) -> float:
        """Spend ``spent`` seconds (into debt if need be); return seconds until out of debt."""
        self.balance = min(self.burst, self.balance + (now - self.last) * self.rate) - spent
        self.last = now
        return 0.0 if self.balance >= 0 else -self.balance / self.rate

    def owed(self, now: float) -> float:
        """Return seconds until out of debt (nothing spent)."""
        return self.charge(now, 0.0)


@dataclass(eq=False, slots=True)
class Slot:
    """One open connection, as the pool sees it."""

    #: The client address it counts against (:func:`client_address`).
    address: str
    #: Closes the connection, answering ``status`` with ``text`` first (``status`` 0: nothing).
    close: Callable[[int, str], None]
    #: What it is doing, and since when (the pool's clock).
    phase: Phase = "new"
    since: float = 0.0
    #: One of its requests carried the admin token: it gives way last.
    admin: bool = False
    #: It waits in the reserve: admitted only if its first request is the instructor's, or
    #: when a place frees while it queues.
    reserved: bool = False
    #: Its head is in and is not the instructor's: it waits for a place (:meth:`Pool.claim`).
    queued: bool = False
    #: Called when it is given a place, or closed, while it queues (the server's wake-up).
    wake: Callable[[], None] | None = None
    #: The refusal a reserved connection gets if no place is found for it.
    refusal: str = ""
    #: It was closed to make room (the server stops serving it).
    evicted: bool = False


@dataclass(slots=True)
class Pool:
    """The open HTTP connections of one server, and its budgets of them."""

    #: Connections at most (``max_http_connections``), and from one address.
    limit: int
    per_address: int
    #: Connections waiting (to show an admin token, then for a place) when there is no room, in
    #: all and per address: a class of 30 browsers behind one address opens up to 180 at once.
    reserve: int = 256
    reserve_per_address: int = 128
    #: Seconds a request without a place queues for one before its 503.
    queue_for: float = 5.0
    #: Seconds a keep-alive connection must have been idle before it gives way to a newcomer.
    idle_grace: float = 1.0
    #: Seconds a request may have been arriving before it gives way to a newcomer when full.
    slow: float = 1.0
    #: Each address's share of the loop's time (:class:`Share`), and its burst (seconds).
    work_share: float = 0.25
    work_burst: float = 0.0125
    #: The shares of the addresses with connections (or still in debt).
    shares: dict[str, Share] = field(default_factory=dict)
    #: Admitted connections, oldest first, and how many per address.
    members: dict[Slot, None] = field(default_factory=dict)
    per: Counter[str] = field(default_factory=Counter)
    #: Connections in the reserve, oldest first.
    waiting: dict[Slot, None] = field(default_factory=dict)
    #: Connections refused (503: :meth:`claim`) and closed to make room, since the start.
    refused: int = 0
    evicted: int = 0

    def admit(self, slot: Slot, now: float) -> None:
        """Give a new connection a place: a member's, or else one in the reserve.

        A reserved slot (``slot.reserved``) waits for its first request's head to say whose it
        is (:meth:`claim`); the reserve always takes a newcomer, pushing out an older waiter.
        """
        slot.phase, slot.since = "new", now
        refusal = self._room(slot.address, now)
        if refusal is None:
            self._join(slot)
            return
        ahead = [s for s in self.waiting if s.address == slot.address]
        if len(ahead) >= self.reserve_per_address:
            self._evict(ahead[0], 503, ahead[0].refusal)  # this address's own oldest waiter
        elif len(self.waiting) >= self.reserve:
            # the oldest waiter of the address with the most: a waiter that has not shown its
            # head for the longest is not the instructor's (a browser sends it at once)
            counts = Counter(s.address for s in self.waiting)
            most = max(counts.values())
            victim = next(s for s in self.waiting if counts[s.address] == most)
            self._evict(victim, 503, victim.refusal)
        slot.reserved, slot.refusal = True, refusal
        self.waiting[slot] = None

    def claim(self, slot: Slot, admin: bool, now: float) -> str | None:
        """A reserved connection's first head is here: admit it if ``admin`` or there is room.

        The instructor's request takes a member's place if it must: the longest idle, else the
        oldest unfinished request of anyone without the admin token (over the budget, within
        the reserve's bound, when every member is busy or the instructor's). Anyone else's
        without room queues (``slot.queued``; the refusal it would get is returned): the server
        waits ``queue_for`` seconds for :attr:`Slot.wake`, then calls :meth:`give_up`.
        """
        if not admin:
            refusal = self._room(slot.address, now)
            if refusal is None:
                self._place(slot)
                return None
            slot.queued, slot.refusal = True, refusal
            return refusal
        self._unwait(slot)
        if self._room(slot.address, now) is not None:
            victim = self._victim(self.members, now, any_request=True)
            if victim is not None:
                self._evict(victim, 408, "closed to make room for the instructor's request\n")
        slot.admin = True
        self._join(slot)
        return None

    def give_up(self, slot: Slot) -> str:
        """A queued connection found no place in time: it leaves the reserve; its 503's text."""
        self._unwait(slot)
        slot.queued = False
        self.refused += 1
        return slot.refusal

    def stats(self) -> dict[str, int]:
        """Return the books in numbers (``/healthz``)."""
        return {
            "open": len(self.members),
            "waiting": len(self.waiting),
            "addresses": len(self.per),
            "refused": self.refused,
            "evicted": self.evicted,
        }

    def share(self, address: str, now: float) -> Share:
        """Return ``address``'s share of the loop's time (a new one starts with its burst)."""
        share = self.shares.get(address)
        if share is None:
            share = self.shares[address] = Share(self.work_share, self.work_burst)
            share.balance, share.last = self.work_burst, now
        return share

    def mark(self, slot: Slot, phase: Phase, now: float) -> None:
        """``slot`` is now doing ``phase`` (its clock restarts only when the phase changes)."""
        if slot.phase != phase:
            slot.phase, slot.since = phase, now

    def retry(self, slot: Slot, now: float) -> bool:
        """Look again for a place for a queued request (a connection may give way by now)."""
        if not slot.queued or self._room(slot.address, now) is not None:
            return False
        self._place(slot)
        return True

    def leave(self, slot: Slot, now: float | None = None) -> None:
        """The connection closed: free its place (and its address's share, if paid up).

        The place goes to a queued request, if one can have it (:meth:`_promote`).
        """
        member = slot in self.members
        self._drop(slot, now)
        if member and self.waiting and now is not None:
            self._promote(slot.address, now)

    def _drop(self, slot: Slot, now: float | None) -> None:
        if slot in self.members:
            del self.members[slot]
            self.per[slot.address] -= 1
            if self.per[slot.address] <= 0:
                del self.per[slot.address]
        self._unwait(slot)
        share = self.shares.get(slot.address)
        # an address in debt keeps it when it reconnects (the debts kept are bounded)
        if (
            share is not None
            and now is not None
            and slot.address not in self.per
            and (share.owed(now) == 0 or len(self.shares) > 4 * (self.limit + self.reserve))
        ):
            del self.shares[slot.address]

    # -- the decisions ------------------------------------------------------------------

    def _promote(self, address: str, now: float) -> None:
        """Give a place to the oldest queued request of ``address``, then the oldest of any.

        Called when a member of ``address`` left: that freed a place of the address's budget,
        or of the pool's. At most two tries, each one pass.
        """
        for mine in (True, False):
            waiter = next(
                (s for s in self.waiting if s.queued and (s.address == address or not mine)),
                None,
            )
            if waiter is not None and self._room(waiter.address, now) is None:
                self._place(waiter)
                if waiter.wake is not None:
                    waiter.wake()

    def _room(self, address: str, now: float) -> str | None:
        """Make room for a newcomer from ``address``; return the refusal if none can be made."""
        if self.per[address] >= self.per_address:
            own = (s for s in self.members if s.address == address)
            victim = self._victim(own, now)
            if victim is None:
                return (
                    f"server busy: {self.per_address} HTTP connections are open from your "
                    "address (max_http_connections_per_address); try again shortly\n"
                )
        elif len(self.members) >= self.limit:
            victim = self._victim(self.members, now)
            if victim is None:
                return (
                    f"server busy: {self.limit} HTTP connections are open "
                    "(max_http_connections); try again shortly\n"
                )
        else:
            return None
        if victim.phase in ("idle", "new"):
            self._evict(victim, 0, "")  # it has nothing on its way: closed quietly
        else:
            self._evict(victim, 408, "request not received in time while the server is full\n")
        return None

    def _victim(self, slots: Iterable[Slot], now: float, any_request: bool = False) -> Slot | None:
        """The connection to close for a newcomer: the longest idle, else the slowest request.

        An idle keep-alive connection (served, waiting for its next request) gives way after
        ``idle_grace`` seconds idle; a new connection that has not begun its first request, or
        a request on its way, after ``slow`` seconds (a browser sends its request at once; a
        newcomer must have the time to); either at once for the instructor (``any_request``).
        Connections being answered, and the instructor's, never give way.
        """
        idle: Slot | None = None
        slowest: Slot | None = None
        for s in slots:
            if s.admin:
                continue
            if s.phase == "idle":
                ripe = any_request or now - s.since >= self.idle_grace
                if ripe and (idle is None or s.since < idle.since):
                    idle = s
            elif (
                s.phase != "busy"
                and (any_request or now - s.since > self.slow)
                and (slowest is None or s.since < slowest.since)
            ):
                slowest = s
        return idle or slowest

    def _place(self, slot: Slot) -> None:
        """A waiter of the reserve (queued or not) becomes a member."""
        self._unwait(slot)
        slot.queued = False
        self._join(slot)

    def _join(self, slot: Slot) -> None:
        slot.reserved = False
        self.members[slot] = None
        self.per[slot.address] += 1

    def _unwait(self, slot: Slot) -> None:
        self.waiting.pop(slot, None)

    def _evict(self, slot: Slot, status: int, text: str) -> None:
        self._drop(slot, None)  # its place is for whoever this eviction is for
        slot.evicted, slot.queued = True, False
        self.evicted += 1
        slot.close(status, text)
        if slot.wake is not None:  # it was queueing: its server stops waiting
            slot.wake()
