"""Budgets of what clients make the server hold or do: per-client limits and shared pools.

Every resource a client can make the server hold is counted in what it costs (bytes, not
characters; ids, not topics) twice: against the client's own limit (:class:`Limits`, kept by
its :class:`~simbridge.rosbridge.session.Session`) and against a :class:`Pool` shared by every
client of the process, so that many clients together cannot exhaust the server either. Both are
given back when the client lets go of the resource or leaves. ``docs/security.md`` lists every
budget, its default and what its refusal says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.graph.access import TokenBucket


__all__ = ["GLOBAL_LIMITS", "Limits", "Pool", "TokenBucket"]


@dataclass(frozen=True, slots=True)
class Limits:
    """What one client may make the server hold or do (``ServerSettings`` sets them)."""

    #: Subscribed topic spellings.
    subscriptions: int = 200
    #: Subscribe ids over every topic (each id is kept; rosbridge merges their options).
    subscribe_ids: int = 1_000
    #: Subscribe ids on one topic spelling.
    ids_per_subscription: int = 100
    #: Advertised names: topics, services and actions together.
    advertisements: int = 100
    #: Advertise ids over every topic.
    advertise_ids: int = 1_000
    #: Calls waiting for a client provider's answer.
    pending_calls: int = 100
    #: Longest a call waits for a client provider, seconds (``timeout: 0`` waits this long).
    call_timeout: float = 60.0
    #: Length of an op's id (characters of a string, digits of an integer).
    id_length: int = 1_000
    #: Goals of this client in flight (to any action server).
    pending_goals: int = 100
    #: Longest a goal to an action served by a client waits for its result, seconds.
    goal_timeout: float = 600.0
    #: Incomplete fragmented messages at once.
    fragment_sets: int = 16
    #: Bytes of incomplete fragments (UTF-8), and the largest reassembled message.
    fragment_bytes: int = 10_000_000
    #: Seconds an incomplete fragmented message may wait for its missing pieces.
    fragment_timeout: float = 60.0
    #: Bytes of latched messages this client published that the server keeps for later
    #: subscribers (their JSON size).
    latched_bytes: int = 16_000_000
    #: ``publish`` ops per second, sustained, and the burst above it.
    publish_rate: float = 200.0
    publish_burst: int = 400
    #: ``status`` refusals per second (and one per cause per second); the rest are counted.
    statuses_per_second: int = 10
    #: Length of one frame (characters of a text frame, bytes of a binary one) from a client
    #: without the admin token; a longer one is refused before it is parsed.
    frame_bytes: int = 1_000_000
    #: JSON values (about: commas + 1, each object counting 32 and each array 4) in one frame
    #: from a client without the admin token; more are refused before parsing.
    frame_values: int = 100_000
    #: Largest frame read from a client that has not authenticated yet (only ``auth`` is).
    unauthenticated_frame_bytes: int = 16_384
    #: Seconds of the loop's time one client's frames may take per second (a share: 0.25 is a
    #: quarter of the loop); past it the client's frames wait, unread.
    work_share: float = 0.25


#: Shared pools: what every client together may make the server hold.
GLOBAL_LIMITS: dict[str, int] = {
    "subscribe_ids": 20_000,
    "advertise_ids": 20_000,
    "pending_calls": 2_000,
    "pending_goals": 2_000,
    "fragment_bytes": 40_000_000,
    "latched_bytes": 64_000_000,
}


class Pool:
    """Counters of what every client together holds, each with a limit (absent: none)."""

    def __init__(self, limits: dict[str, int] | None = None) -> None:
        self._limits = dict(GLOBAL_LIMITS if limits is None else limits)
        #: What is held now, by resource.
        self.used: dict[str, int] = dict.fromkeys(self._limits, 0)

    def limit(self, what: str) -> int | float:
        """Return the limit of ``what`` (infinite when none is set)."""
        return self._limits.get(what, math.inf)

    def take(self, what: str, n: int = 1) -> bool:
        """Take ``n`` of ``what`` if the pool allows it; return whether it did."""
        used = self.used.get(what, 0)
        if used + n > self.limit(what):
            return False
        self.used[what] = used + n
        return True

    def give(self, what: str, n: int = 1) -> None:
        """Give back ``n`` of ``what``."""
        self.used[what] = max(0, self.used.get(what, 0) - n)
