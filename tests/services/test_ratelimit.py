"""Per-client token buckets (issue 14): :class:`services.common.ratelimit.RateLimiter`.

A fake clock makes every count exact; the end-to-end behaviour (a flooding client
refused while another one is served, through the ACL router) is in
``tests/deploy/test_rate_limit.py``.
"""

from __future__ import annotations

import pytest

from services.common.ratelimit import CLIENT, NEW, OK, TOTAL, RateLimiter
from services.monitor.slots import FREE, fair_slot
from services.predictor.__main__ import build_parser
from skinet.wire import keys


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_client_gets_its_burst_then_its_rate() -> None:
    clock = Clock()
    limiter = RateLimiter(5.0, 3.0, clock=clock)
    assert [limiter.allow("a") for _ in range(5)] == [True, True, True, False, False]
    clock.now += 0.2  # one request's worth at 5/s
    assert [limiter.allow("a") for _ in range(2)] == [True, False]
    clock.now += 10.0  # the bucket refills to the burst, not beyond
    assert sum(limiter.allow("a") for _ in range(10)) == 3


def test_clients_have_their_own_buckets() -> None:
    clock = Clock()
    limiter = RateLimiter(2.0, clock=clock)  # burst: one second's worth
    assert sum(limiter.allow("flooder") for _ in range(100)) == 2
    assert [limiter.allow("monitor"), limiter.allow("monitor"), limiter.allow("monitor")] == [True, True, False]
    assert limiter.refusal("flooder") == "rate limited: client 'flooder' exceeds 2 requests/s (burst 2)"


def test_tracked_clients_are_bounded_and_a_busy_one_is_never_dropped() -> None:
    clock = Clock()
    limiter = RateLimiter(1.0, 3.0, max_clients=3, clock=clock)
    for name in ("a", "b", "c"):
        assert limiter.allow(name)
    assert limiter.take("d") == NEW  # three new names took the new names' burst
    clock.now += 3.0
    assert [limiter.take("a") for _ in range(4)] == [OK, OK, OK, CLIENT]
    assert limiter.allow("b") and limiter.allow("c")  # "a" is the least recently used, and empty
    assert limiter.take("d") == NEW  # the table is full and "a" has not filled up again: nobody is dropped
    clock.now += 1.0
    assert limiter.take("d") == NEW and limiter.tracked() == 3  # "a" has one token of three
    clock.now += 2.0  # "a" is full again: forgetting it loses nothing
    assert limiter.take("d") == OK and limiter.tracked() == 3
    assert limiter.take("a") == OK  # back as a new name, "b" (full and idle) dropped for it
    assert [limiter.take("a") for _ in range(3)] == [OK, OK, CLIENT]
    assert limiter.tracked() == 3


def test_rotating_names_get_no_more_than_one_more_client() -> None:
    """A client asking under a new name each time (``check/bad{i}``) gets the new names' budget: ``rate``
    new names a second after a burst of ``burst``, whatever it sends; a known client keeps its own."""
    clock = Clock()
    limiter = RateLimiter(20.0, total=100.0, clock=clock)
    assert limiter.allow("good")
    answered = refused = 0
    for second in range(10):  # 1024 requests a second under new names, 10 s (a step exact in binary)
        for i in range(1024):
            ok = limiter.take(f"bad{second}-{i}")
            answered += ok == OK
            refused += ok == NEW
            clock.now += 1 / 1024
        assert limiter.allow("good")
    # The burst's 20 less the one "good" took, then 20 a second: 199.98 tokens by the last request.
    assert (answered, refused) == (19 + 199, 10_240 - 19 - 199)
    assert limiter.refusal("bad", NEW) == ("rate limited: too many new clients (more than 20 new names/s, 1024 "
                                           "clients at most); ask again under a name already used")


def test_all_clients_together_are_bounded() -> None:
    clock = Clock()
    limiter = RateLimiter(20.0, total=50.0, clock=clock)
    names = [f"c{i}" for i in range(5)]
    for i, name in enumerate(names):
        clock.now += 1.0  # five names, one a second: within the new names' budget
        assert limiter.allow(name)
    taken = [limiter.take(name) for _ in range(20) for name in names]  # 100 at once, 20 each
    assert taken.count(OK) == 49 and taken.count(TOTAL) == 51  # 50 a second in all, one taken above
    assert limiter.refusal("c0", TOTAL) == "rate limited: all clients together exceed 50 requests/s"
    clock.now += 0.125  # 6.25 more in all; c0's own bucket (10 left) is not what refuses
    assert [limiter.take("c0") for _ in range(8)] == [OK] * 6 + [TOTAL] * 2
    assert RateLimiter(20.0, total=0).total is None and RateLimiter(0.0, total=50).take("x") == OK


def test_zero_rate_is_no_limit() -> None:
    limiter = RateLimiter(0.0)
    assert all(limiter.allow("a") for _ in range(1000)) and limiter.tracked() == 0


@pytest.mark.parametrize("key, client", [
    ("skinet/spot_arm/predict/monitor", "monitor"),
    ("skinet/spot_arm/predict/monitor/p1", "monitor"),
    ("skinet/spot_arm/check/observer", "observer"),
    ("skinet/spot_arm/predict/*", None),
    ("skinet/spot_arm/check/**", None),
    ("skinet/spot_arm/check", None),
])
def test_client_of_key(key: str, client: str | None) -> None:
    assert keys.client_of(key) == client


def test_rate_limit_option(capsys: pytest.CaptureFixture[str]) -> None:
    assert build_parser().parse_args([]).rate_limit == 20.0
    assert build_parser().parse_args(["--rate-limit", "0"]).rate_limit == 0.0
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["--rate-limit", "-1"])
    assert exc.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        "python -m services.predictor: error: argument --rate-limit: expected a number >= 0, got '-1' "
        "(see python -m services.predictor --help)")


def test_waiting_slots_are_shared_fairly() -> None:
    assert fair_slot(["hog"] * 3, "hog", 4) == FREE
    assert fair_slot(["hog"] * 4, "hog", 4) is None  # full, and nobody holds more than it
    assert fair_slot(["hog"] * 4, "good", 4) == 0  # the hog's oldest is answered now
    assert fair_slot(["a", "hog", "b", "hog"], "good", 4) == 1  # the biggest holder's oldest
    assert fair_slot(["a", "b", "c", "d"], "e", 4) == 0  # one name each: the oldest makes room
    assert fair_slot(["a", "good", "a", "good"], "good", 4) is None  # its share already
    assert fair_slot(["a", "good", "a", "a"], "good", 4) == 0
