"""The monitor's feed (services/monitor/feed.py): its results in rounds on ``skinet/<system>/feed``.

Real parts: a loopback router, the monitor and the bridge's side on clients of it, the feed's subscriber on
another; the flood's messages are a real monitor's, handed to a feed in one call (one round, whatever the
machine's speed)."""

from __future__ import annotations

from collections.abc import Callable

import msgpack
import zenoh

from services.dashboard.observer import Observer
from services.monitor import start_monitor
from services.monitor.feed import Feeder
from skinet.system.load import load_system
from skinet.wire import keys
from skinet.wire.codec import decode, encode, validate
from skinet.wire.limits import FEED_FLOOD_ROUND, FEED_ROUND
from skinet.wire.messages import Divergences, ResultFeed
from tests.bridge_side import BridgeSide
from tests.services.test_dashboard import SYSTEM_FILE
from tests.services.test_monitor import AG, PAPER_STEPS, wait_until

NAMES = {key("spot_arm"): key.__name__ for key in (keys.state, keys.verdicts, keys.unsafe, keys.state_space,
                                                    keys.divergences)}


def subscribe(session: zenoh.Session, rounds: list[ResultFeed]) -> zenoh.Subscriber:
    return session.declare_subscriber(keys.feed("spot_arm"),
                                      lambda s: rounds.append(decode(s.payload.to_bytes(), ResultFeed)))


def fed(rounds: list[ResultFeed]) -> list[tuple[str, dict]]:
    return [(r.kind, r.message) for f in list(rounds) for r in f.results]


def test_the_feed_is_the_monitors_results_in_order_and_only_while_its_key_is_subscribed_to(
        client_factory: Callable[[], zenoh.Session]) -> None:
    system = load_system(SYSTEM_FILE)[0]
    session = client_factory()
    tapped: list[tuple[str, dict]] = []
    monitor = start_monitor(session, system, tap=lambda k, p, t=0.0: k in NAMES and tapped.append(
        (NAMES[k], msgpack.unpackb(p))))
    side = BridgeSide(session, "spot_arm", model=system)
    feeder: Feeder = monitor._feed
    rounds: list[ResultFeed] = []
    try:
        viewer = client_factory()
        recorder: list[str] = []  # a recorder's wildcard (skinet record) does not match the feed's @ chunk
        viewer.declare_subscriber("skinet/spot_arm/**", lambda s: recorder.append(str(s.key_expr)))
        wait_until(lambda: monitor._pub["unsafe"].matching_status.matching, 10, "the recorder's subscriber")
        side.send(*PAPER_STEPS[0][:2])
        wait_until(lambda: "skinet/spot_arm/unsafe" in recorder, 10, "step 1's report at the recorder")
        assert (feeder.heard, feeder._since, feeder.seq, feeder.unheard) == (False, None, 0, 0)  # nothing gathered
        sub = subscribe(viewer, rounds)
        wait_until(lambda: feeder.heard, 10, "the feed's subscriber")
        for i, (skillset, transition, _, _) in enumerate(PAPER_STEPS[1:6], 2):
            side.send(skillset, transition)
            wait_until(lambda: any(k == "unsafe" and m["seq"] == i for k, m in fed(rounds)), 10, f"step {i}'s report")
        assert rounds and [k for k in recorder if "@" in k] == []
        # Every result since the first round heard, in the order published (the tap comes just after the feed);
        # no step left out (a change of sync state publishes its step again: same seq).
        wait_until(lambda: (f := fed(rounds)) == tapped[-len(f):], 10, "the feed equal to what the monitor published")
        assert list(dict.fromkeys(m["seq"] for k, m in fed(rounds) if k == "state"))[-5:] == [2, 3, 4, 5, 6]
        heard_rounds = list(rounds)  # a step published again may bring one more meanwhile
        assert [f.seq for f in heard_rounds] == list(range(1, len(heard_rounds) + 1))
        assert {(f.system, f.monitor, f.round, f.skipped) for f in heard_rounds} == {
            ("spot_arm", monitor.instance_id, FEED_ROUND, 0)}
        sub.undeclare()
        wait_until(lambda: not feeder.heard and feeder._since is None, 10, "the subscriber gone, no round pending")
        heard = feeder.seq
        side.send(*PAPER_STEPS[6][:2])
        wait_until(lambda: monitor.counters.applied == 7, 10, "step 7")
        assert (feeder._since, feeder.seq) == (None, heard)
    finally:
        side.close()
        monitor.close()


def monitor_messages(client_factory: Callable[[], zenoh.Session]) -> list[tuple[str, bytes]]:
    """What a monitor published over the paper's unassisted run and two steps more (no predictor), in order."""
    system = load_system(SYSTEM_FILE)[0]
    published: list[tuple[str, bytes]] = []
    alone = client_factory()
    monitor = start_monitor(alone, system, tap=lambda k, p, t=0.0: k in NAMES and published.append((NAMES[k], p)))
    side = BridgeSide(alone, "spot_arm", model=system)
    steps = [(s, t) for s, t, _, _ in PAPER_STEPS] + [("manipulator", "arm_ready.success.ready"),
                                                       ("manipulator", "arm_RD_to_HP.start")]
    try:
        for skillset, transition in steps:
            side.send(skillset, transition)
        wait_until(lambda: any(k == "unsafe" and msgpack.unpackb(p)["seq"] == len(steps) for k, p in published), 10,
                   "the monitor's report of the last step")
        return list(published)
    finally:
        side.close()
        monitor.close()


def test_a_flood_round_holds_the_last_of_each_kind_and_counts_the_steps_it_left_out(
        client_factory: Callable[[], zenoh.Session]) -> None:
    taken = monitor_messages(client_factory)
    last = [msgpack.unpackb(p) for k, p in taken if k == "state"][-1]["seq"]
    feeder = Feeder(client_factory(), "spot_arm", "flood")
    rounds: list[ResultFeed] = []
    subscribe(client_factory(), rounds)
    try:
        wait_until(lambda: feeder.heard, 10, "the feed's subscriber")
        feeder.add(*taken)  # one call: one round
        wait_until(lambda: len(rounds) == 1, 10, "the flood's round")
        [flood] = rounds
        steps = sum(k == "state" for k, _ in taken)
        assert (flood.seq, flood.monitor, flood.round, flood.skipped) == (1, "flood", FEED_ROUND, steps - 1)
        assert [r.kind for r in flood.results] == ["divergences", "state", "verdicts", "unsafe"]
        assert [r.message["seq"] for r in flood.results[1:]] == [last] * 3
        # The list of divergences names the violation begun and ended among the steps left out, at its step.
        divergences = validate(flood.results[0].message, Divergences)
        assert [(e.kind, e.seq, e.reason) for e in divergences.entries] == [
            ("violation", 10, f"{AG} is violated from this step")]
        assert flood.results[0].message == msgpack.unpackb([p for k, p in taken if k == "divergences"][-1])
        one_step = taken[-3:]
        assert [k for k, _ in one_step] == ["state", "verdicts", "unsafe"]
        feeder.add(*one_step)  # while a flood lasts, a round every FEED_FLOOD_ROUND
        wait_until(lambda: len(rounds) == 2, 10, "the round after the flood's")
        feeder.add(*one_step)  # that round was no flood: back to FEED_ROUND
        wait_until(lambda: len(rounds) == 3, 10, "the next round")
        step = ["state", "verdicts", "unsafe"]
        assert [(f.seq, f.round, f.skipped, [r.kind for r in f.results]) for f in rounds[1:]] == [
            (2, FEED_FLOOD_ROUND, 0, step), (3, FEED_ROUND, 0, step)]
        assert (feeder.seq, feeder.skipped, feeder.unheard) == (3, steps - 1, 0)
    finally:
        feeder.close()


def test_an_observer_of_the_feed_asks_the_monitor_again_when_a_round_is_lost(
        client_factory: Callable[[], zenoh.Session]) -> None:
    system = load_system(SYSTEM_FILE)[0]
    session = client_factory()
    monitor = start_monitor(session, system)
    side = BridgeSide(session, "spot_arm", model=system)
    observer = Observer(client_factory(), "spot_arm", system, feed=True)
    try:
        wait_until(lambda: observer.fetches >= 2, 10, "the observer's first look and its follow-up")
        wait_until(lambda: monitor._feed.heard, 10, "the observer's subscriber")
        side.send(*PAPER_STEPS[0][:2])
        wait_until(lambda: observer.read(lambda b: b.unsafe is not None and b.unsafe.seq == 1), 10, "step 1 fed")
        wait_until(lambda: observer._feed_at == (monitor.instance_id, monitor._feed.seq), 10, "the feed's last round")
        assert (observer.feed_gaps, observer.malformed) == (0, 0)
        asked = observer.fetches
        with monitor._feed._cond:
            monitor._feed.seq += 1  # a round lost on its way: the observer never saw it
        side.send(*PAPER_STEPS[1][:2])
        wait_until(lambda: observer.feed_gaps == 1 and observer.fetches > asked, 10, "the observer asking again")
        wait_until(lambda: observer.read(lambda b: b.unsafe.seq) == 2, 10, "step 2")
        side.send(*PAPER_STEPS[2][:2])  # the next round follows the last: no gap from there
        wait_until(lambda: observer.read(lambda b: b.unsafe.seq) == 3, 10, "step 3 fed")
        assert (observer.feed_gaps, observer.malformed) == (1, 0)
        # Bad rounds are counted and dropped: not msgpack, another system's (its seq no gap of this one's).
        bad = client_factory().declare_publisher(keys.feed("spot_arm"))
        wait_until(lambda: bad.matching_status.matching, 10, "the observer's subscriber, from the test")
        bad.put(b"\xc1")
        bad.put(encode(ResultFeed(system="other", monitor=monitor.instance_id, seq=1000, round=FEED_ROUND)))
        wait_until(lambda: observer.malformed == 2, 10, "two bad rounds counted")
        assert observer.feed_gaps == 1 and observer.read(lambda b: b.unsafe.seq) == 3
    finally:
        observer.close()
        side.close()
        monitor.close()
