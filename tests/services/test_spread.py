"""Load spreading and failover across predictor instances (docs/semantics.md §7), real processes on a real router.

Predictors run as ``python -m services.predictor`` processes, clients of a Python
router; the monitor runs in-process on its own client session.  A predictor frozen
with SIGSTOP must not stall predictions for the liveliness lease (10 s): the
monitor hears no "working" reply for ``stall`` seconds and asks another instance.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from services.monitor.pool import Pool
from services.monitor.service import SystemNameTaken, start_monitor
from skinet.system.load import load_system
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.convert import statuses
from skinet.wire.messages import PredictReply, PredictRequest
from tests.processes import start_module, stop
from tests.services.conftest import LivelinessWatch, client_args, open_client
from tests.services.test_monitor import (
    PAPER_STEPS, Events, Reports, _heavy_system, monitor_factory, session, system, wait_until,
)

__all__ = ["monitor_factory", "session", "system"]  # fixtures used here


def _token(instance: str) -> str:
    return keys.alive(keys.ANY_SYSTEM, "predictor", instance)


@pytest.fixture
def pool_of(router: str, session: zenoh.Session, tmp_path: Path):
    """Starts predictor processes ``pool_of("pa", "pb")`` and waits for their tokens."""
    procs: list[subprocess.Popen] = []
    watch = LivelinessWatch(session, keys.alive("*", "predictor", "*"))

    def start(*names: str) -> dict[str, subprocess.Popen]:
        started = {n: start_module("services.predictor", *client_args(router), "--instance", n, "--fetch-timeout", "1",
                                   log=tmp_path / f"{n}.log") for n in names}
        procs.extend(started.values())
        for n in names:
            watch.wait_for(_token(n), timeout=15)
        return started

    yield start
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGCONT)
        stop(proc)
    watch.close()


# -- the pick, in memory -------------------------------------------------------------------


def test_pool_picks_least_outstanding_then_least_recent_and_avoids_suspects() -> None:
    pool = Pool(suspicion=60.0)
    for name in ("a", "b", "c"):
        pool.add(name)
    first = [pool.pick() for _ in range(1)][0]
    assert first is not None
    order = []
    for _ in range(6):  # one query at a time: a rotation over the three
        name = pool.pick()
        assert name is not None
        pool.sent(name)
        pool.returned(name)
        order.append(name)
    assert order[:3] == order[3:] and sorted(order[:3]) == ["a", "b", "c"] and order[0] == first
    pool.sent("a"), pool.sent("a"), pool.sent("b")
    assert pool.pick() == "c"  # nothing outstanding there
    pool.sent("c")
    assert pool.pick() in ("b", "c") and pool.pick(exclude={"b", "c"}) == "a"
    pool.suspect("c")
    pool.returned("c")
    assert pool.pick() == "b" and pool.pick(exclude={"a", "b"}) == "c", "a suspect only when nothing else is left"
    pool.add("c")  # its token again: no longer suspect
    assert pool.pick() == "c"
    pool.remove("c")
    assert pool.names() == ["a", "b"] and pool.pick(exclude={"a", "b"}) is None
    pool.returned("c")  # a query to a removed instance ends: no error


# -- spreading -----------------------------------------------------------------------------


def test_queries_alternate_between_two_instances(pool_of, monitor_factory, session, system) -> None:
    pool_of("pa", "pb")
    reports = Reports(session)
    # Stalls have their own tests: here a worker starved for 0.5 s by a loaded machine (CI builds images
    # beside it) must not make the monitor suspect an instance and skew the rotation.
    monitor = monitor_factory(system, stall=5.0)
    assert monitor.predictor_stats.instances == ["pa", "pb"]
    events = Events(session)
    reports.wait("unsafe", lambda m: m.seq == 0 and not m.prediction_stale, timeout=10)
    for step, (skillset, transition, _, _) in enumerate(PAPER_STEPS, 1):
        events.send(skillset, transition)
        reports.wait("unsafe", lambda m, s=step: m.seq == s and not m.prediction_stale, timeout=10)
    stats = monitor.predictor_stats
    # One query at a time: least outstanding is a tie, so least recently used alternates.
    assert set(stats.answers) == {"pa", "pb"} and abs(stats.answers["pa"] - stats.answers["pb"]) <= 1, stats
    assert sum(stats.answers.values()) == stats.answered == stats.sent >= 8
    assert (stats.retried, stats.failed, stats.timed_out, stats.unanswered) == (0, 0, 0, 0)
    # Clients that do not spread still get one answer on the shared key.
    request = PredictRequest(system="spot_arm", digest=monitor.digest, seq=7,
                             skillsets=statuses(system, system.initial_marking()), budget=1.0)
    replies = list(session.get(keys.predict("spot_arm", keys.LOCAL_CLIENT), payload=encode(request), timeout=3.0))
    assert len(replies) == 1 and decode(replies[0].ok.payload.to_bytes(), PredictReply).instance in ("pa", "pb")
    # On an instance's own key: "working" replies (empty), then the answer of that instance.
    replies = list(session.get(keys.predict_instance("spot_arm", keys.LOCAL_CLIENT, "pb"), payload=encode(request), timeout=3.0,
                               consolidation=zenoh.ConsolidationMode.NONE))
    payloads = [r.ok.payload.to_bytes() for r in replies]
    assert payloads[0] == b"" and all(p == b"" for p in payloads[:-1])
    answer = decode(payloads[-1], PredictReply)
    assert (answer.ok, answer.instance, answer.seq) == (True, "pb", 7)


# -- failover within the query timeout -----------------------------------------------------


@pytest.mark.parametrize("sig", [signal.SIGSTOP, signal.SIGKILL], ids=["frozen", "killed"])
def test_instance_lost_mid_query_is_replaced_within_the_timeout(pool_of, monitor_factory, session, tmp_path,
                                                               sig: signal.Signals) -> None:
    fleet = load_system(_heavy_system(tmp_path, pairs=3))[0]  # about 1.5 s of exploration
    procs = pool_of("pa", "pb")
    watch = LivelinessWatch(session, keys.alive("*", "predictor", "*"))
    reports = Reports(session, "fleet")
    monitor = monitor_factory(fleet, budget=5.0, query_timeout=12.0, retry=30.0)
    fetched = {n: lambda n=n: "fetched model" in (tmp_path / f"{n}.log").read_text() for n in procs}
    wait_until(lambda: any(f() for f in fetched.values()), 5, "exploration started")
    busy = next(n for n, f in fetched.items() if f())
    other = "pb" if busy == "pa" else "pa"
    assert monitor.predictor_stats.answered == 0, "exploration finished before the signal"
    lost = time.monotonic()
    procs[busy].send_signal(sig)
    fresh = reports.wait("unsafe", lambda m: not m.prediction_stale, timeout=12)
    took = time.monotonic() - lost
    stats = monitor.predictor_stats
    assert fresh.seq == 0 and stats.last_instance == other and stats.retried == 1
    if sig == signal.SIGSTOP:  # answered before the 10 s lease could remove the frozen instance
        assert _token(busy) in watch.alive
    # silence of 0.5 s (frozen) or at once (killed), then a whole exploration on the other
    # instance (about 1.5 s on a quiet machine), with the 12 s timeout's budget left: at most 5 s.
    assert took < 8.0, took
    assert (stats.answered, stats.timed_out, stats.unanswered) == (1, 0, 0)
    space = reports.wait("state_space", lambda m: m.system == "fleet", timeout=2)
    assert not space.timeout_reached and space.markings == 250047
    watch.close()


def test_whole_pool_frozen_marks_predictions_stale_without_hanging(pool_of, monitor_factory, session,
                                                                   system) -> None:
    procs = pool_of("pa", "pb")
    for proc in procs.values():
        proc.send_signal(signal.SIGSTOP)
    reports = Reports(session)
    monitor = monitor_factory(system, budget=1.0, query_timeout=2.0, retry=0.2)
    events = Events(session)
    for step, (skillset, transition, unsafe, _) in enumerate(PAPER_STEPS[:4], 1):
        sent = time.perf_counter()
        events.send(skillset, transition)
        _, _, report = reports.step(step)
        assert report.prediction_stale  # explicit constraints on time, predictions marked stale
        assert reports.arrival("unsafe", lambda m, s=step: m.seq == s) - sent < 1.0
    # both tried (0.5 s of silence each), then the query ends without waiting for its timeout
    wait_until(lambda: monitor.predictor_stats.unanswered >= 1, 3, "query given up")
    stats = monitor.predictor_stats
    assert stats.answered == 0 and stats.retried >= 1 and stats.timed_out == 0
    for proc in procs.values():
        proc.send_signal(signal.SIGCONT)
    # Thawed: the suspicion ends with the next answer or the 10 s suspicion; the retry
    # delay then sends the latest marking again and it turns fresh.
    reports.wait("unsafe", lambda m: m.seq == 4 and not m.prediction_stale, timeout=15)


# -- bad input -------------------------------------------------------------------------------


def test_second_monitor_of_the_same_system_name_is_refused(router: str, monitor_factory, system) -> None:
    first = monitor_factory(system)
    other = open_client(router)
    try:
        with pytest.raises(SystemNameTaken) as err:
            start_monitor(other, system)
        assert str(err.value) == (
            f"system 'spot_arm' is already monitored by {first.instance_id} on this Zenoh network: "
            "give each robot its own system name ([system] name in its .toml)")
    finally:
        other.close()


def test_monitor_process_with_a_wrong_router_endpoint_exits_with_one_line(tmp_path: Path) -> None:
    from tests.services.conftest import free_port

    port = free_port()
    proc = subprocess.run(
        [sys.executable, "-m", "services.monitor", "skillsets/spot_arm.toml", *client_args(f"tcp/127.0.0.1:{port}")],
        cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 1 and proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert lines == [f"python -m services.monitor: error: cannot open the Zenoh session: nothing answers at "
                     f"tcp/127.0.0.1:{port}"], proc.stderr
