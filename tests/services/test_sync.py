"""The monitor's sync states without I/O (docs/semantics.md §7, :mod:`services.monitor.sync`): a clock is
stepped by hand, heartbeats, tokens, events and resync answers are fed in order."""

from __future__ import annotations

import time

from services.monitor.engine import Engine
from services.monitor.sync import STARTED, SyncTracker
from skinet.wire.messages import CanonicalEvent, Heartbeat, HeartbeatSkillset, SkillsetStatus
from tests.services.test_sequences import SYSTEM

B1, TOKEN = "bridge_ros2/b1", "skinet/spot_arm/alive/bridge_ros2/b1"
ON = {"resources": {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Idle"}}


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def tracker(clock: Clock, **options: object) -> SyncTracker:
    return SyncTracker(["spot", "manipulator"], system="spot_arm", clock=clock, wall=lambda: 1000 + clock.t,
                       **options)  # type: ignore[arg-type]


def beat(manager: bool | None = True, epoch: int = 7, spot: int | None = 3) -> Heartbeat:
    return Heartbeat(system="spot_arm", source=B1, epoch=epoch, period=0.5, token=TOKEN,
                     skillsets={"spot": HeartbeatSkillset(seq=spot, manager=manager),
                                "manipulator": HeartbeatSkillset(seq=0, manager=manager)})


def event(seq: int, epoch: int = 7, status: dict | None = None) -> CanonicalEvent:
    return CanonicalEvent(system="spot_arm", skillset="spot", seq=seq, stamp=0.0, source=B1, epoch=epoch,
                          status=None if status is None else SkillsetStatus(**status))


def states(t: SyncTracker) -> dict[str, tuple[str, str]]:
    return {n: (s.state, s.reason) for n, s in t.message().items()}


def test_nothing_is_live_until_its_resync_answers_and_events_wait() -> None:
    clock = Clock()
    t = tracker(clock)
    assert states(t) == {"spot": ("syncing", STARTED), "manipulator": ("syncing", STARTED)}
    since = time.strftime("%H:%M:%S", time.localtime(1100.0))
    assert t.stale() == (f"spot syncing since {since}: {STARTED}; manipulator syncing since {since}: {STARTED}",
                         1100.0)
    assert t.hold(event(1)) and t.hold(event(2))  # they wait
    assert t.asking("spot") and not t.asking("spot")  # one query in flight
    t.answered("spot", replied=False)
    assert states(t)["spot"] == ("syncing", "no bridge answered the resync query")
    assert t.tick() == ["manipulator"]  # never asked; spot: the next query after ``retry``
    assert t.asking("manipulator")
    t.answered("manipulator", replied=False)
    assert t.tick() == []
    clock.t += 1.0
    assert t.tick() == ["spot", "manipulator"]
    t.heartbeat(beat(spot=None))
    t.asking("spot")
    t.answered("spot", replied=False)
    assert states(t)["spot"] == ("syncing", "'bridge_ros2/b1' has no status of spot yet (its manager has not answered)")
    assert [e.seq for e in t.synced("spot", B1, 7)] == [1, 2] and t.live("spot") and not t.all_live()
    assert not t.hold(event(3))  # live: applied at once
    t.synced("manipulator", B1, 7)
    assert t.all_live() and t.stale() is None


def test_silence_past_the_bound_loses_then_a_heartbeat_resyncs() -> None:
    clock = Clock()
    t = tracker(clock, bound=2.0)
    t.synced("spot", B1, 7)
    t.synced("manipulator", B1, 7)
    clock.t += 1.5
    t.heartbeat(beat())
    clock.t += 2.0
    t.tick()
    assert t.live("spot")  # 2.0 s since the heartbeat: not past the bound
    clock.t += 0.1
    t.tick()
    assert states(t)["spot"] == ("lost", "nothing heard from 'bridge_ros2/b1' for 2 s (no heartbeat, no event)")
    assert t.message()["spot"].since == 1000 + clock.t
    version = t.version
    t.tick()
    assert t.version == version  # nothing new: nothing published again
    t.heartbeat(beat())
    assert states(t)["spot"] == ("syncing", "'bridge_ros2/b1' is heard again: waiting for its resync answer")
    t.synced("spot", B1, 7)
    assert t.live("spot")


def test_a_token_gone_loses_at_once_even_before_any_heartbeat() -> None:
    """The bridge's token follows its source name (``bridge_ros2/<id>``); its heartbeat, up to 0.5 s
    later, may name another."""
    t = tracker(Clock())
    t.synced("spot", B1, 7)
    t.token("skinet/spot_arm/alive/monitor/m1", False)  # another service's token: nothing happens
    assert t.live("spot")
    t.token(TOKEN, False)
    assert states(t)["spot"] == ("lost", "the liveliness token of 'bridge_ros2/b1' is gone (it stopped, or its link did)")
    t.token(TOKEN, True)
    assert states(t)["spot"][0] == "syncing"
    t.token(TOKEN, False)
    assert t.synced("spot", B1, 7) == [] and states(t)["spot"][0] == "lost"  # an answer from before it went


def test_a_manager_that_left_loses_its_skillset_and_a_restarted_bridge_resyncs() -> None:
    t = tracker(Clock())
    t.synced("spot", B1, 7)
    t.synced("manipulator", B1, 7)
    t.heartbeat(beat(manager=None))  # a gateway that announces no managers: nothing known, nothing lost
    assert t.all_live()
    t.heartbeat(beat(manager=False))
    assert states(t)["spot"] == ("lost", "its manager left (said 'bridge_ros2/b1')")
    t.heartbeat(beat(manager=True))
    assert states(t)["spot"][0] == "syncing"
    t.synced("spot", B1, 7)
    t.synced("manipulator", B1, 7)
    t.heartbeat(beat(epoch=8))  # the same source, a new run
    assert states(t)["spot"] == ("syncing", "'bridge_ros2/b1' restarted (epoch 8): waiting for its resync answer")


def test_the_buffer_is_bounded_and_forged_sources_are_forgotten() -> None:
    t = tracker(Clock(), buffer=4)
    for seq in range(10):
        t.hold(event(seq))
    assert t.overflow == 6 and [e.seq for e in t.synced("spot", B1, 7)] == [6, 7, 8, 9]
    for n in range(1000):
        t.hold(CanonicalEvent(system="spot_arm", skillset="manipulator", seq=0, stamp=0.0, source=f"forged-{n}"))
    assert len(t.sources) == 64


def test_what_the_resync_answer_covers_is_history_whatever_the_stamps() -> None:
    """Engine side: the adopted answer at #5 makes events #0-#5 of its stream history, later ones live."""
    engine = Engine(SYSTEM)
    step = engine.adopt(event(5, status=ON))
    assert step is not None and step.live and engine.counters.resyncs == 1
    for seq in (0, 3, 5):  # the cache's replay, whatever order
        assert engine.check_seq(CanonicalEvent(**{**event(seq).model_dump(), "stamp": 4e9})) == (False, None, False)
    assert engine.counters.history == 3
    assert engine.check_seq(event(6)) == (True, None, False)
    assert engine.check_seq(event(6)) == (False, "duplicate event spot#6 from 'bridge_ros2/b1' ignored", False)
    assert engine.check_seq(event(4)) == (False, None, False) and engine.counters.history == 4
    assert engine.check_seq(event(0, epoch=8))[0]  # another run of the source: not covered
    step = engine.adopt(event(9, epoch=8, status=ON))  # the same marking, but #1-#9 were never checked here
    assert step is not None and not step.changed and step.unchecked == "events #1-#9 of 'bridge_ros2/b1' not checked"


RESTARTED = "its manager restarted (the manager (or its gateway) came back): waiting for its new status"
REFUSED = f"'bridge_ros2/b1' has no current status of spot: {RESTARTED}"


def test_a_status_the_source_says_is_outdated_is_not_vouched_for() -> None:
    """``Heartbeat.pending``: a live skillset is syncing at once, a syncing one says why, a lost one stays lost;
    its resync queries are refused with the same words until the source's next status comes."""
    clock = Clock()
    t = tracker(clock)
    t.synced("spot", B1, 7)
    t.synced("manipulator", B1, 7)
    pending = beat().model_copy(update={"pending": {"spot": RESTARTED}})
    t.heartbeat(pending, superseded=["spot"])  # sent before an event already applied: older news
    assert t.all_live()
    t.heartbeat(pending)
    assert states(t) == {"spot": ("syncing", REFUSED), "manipulator": ("live", "")}
    assert t.outdated("spot", B1) and not t.outdated("manipulator", B1)
    assert t.asking("spot")
    t.answered("spot", replied=False, refused=REFUSED)
    assert states(t)["spot"] == ("syncing", REFUSED)
    t.heartbeat(beat(spot=4))  # its new status came (#4)
    assert not t.outdated("spot", B1) and states(t)["spot"] == ("syncing", REFUSED)  # until its answer
    t.synced("spot", B1, 7)
    assert t.all_live()
    clock.t += 5.0
    t.tick()
    t.heartbeat(pending)  # lost: stays lost until heard, then says why it waits
    assert states(t)["spot"] == ("syncing", REFUSED)


def test_an_answer_ahead_of_the_events_is_live_once_they_come() -> None:
    """After an outage the bridge's cache gives back the events the answer covers, up to 2 s later: until
    they are applied the marking is behind the answer, and the skillset is not live."""
    t = tracker(Clock())
    t.synced("spot", B1, 7)
    t.heartbeat(beat(manager=False))
    t.heartbeat(beat())
    assert t.hold(event(4))  # another event of the same run waits for the answer
    assert [e.seq for e in t.synced("spot", B1, 7, upto=6)] == [4]
    assert states(t)["spot"] == ("syncing", "catching up: events up to #6 from 'bridge_ros2/b1' are on their way")
    assert not t.hold(event(5))  # what it waits for is applied at once
    assert t.tick() == ["manipulator"]  # nothing to ask: the answer is known
    t.caught_up("spot", B1, 8, 6)  # another run: not what it waits for
    t.caught_up("spot", B1, 7, 5)
    assert states(t)["spot"][0] == "syncing"
    t.caught_up("spot", B1, 7, 6)
    assert t.live("spot")
    t.heartbeat(beat(manager=False))
    t.heartbeat(beat())
    t.synced("spot", B1, 7, upto=9)
    t.caught_up("spot", B1, 7)  # the bound passed: the answer was adopted
    assert t.live("spot")


def test_a_divergence_names_the_message_that_showed_it() -> None:
    """The live nets' reason, with the event's info (a manager's: its response, or why the bridge says the
    state changed); a bridge's own finding (a binding's drift) first, even when the marking does not move."""
    engine = Engine(SYSTEM)
    restarted = CanonicalEvent(system="spot_arm", skillset="manipulator", seq=0, stamp=0.0, source=B1, epoch=7,
                               status=SkillsetStatus(resources={"mutex": "Free", "arm_status": "Away"}),
                               info="manager restarted (new status publisher); state now differs: arm_status HP -> Away")
    step = engine.apply(restarted)
    assert step is not None and step.divergence == (
        "no transition explains the observed status of 'manipulator'; observed marking adopted (message: manager "
        "restarted (new status publisher); state now differs: arm_status HP -> Away)")
    drift = restarted.model_copy(update={"seq": 1, "info": "model divergence: x", "divergence": "/arm: x, but y"})
    step = engine.apply(drift)  # the status matches the marking: a step all the same
    assert step is not None and step.divergence == "/arm: x, but y" and engine.counters.divergences == 2
    assert engine.apply(drift.model_copy(update={"seq": 2, "info": "", "divergence": ""})) is None


def test_a_silent_manager_loses_its_skillset_with_the_bridges_words() -> None:
    """The bridge's polls found the manager silent: lost, saying what was asked and who did not answer."""
    t = tracker(Clock())
    t.synced("spot", B1, 7)
    t.synced("manipulator", B1, 7)
    why = "manager /spot/spot_skillset_manager answered none of the last 3 status requests (1 s apart)"
    t.heartbeat(Heartbeat(system="spot_arm", source=B1, epoch=7, period=0.5, token=TOKEN,
                          skillsets={"spot": HeartbeatSkillset(seq=3, manager=False),
                                     "manipulator": HeartbeatSkillset(seq=0, manager=None)},
                          pending={"spot": why}))
    assert states(t) == {"spot": ("lost", f"'bridge_ros2/b1' has no current status of spot: {why}"),
                         "manipulator": ("live", "")}
    t.heartbeat(beat(manager=None))  # it answers again: syncing until the status that closes the gap
    assert states(t)["spot"] == ("syncing", "'bridge_ros2/b1' is heard again: waiting for its resync answer")


def test_a_zenoh_error_is_never_the_whole_reason() -> None:
    """Issue 30: "spot syncing since …: Timeout" said neither what was asked nor of whom."""
    clock = Clock()
    t = tracker(clock)
    t.heartbeat(beat(spot=3))
    key = "skinet/spot_arm/resync/spot"
    t.asking("spot")
    t.answered("spot", replied=False, failed="Timeout", key=key, timeout=2.0)
    assert states(t)["spot"] == ("syncing", "the resync query to 'bridge_ros2/b1' on skinet/spot_arm/resync/spot "
                                            "got no answer within 2 s (Timeout)")
    since = time.strftime("%H:%M:%S", time.localtime(1100.0))
    assert t.stale()[0].startswith(f"spot syncing since {since}: the resync query to 'bridge_ros2/b1' on {key} got "
                                   "no answer within 2 s (Timeout); ")
    t.asking("spot")
    t.answered("spot", replied=False, failed="routing failed", key=key, timeout=2.0)
    assert states(t)["spot"] == ("syncing", f"the resync query to 'bridge_ros2/b1' on {key} failed: routing failed")
    t.asking("spot")
    t.answered("spot", replied=False, key=key, timeout=2.0)  # heard, but no reply at all
    assert states(t)["spot"] == ("syncing", f"the resync query to 'bridge_ros2/b1' on {key} got no answer within 2 s")
