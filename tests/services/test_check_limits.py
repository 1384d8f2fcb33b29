"""Limits on the command check that a client cannot dodge (issue 31, item 4; docs/deployment.md "Rate limits
per client").

Without the router's access control the client chunk of ``skinet/<system>/check/<client>`` is the
client's own choice: a flood under a new name each time (``check/bad{i}``) must get no more than the new
names' budget while a client under its usual name keeps being answered, and a client asking to wait
cannot hold all of the monitor's waiting slots.  A real monitor on its own client session of a real router;
no bridge, so every answer says the state is unknown and a request asking to wait is kept.
``benchmarks/bench_hostile.py`` measures the good client's latency under both floods.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable

import zenoh

from services.common.ratelimit import CHECK_RATE_LIMIT
from services.monitor.check import parse_command
from services.monitor.service import MAX_WAITING, Monitor
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CheckReply
from tests.services.test_monitor import monitor_factory, session, system  # noqa: F401 (fixtures)
from tests.services.conftest import open_client

REQUEST = encode(parse_command("spot:init_power.start"))
NEW_NAMES = "rate limited: too many new clients"


def outcome(replies: list[zenoh.Reply]) -> str:
    """'answered', the refusal's first words, or what went wrong."""
    if len(replies) != 1 or replies[0].ok is None:
        return f"{len(replies)} replies, errors {[r.err.payload.to_string() for r in replies if r.err is not None]}"
    reply = decode(replies[0].ok.payload.to_bytes(), CheckReply)
    return "answered" if reply.ok else reply.error


def test_a_flood_under_rotating_names_gets_the_new_names_budget(router: str, monitor_factory: Callable[..., Monitor],
                                                                system: System, session: zenoh.Session) -> None:
    monitor = monitor_factory(system)
    good = session
    assert outcome(list(good.get(keys.check(system.name, "good"), payload=REQUEST, timeout=5))) == "answered"
    flooder = open_client(router)
    results: Counter[str] = Counter()
    lock = threading.Lock()
    n, threads = 500, 4

    def flood(t: int) -> None:
        for i in range(n):
            what = outcome(list(flooder.get(keys.check(system.name, f"bad{t}x{i}"), payload=REQUEST, timeout=5)))
            with lock:
                results[what[:len(NEW_NAMES)]] += 1

    good_results: list[str] = []
    flooding = [threading.Thread(target=flood, args=(t,)) for t in range(threads)]
    t0 = time.monotonic()
    try:
        for t in flooding:
            t.start()
        while any(t.is_alive() for t in flooding):  # the good client asks under its usual name
            good_results.append(outcome(list(good.get(keys.check(system.name, "good"), payload=REQUEST, timeout=10))))
            time.sleep(0.2)
        for t in flooding:
            t.join()
        seconds = time.monotonic() - t0
    finally:
        flooder.close()
    # The new names' burst (refilled since "good" took one) and CHECK_RATE_LIMIT new names a second; the rest refused.
    bound = CHECK_RATE_LIMIT + CHECK_RATE_LIMIT * seconds
    print(f"flooder: {dict(results)} in {seconds:.1f} s (answered at most {bound:.0f}); good: {Counter(good_results)}")
    assert set(results) <= {"answered", NEW_NAMES} and sum(results.values()) == n * threads, results
    assert results["answered"] <= bound, results
    assert results[NEW_NAMES] >= n * threads - bound
    assert good_results and set(good_results) == {"answered"}, good_results
    c = monitor.check_counters
    assert c.rate_limited == results[NEW_NAMES] and c.answered == results["answered"] + len(good_results) + 1
    assert monitor.check_limiter.tracked() == results["answered"] + 1


def test_one_client_cannot_hold_every_waiting_slot(router: str, monitor_factory: Callable[..., Monitor], system: System,
                                                   session: zenoh.Session) -> None:
    monitor = monitor_factory(system, check_rate_limit=0)  # the slots alone: the hog asks as fast as it likes
    hog = open_client(router)
    waiting = encode(parse_command("spot:init_power.start").model_copy(update={"wait": 30.0}))
    answered: list[float] = []
    lock = threading.Lock()

    def count(reply: zenoh.Reply) -> None:
        assert reply.ok is not None and decode(reply.ok.payload.to_bytes(), CheckReply).state_stale
        with lock:
            answered.append(time.monotonic())

    def hog_answers() -> int:
        with lock:
            return len(answered)

    def until(what: Callable[[], bool], timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not what():
            assert time.monotonic() < deadline, "timed out"
            time.sleep(0.02)

    extra = 20
    try:
        for _ in range(MAX_WAITING + extra):
            hog.get(keys.check(system.name, "hog"), zenoh.handlers.Callback(count), payload=waiting, timeout=60)
        until(lambda: hog_answers() == extra)  # the slots full: the rest answered at once
        until(lambda: len(monitor._waiting) == MAX_WAITING)
        # Three other clients asking to wait at once get a slot each: the hog's three oldest are answered now.
        short = encode(parse_command("spot:init_power.start").model_copy(update={"wait": 3.0}))
        t0 = time.monotonic()
        asked = [session.get(keys.check(system.name, f"good{i}"), payload=short, timeout=10) for i in range(3)]
        assert [outcome(list(replies)) for replies in asked] == ["answered"] * 3
        assert time.monotonic() - t0 >= 3.0, "they waited their 3 s, as they asked"
        c = monitor.check_counters
        assert (c.made_room, c.waited, hog_answers()) == (3, 3 + 3, extra + 3)
        assert len(monitor._waiting) == MAX_WAITING - 3
    finally:
        monitor.close()  # answers the hog's waiting requests before its session goes
        until(lambda: hog_answers() == MAX_WAITING + extra)
        hog.close()
