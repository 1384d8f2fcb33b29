"""Missed outcomes and the bridge's anti-entropy (docs/how-it-works.md, *Missed outcomes*; docs/operator.md).

The monitor's step lists a skill the bridge found ended without its response, with the model's
inference; the bridge polls every manager, loses a silent one with why, and names the skills a
manager that comes back no longer runs."""

from __future__ import annotations

import threading
import time

import zenoh

from event_watch import Events
from services.bridge_ros2 import start_bridge
from services.monitor.engine import Engine
from services.simulator import Simulator
from skinet.mission.scenario import parse_scenario
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent, Heartbeat, LiveState, MissedOutcome, SkillsetStatus
from tests.services.test_bridge import CHAIN, SOURCE
from tests.services.test_sequences import SYSTEM

GAP = "the link to /spot/spot_skillset_manager was down 12.4 s"


def spot(seq: int, transition: str | None, resources: dict[str, str], running: list[str],
         missed: list[str] = ()) -> CanonicalEvent:
    return CanonicalEvent(system="spot_arm", skillset="spot", seq=seq, stamp=0.0, source=SOURCE, epoch=7,
                          transition=transition, status=SkillsetStatus(resources=resources, running=running),
                          missed=[MissedOutcome(skillset="spot", skill=k, gap=GAP) for k in missed])


def live(engine: Engine, *events: CanonicalEvent) -> LiveState | None:
    step = None
    for e in events:
        applied, _, _ = engine.check_seq(e)
        assert applied
        step = engine.apply(e)
    return None if step is None else decode(step.live, LiveState)


OFF_BUSY = {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Busy"}
ON_IDLE = {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Idle"}


def test_a_missed_init_power_is_inferred_success() -> None:
    engine = Engine(SYSTEM)
    state = live(engine, spot(0, "init_power.start", OFF_BUSY, ["init_power"]),
                 spot(1, None, ON_IDLE, [], missed=["init_power"]))
    assert state is not None and state.event == "spot:status#1" and state.divergence is None
    assert state.missed == [MissedOutcome(skillset="spot", skill="init_power", gap=GAP,
                                          outcome="init_power.success.powered_on",
                                          candidates=["init_power.success.powered_on"])]
    assert state.skillsets["spot"].resources == ON_IDLE and state.skillsets["spot"].running == []
    assert decode(engine.republish().live, LiveState).missed == state.missed  # a republished step keeps it
    nothing = live(engine, spot(2, "stand_up.start", {**ON_IDLE, "control_mode": "Busy"}, ["stand_up"]))
    assert nothing is not None and nothing.missed == []  # the next step lists none


def test_a_missed_teleop_stays_unknown_with_both_candidates() -> None:
    engine = Engine(SYSTEM)
    standing = {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"}
    state = live(engine, spot(0, None, standing, []), spot(1, "teleop.start", {**standing, "control_mode": "Busy"},
                                                        ["teleop"]),
                 spot(2, None, standing, [], missed=["teleop"]))
    assert state is not None and state.missed == [MissedOutcome(
        skillset="spot", skill="teleop", gap=GAP, outcome=None,
        candidates=["teleop.success.done", "teleop.failure.link_lost"])]


class Beats:
    """The bridge's heartbeats as they come."""

    def __init__(self, session: zenoh.Session, source: str):
        self.items: list[Heartbeat] = []
        self._cv = threading.Condition()
        self._sub = session.declare_subscriber(keys.heartbeat("spot_arm", source), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        with self._cv:
            self.items.append(decode(sample.payload.to_bytes(), Heartbeat))
            self._cv.notify_all()

    def wait(self, ready, what: str, timeout: float = 30.0) -> Heartbeat:
        with self._cv:
            if not self._cv.wait_for(lambda: any(ready(b) for b in self.items), timeout):
                raise AssertionError(f"no heartbeat {what} within {timeout} s: last {self.items[-1:]}")
            return next(b for b in self.items if ready(b))


def test_a_silent_manager_is_lost_with_why_and_its_successor_is_a_restart_with_missed_skills(client_factory,
                                                                                           spot_arm):
    """The plain layout announces nothing: the bridge's polls alone find the managers' process gone (no answer
    to 3 requests) and a fresh one (skill ids reset), whose status names stand_up as a missed outcome."""
    system, typemap = spot_arm
    events = Events(client_factory(), system.name)
    beats = Beats(client_factory(), SOURCE)
    sim = Simulator(client_factory(), system, typemap)
    bridge = start_bridge(client_factory(), system, typemap, source=SOURCE, poll=0.2)
    fresh = None
    try:
        events.wait(lambda items: len(items) == 2)
        steps = parse_scenario(CHAIN, "chain.toml")
        sim.drive(steps.__class__(steps.name, steps.system, steps.steps[:3]), speed=0)
        events.wait(lambda items: len(items) == 5)  # spot: init_power.start, .success, stand_up.start
        assert not sim.nodes["spot"].tokens  # the plain simulator announces nothing
        time.sleep(0.5)
        sent, answered = bridge.polls["spot"]
        assert sent >= 3 and answered >= sent - 1  # a poll may be on its way
        sim.close()
        why = "manager /spot/spot_skillset_manager answered none of the last 3 status requests (0.2 s apart)"
        beat = beats.wait(lambda b: b.skillsets["spot"].manager is False, "with spot's manager gone")
        assert beat.pending["spot"] == why
        assert len(events.items) == 5  # silence is no event
        fresh = Simulator(client_factory(), system, typemap)  # a new process: PowerOff, Sitting, no ids
        got = events.wait(lambda items: any(e.skillset == "spot" and e.seq == 4 for e in items))
        last = next(e for e in got if e.skillset == "spot" and e.seq == 4)
        assert last.restart and last.transition is None
        assert last.status.resources == {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"}
        assert last.info == "manager restarted (skill ids reset: init_power, stand_up); state now differs: " \
                            "power_status PowerOn -> PowerOff, control_mode Busy -> Idle, stand_up no longer running"
        assert last.missed == [MissedOutcome(
            skillset="spot", skill="stand_up",
            gap="manager /spot/spot_skillset_manager restarted (skill ids reset: init_power, stand_up)")]
        beats.items.clear()
        beat = beats.wait(lambda b: "spot" not in b.pending and b.skillsets["spot"].manager is None,
                          "with spot's manager answering")
        manip = events.wait(lambda items: sum(e.skillset == "manipulator" for e in items) == 2)
        assert [e.info for e in manip if e.skillset == "manipulator"][1].startswith(
            "resync after the link to /kinova/manipulator_skillset_manager was down ")
    finally:
        bridge.close()
        sim.close()
        if fresh is not None:
            fresh.close()


def test_missed_outcome_lines_say_the_inference_or_why_there_is_none() -> None:
    from skinet.wire.convert import missed_line
    known = MissedOutcome(skillset="spot", skill="init_power", gap=GAP, outcome="init_power.success.powered_on",
                          candidates=["init_power.success.powered_on"])
    unknown = MissedOutcome(skillset="spot", skill="teleop", gap=GAP,
                            candidates=["teleop.success.done", "teleop.failure.link_lost"])
    assert missed_line(known) == f"missed outcome: spot:init_power ended without its response ({GAP}): " \
                                 "init_power.success.powered_on inferred from the resources"
    assert missed_line(unknown) == f"missed outcome: spot:teleop ended without its response ({GAP}): outcome " \
                                   "unknown, the model cannot tell teleop.success.done from teleop.failure.link_lost"
    assert missed_line(MissedOutcome(skillset="spot", skill="teleop", gap=GAP)).endswith(
        "outcome unknown, no mode of the model explains the status")


def test_a_resync_answer_says_which_events_were_not_checked() -> None:
    """Issue 30: the robot's first events before the monitor synced became one silent resync step."""
    engine = Engine(SYSTEM)
    answer = spot(5, None, ON_IDLE, [])
    step = engine.adopt(answer)
    assert step is not None and step.unchecked == f"events #1-#5 of '{SOURCE}' not checked"
    state = decode(step.live, LiveState)
    assert state.event == f"spot:resync#5 (events #1-#5 of '{SOURCE}' not checked)"
    again = engine.adopt(spot(6, None, ON_IDLE, []))  # the same run: only #6 was not seen
    assert again is not None and decode(again.live, LiveState).event == \
        f"spot:resync#6 (event #6 of '{SOURCE}' not checked)"
    assert engine.adopt(spot(6, None, ON_IDLE, [])) is None  # nothing new, nothing moved: no step
    fresh = Engine(SYSTEM)
    assert fresh.adopt(spot(0, None, {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"},
                            [])) is None  # the bridge's first status covers nothing


def test_a_silent_rmw_zenoh_manager_is_gone_while_its_token_stays(client_factory, spot_arm):
    """rmw_zenoh: a frozen managers' process keeps its liveliness tokens for the lease; its silence tells."""
    from skinet.ros.keys import KeyStyle

    system, typemap = spot_arm
    style = KeyStyle(rmw_zenoh=True, domain=9)
    beats = Beats(client_factory(), SOURCE)
    sim = Simulator(client_factory(), system, typemap, style=style)
    bridge = start_bridge(client_factory(), system, typemap, source=SOURCE, style=style, poll=0.2)
    try:
        beats.wait(lambda b: b.skillsets["spot"].manager is True and not b.pending, "with spot's manager there")
        for node in sim.nodes.values():  # deaf, its tokens kept: as a frozen process looks until its lease ends
            node.manager.status_request = lambda: []
        beat = beats.wait(lambda b: b.skillsets["spot"].manager is False, "with spot's manager silent")
        assert beat.pending["spot"] == \
            "manager /spot/spot_skillset_manager answered none of the last 3 status requests (0.2 s apart)"
    finally:
        bridge.close()
        sim.close()
