"""Per-client token buckets (issue 14): :class:`services.common.ratelimit.RateLimiter`.

A fake clock makes every count exact; the end-to-end behaviour (a flooding client
refused while another one is served, through the ACL router) is in
``tests/deploy/test_rate_limit.py``.
"""

from __future__ import annotations

import pytest

from services.common.ratelimit import RateLimiter
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


def test_tracked_clients_are_bounded_least_recently_used_first() -> None:
    clock = Clock()
    limiter = RateLimiter(1.0, max_clients=3, clock=clock)
    assert limiter.allow("a") and not limiter.allow("a")
    for name in ("b", "c", "a", "d"):  # "a" used again: "b" is the oldest when "d" comes
        limiter.allow(name)
    assert limiter.tracked() == 3
    assert not limiter.allow("a")  # still tracked, still empty
    assert limiter.allow("b")  # dropped, back with a full bucket
    assert limiter.tracked() == 3


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
