"""A hostile model costs a predictor at most its limits (issue 14; docs/semantics.md §6, §7).

The attack: any peer answers ``skinet/h/model/<digest>`` with a consistent 1.9 KB
bundle whose nets take seconds to build, or gigabytes with more skills
(:mod:`tests.services.hostile`), and asks for a prediction with ``budget=0.1``.  Without limits, an embedded ``skinet run``
grew by gigabytes, its monitor's verdicts slowed by seconds and SIGTERM did not stop
it.  Here the predictor answers within the budget plus its grace, its own memory
does not grow, the monitor on the same session keeps publishing every step, and
``skinet run`` stops at once.  ``benchmarks/bench_hostile.py`` gives the figures.
"""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

import zenoh

from services.monitor import start_monitor
from services.predictor import start_predictor
from skinet.system.load import load_system
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import LiveState, PredictReply
from tests.services.conftest import LivelinessWatch, free_port, open_client, start_skinet
from tests.services.test_monitor import Events
from tests.services.test_predictor import peer  # noqa: F401  (one session for monitor, predictor and attacker)
from tests.services.hostile import Attacker, hostile_bundle

REPO = Path(__file__).resolve().parents[2]
SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
GRACE = 0.5
MEMORY_MB = 400
# Time for the reply beyond budget + grace: the query's round trip and, after a kill,
# nothing (the replacement's start-up happens before the next job, not in this one).
SLACK = 1.0


def rss_kb() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def the_reply(replies: list[zenoh.Reply]) -> PredictReply:
    assert len(replies) == 1 and replies[0].ok is not None, replies
    return decode(replies[0].ok.payload.to_bytes(), PredictReply)


def test_hostile_bundle_costs_at_most_the_limits_and_the_monitor_keeps_up(peer: zenoh.Session) -> None:
    system, _ = load_system(SYSTEM_FILE)
    t0 = time.monotonic()
    predictor = start_predictor(peer, "embedded", memory_mb=MEMORY_MB, grace=GRACE)
    startup = time.monotonic() - t0  # its workers' start-up, which a replacement needs again
    monitor = start_monitor(peer, system, budget=0.2)
    events = Events(peer, system.name, source="t", model=system)  # the bridge's side: the monitor syncs
    attacker = Attacker(peer)
    states: list[int] = []
    sub = peer.declare_subscriber(keys.state(system.name),
                                  lambda s: states.append(decode(s.payload.to_bytes(), LiveState).seq))
    try:
        before = rss_kb()
        # Events flow to the monitor during the whole attack (status-only events: each is a step).
        stop = threading.Event()
        sent = []

        def feed() -> None:
            while not stop.is_set() and len(sent) < 64:
                sent.append(events.send("spot", None))
                time.sleep(0.05)

        feeder = threading.Thread(target=feed)
        feeder.start()
        for n in range(3):
            t0 = time.monotonic()
            reply = the_reply(attacker.ask(budget=0.1, seq=n + 1))
            took = time.monotonic() - t0
            # An answer of the core within the budget (it bounds exploration itself), or the
            # worker killed at budget + grace.
            killed = f"exceeded the budget of 0.1 s (+{GRACE:g} s grace): worker killed"
            assert reply.ok or reply.error == killed, reply
            bound = 0.1 + GRACE + SLACK + (2 * startup if n else 0)  # after a kill: the replacement starts
            assert took < bound, f"attack {n}: reply after {took:.2f} s (bound {bound:.2f} s)"
        feeder.join()
        assert predictor.counts["fetched"] == 2  # the monitor's model and h
        grown = (rss_kb() - before) / 1024
        assert grown < 50, f"the predictor's process grew by {grown:.0f} MB"
        deadline = time.monotonic() + 5
        while monitor.counters.applied < 64 and time.monotonic() < deadline:
            time.sleep(0.05)
        c = monitor.counters
        assert (c.received, c.applied, c.lost, c.errors) == (64, 64, 0, 0), "the monitor missed events"
        # A genuine request still gets a real answer from the replacement worker.
        ok = monitor.predictor_stats.answered
        assert ok >= 1
    finally:
        sub.undeclare()
        attacker.close()
        events.close()
        monitor.close()
        predictor.close()


def test_memory_limit_kills_the_worker_not_the_instance(peer: zenoh.Session) -> None:
    limit = 300
    predictor = start_predictor(peer, "small", memory_mb=limit, grace=GRACE, max_budget=120)
    attacker = Attacker(peer, hostile_bundle(skills=80))  # about 10 KB, gigabytes to build
    try:
        before = rss_kb()
        reply = the_reply(attacker.ask(budget=120.0, timeout=150))
        assert (reply.ok, reply.error) == (False, f"exceeded the memory limit of {limit} MB: worker replaced")
        assert (rss_kb() - before) / 1024 < 50
        # The instance keeps serving: a small consistent model is answered.
        small = Attacker(peer, hostile_bundle(resources=2, skills=2))
        try:
            assert the_reply(small.ask(budget=2.0)).ok
        finally:
            small.close()
    finally:
        attacker.close()
        predictor.close()


def test_skinet_run_under_attack_stops_on_sigterm() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = start_skinet("run", str(SYSTEM_FILE), "--listen", endpoint, "--duration", "60")
    session = None
    try:
        assert proc.stdout is not None
        while not (line := proc.stdout.readline()).startswith("[0] start"):  # after the lines that reach it
            assert line.startswith(("skinet run: system spot_arm, listening on", "  ")), line
        session = open_client(endpoint)
        LivelinessWatch(session, keys.alive("*", "predictor", "*")).wait(bool)
        attacker = Attacker(session)
        asking = threading.Thread(target=attacker.ask, kwargs={"budget": 10.0, "timeout": 20})
        asking.start()
        time.sleep(1.0)  # the worker is building the hostile nets now
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        assert time.monotonic() - t0 < 5.0, "skinet run took too long to stop"
        asking.join(20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if session is not None:
            session.close()
