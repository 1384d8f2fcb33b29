"""Nothing lost across a router restart (issue 14; SPEC §7).

Canonical events go through the bridge's publisher (:func:`event_publisher`: a
cache and heartbeats) to the monitor's subscriber (:func:`event_subscriber`:
recovery from that cache).  The router is closed while events keep coming and
reopened on the same port: every event reaches the monitor in order.  With a
cache smaller than the outage, the monitor counts exactly the events it could not
get back and resyncs.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from services.monitor import start_monitor
from skinet.files import load_system
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import LiveState
from tests.services.conftest import free_port, open_client, open_router
from tests.services.test_monitor import Events, wait_until

REPO = Path(__file__).resolve().parents[2]
SYSTEM = load_system(REPO / "skillsets" / "spot_arm.toml")[0]


class Outage:
    """A router on a fixed port that can be closed and reopened; ``login(user)`` opens a
    client session of it (users matter with access control)."""

    def __init__(self, router: Callable[[str], zenoh.Session] = open_router,
                 login: Callable[[str, str], zenoh.Session] = lambda endpoint, user: open_client(endpoint)) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self._open, self._login = router, login
        self.router: zenoh.Session | None = router(self.endpoint)

    def login(self, user: str) -> zenoh.Session:
        return self._login(self.endpoint, user)

    def down(self) -> None:
        assert self.router is not None
        self.router.close()
        self.router = None

    def up(self) -> None:
        self.router = self._open(self.endpoint)

    def close(self) -> None:
        if self.router is not None:
            self.router.close()


@pytest.fixture
def outage() -> Iterator[Outage]:
    o = Outage()
    yield o
    o.close()


def run(outage: Outage, cache: int, seconds: float, total: int = 200, rate: float = 40.0) -> tuple:
    """Publish ``total`` status events at ``rate``/s, with the router down ``seconds`` from the 40th."""
    pub_s, mon_s, obs_s = outage.login("bridge"), outage.login("monitor"), outage.login("observer")
    states: list[LiveState] = []
    # On the monitor's own session: what it publishes during the outage too.
    sub = mon_s.declare_subscriber(keys.state("spot_arm"), lambda s: states.append(
        decode(s.payload.to_bytes(), LiveState)))
    monitor = start_monitor(mon_s, SYSTEM)
    events = Events(pub_s, source="bridge", advanced=True, cache=cache, model=SYSTEM)
    try:
        events.synced()
        time.sleep(0.5)  # the monitor's subscription reaches the publisher
        down_at = 40
        up_at = down_at + int(seconds * rate)
        for n in range(total):
            if n == down_at:
                outage.down()
            if n == up_at:
                outage.up()
            events.send("spot", None)
            time.sleep(1 / rate)
        wait_until(lambda: monitor.counters.received + monitor.counters.unrecovered >= total, 20,
                   f"the events after recovery ({monitor.counters})")
        wait_until(monitor.synced, 10, "live again")
        time.sleep(1.0)  # anything late arrives now
        return monitor.counters, list(states)
    finally:
        events.close()
        monitor.close()
        sub.undeclare()
        for s in (pub_s, mon_s, obs_s):
            s.close()


def test_router_restart_loses_nothing(outage: Outage) -> None:
    counters, states = run(outage, cache=4096, seconds=3.0)
    assert (counters.received, counters.applied, counters.lost, counters.unrecovered, counters.out_of_order,
            counters.duplicates, counters.history) == (200, 200, 0, 0, 0, 0, 0)
    # The outage showed: the skillset was lost, then syncing, then live again (SPEC §7).
    seen = [s.sync["spot"].state for s in states]
    changes = [a for a, b in zip(seen, [None, *seen]) if a != b]
    assert changes == ["syncing", "live", "lost", "syncing", "live"], changes
    assert "the liveliness token of 'bridge' is gone" in next(s.sync["spot"].reason for s in states
                                                              if s.sync["spot"].state == "lost")


def test_outage_longer_than_the_cache_is_counted_exactly(outage: Outage) -> None:
    counters, _ = run(outage, cache=10, seconds=2.0)
    assert counters.unrecovered > 0
    assert counters.lost == counters.unrecovered == 200 - counters.applied
    assert counters.out_of_order == counters.duplicates == 0


@pytest.mark.parametrize("stamp", [0.0, -1.0, 4e9], ids=["1970", "wall-clock", "future"])
def test_a_late_monitor_does_not_replay_the_cache(outage: Outage, stamp: float) -> None:
    """zenoh.ext gives a new subscriber everything cached before the publisher's heartbeat: a monitor
    started late counts what its resync answer covers as history, whatever the events' stamps
    (here from 1970, now or 2096), and follows from the next event."""
    pub_s, mon_s = outage.login("bridge"), outage.login("monitor")
    events = Events(pub_s, source="bridge", advanced=True, model=SYSTEM, wait=False)
    stamp = time.time() if stamp < 0 else stamp
    try:
        for _ in range(50):
            events.send("spot", None, stamp=stamp)  # #1..#50, before the monitor starts
        monitor = start_monitor(mon_s, SYSTEM)
        try:
            events.synced()
            wait_until(lambda: monitor.counters.history == 50, 10, f"the cache's replay ({monitor.counters})")
            events.send("spot", "init_power.start", stamp=stamp)
            wait_until(lambda: monitor.counters.applied == 1, 5, "the live event")
            assert (monitor.counters.received, monitor.counters.lost) == (51, 0)
            assert monitor.snapshot().state.skillsets["spot"].running == ["init_power"]
        finally:
            monitor.close()
    finally:
        events.close()
        pub_s.close()
        mon_s.close()
