from __future__ import annotations

from simbridge.rosbridge import Pool, TokenBucket


def test_pool_takes_within_its_limit_and_gives_back() -> None:
    """A shared pool refuses what would pass its limit; what is given back can be taken."""
    pool = Pool({"ids": 3})
    assert pool.take("ids", 2) and not pool.take("ids", 2) and pool.take("ids")
    assert pool.used["ids"] == 3
    pool.give("ids", 2)
    assert pool.take("ids", 2) and pool.used["ids"] == 3
    assert pool.take("unlimited", 10**9)  # no limit set: only counted


def test_token_bucket_charge_goes_into_debt_and_says_how_long_to_wait() -> None:
    """The work budget: a 100 ms frame at a share of 0.25 costs 400 ms of waiting."""
    work = TokenBucket(rate=0.25, burst=0.0)
    assert work.charge(0.0, 0.1) == 0.1 / 0.25
    assert work.charge(0.4, 0.0) == 0.0  # the debt is paid after the wait
