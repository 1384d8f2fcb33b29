"""Status diffs to model-level transitions (skinet.ros.derive; docs/semantics.md §1 bridge_ros2, corpus README).

Every test checks the derived events against the live nets too: feeding them to
:class:`~skinet.system.live.LiveSystem` must reproduce the manager's status without a
divergence, unless the test is about a change the model cannot name.
"""

from __future__ import annotations

import pytest

from skinet.lang.parser import parse_skillset
from skinet.system.live import LiveSystem
from skinet.ros.derive import (
    Derived, Deriver, EventRequest, EventResponse, SkillResponse, SkillView, Status, event_response_from_plain,
    skill_response_from_plain, status_from_plain, termination,
)
from skinet.ros.interfaces import EVENT_RESULTS, RESULTS
from skinet.system.model import System, build_system

R, E = RESULTS, EVENT_RESULTS

LAB = """
skillset lab {
    resource {
        power { state { On Off } initial On transition all }
        mode { state { Idle Busy } initial Idle transition all }
        arm { state { Home Away Moving } initial Home transition { Home -> Moving Moving -> Away Away -> Home } }
    }
    event {
        cut { guard power == On effect power -> Off }
        trip { guard power == On effect power -> Off }
        restore { guard power == Off effect power -> On }
        jam { effect arm -> Moving }
    }
    skill work {
        precondition { on: power == On  idle: mode == Idle }
        start { mode -> Busy }
        invariant { powered { guard power == On effect { mode -> Idle arm -> Away } } }
        interrupt { effect mode -> Idle }
        success done { effect mode -> Idle }
        failure broke { effect mode -> Idle }
    }
    skill reach {
        start { arm -> Moving }
        invariant { powered { guard power == On } }
        success there { effect arm -> Away }
    }
}
"""

SPOT_INITIAL = {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"}
SPOT_READY = {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"}
SPOT_BUSY = {**SPOT_READY, "control_mode": "Busy"}
SPOT_OFF = {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"}
INFO = "/spot/spot_skillset_manager"


class Harness:
    """A deriver plus the live nets it should keep in step with."""

    def __init__(self, system: System, skillset: str):
        self.comp = system.component(skillset)
        self.deriver = Deriver(self.comp.skillset, self.comp.net)
        self.live = LiveSystem(system)
        self.skillset = skillset
        self.notes: list[str] = []

    def status(self, resources: dict[str, str], running: dict[str, str] | None = None,
               ids: dict[str, str] | None = None, interrupting: tuple[str, ...] = (), stamp: float = 1.0) -> list[Derived]:
        """Feed a status; ``running`` maps running skills to their ids, ``ids`` gives READY skills' ids."""
        running, ids = running or {}, ids or {}
        skills = {}
        for k in self.comp.skillset.skills:
            if k.name in running:
                skills[k.name] = SkillView(2 if k.name in interrupting else 1, running[k.name])
            else:
                skills[k.name] = SkillView(0, ids.get(k.name, ""))
        out = self.deriver.on_status(Status(resources, skills, INFO if self.skillset == "spot" else "lab", stamp))
        self.notes += out.notes
        return out.events

    def feed(self, msg) -> list[Derived]:
        if isinstance(msg, SkillResponse):
            out = self.deriver.on_skill_response(msg)
        elif isinstance(msg, EventResponse):
            out = self.deriver.on_event_response(msg)
        else:
            out = self.deriver.on_event_request(msg)
        self.notes += out.notes
        return out.events

    def apply(self, events: list[Derived]) -> list[str | None]:
        """Apply to the live nets; fails on a divergence."""
        for ev in events:
            outcome = self.live.apply(self.skillset, ev.transition, None if ev.status is None else ev.status.model_dump())
            assert outcome.divergence is None, (ev, outcome)
        return [ev.transition for ev in events]


def response(skill: str, id_: str, result: str, name: str = "", effect: bool = True, **pre: bool) -> SkillResponse:
    return SkillResponse(skill, id_, R[result], name, effect, True, pre)


@pytest.fixture
def spot(paper_system: System) -> Harness:
    h = Harness(paper_system, "spot")
    h.status(SPOT_INITIAL)
    return h


@pytest.fixture
def spot_ready(spot: Harness) -> Harness:
    """Spot powered and standing, as the live nets also know it."""
    spot.live.apply("spot", None, {"resources": SPOT_READY, "running": []})
    spot.status(SPOT_READY)
    return spot


@pytest.fixture
def lab() -> Harness:
    system = build_system("lab", [(parse_skillset(LAB, "lab.rl"), "/lab/lab_skillset_manager")], "")
    h = Harness(system, "lab")
    h.status({"power": "On", "mode": "Idle", "arm": "Home"})
    return h


def test_first_status_is_published_without_a_transition(paper_system: System):
    h = Harness(paper_system, "spot")
    [ev] = h.status(SPOT_READY, stamp=7.5)
    assert (ev.transition, ev.info, ev.stamp) == (None, "initial status", 7.5)
    assert ev.status.resources == SPOT_READY and ev.status.running == []


def test_start_then_success(spot_ready: Harness):
    h = spot_ready
    assert h.apply(h.status(SPOT_BUSY, {"teleop": "t1"})) == ["teleop.start"]
    assert h.feed(response("teleop", "t1", "SUCCESS", "done")) == []
    [ev] = h.status(SPOT_READY, ids={"teleop": "t1"})
    assert h.apply([ev]) == ["teleop.success.done"]
    assert ev.status.running == []


def test_failure_and_unnamed_modes_are_named_from_the_response():
    assert termination(response("teleop", "t", "FAILURE", "link_lost")) == "teleop.failure.link_lost"
    assert termination(response("k", "t", "SUCCESS")) == "k.success"
    assert termination(response("k", "t", "FAILURE")) == "k.failure"
    assert termination(response("k", "t", "INTERRUPT")) == "k.interrupt"
    assert termination(response("k", "t", "INVARIANT_FAILURE", "upright")) == "k.inv.upright"


def test_duplicate_status_gives_nothing(spot_ready: Harness):
    h = spot_ready
    h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
    assert h.status(SPOT_BUSY, {"teleop": "t1"}, stamp=2.0) == []  # status_request answer


def test_already_running_quirk_changes_nothing(spot_ready: Harness):
    h = spot_ready
    h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
    # The manager answers with the id of the execution already running, then its status.
    assert h.feed(response("teleop", "t1", "ALREADY_RUNNING", standing=True, free=True, powered=True)) == []
    assert h.status(SPOT_BUSY, {"teleop": "t1"}) == []
    assert any("ALREADY_RUNNING" in n and "'t1'" in n for n in h.notes)
    # The response did not stay pending: the real termination is still named.
    h.feed(response("teleop", "t1", "SUCCESS", "done"))
    assert h.apply(h.status(SPOT_READY, ids={"teleop": "t1"})) == ["teleop.success.done"]


@pytest.mark.parametrize("result", ["PRECONDITION_FAILURE", "START_FAILURE", "VALIDATE_FAILURE"])
def test_rejected_start_publishes_nothing(spot: Harness, result: str):
    h = spot
    assert h.feed(response("teleop", "t9", result, effect=False, standing=False, free=True, powered=False)) == []
    # The manager keeps the rejected id in the status of the READY skill.
    assert h.status(SPOT_INITIAL, ids={"teleop": "t9"}) == []
    assert any(result in n and "'t9'" in n for n in h.notes)
    if result == "PRECONDITION_FAILURE":
        assert any("(standing, powered)" in n for n in h.notes)


def test_event_by_request_id(spot_ready: Harness):
    h = spot_ready
    h.feed(EventRequest("e1", "power_switchoff"))
    h.feed(EventResponse("e1", E["SUCCESS"]))
    assert h.apply(h.status(SPOT_OFF)) == ["power_switchoff"]


def test_duplicated_messages_are_ignored(spot_ready: Harness):
    h = spot_ready
    h.feed(EventRequest("e1", "power_switchoff"))
    h.feed(EventResponse("e1", E["SUCCESS"]))
    h.feed(EventResponse("e1", E["SUCCESS"]))
    assert h.apply(h.status(SPOT_OFF)) == ["power_switchoff"]
    assert h.status(SPOT_OFF) == []
    h.apply(h.status(SPOT_OFF | {"control_mode": "Busy"}, {"init_power": "i1"}))
    h.feed(response("init_power", "i1", "FAILURE", "no_battery"))
    [ev] = h.status(SPOT_OFF, ids={"init_power": "i1"})
    assert h.feed(response("init_power", "i1", "FAILURE", "no_battery")) == []
    assert h.apply([ev]) == ["init_power.failure.no_battery"] and h.status(SPOT_OFF, ids={"init_power": "i1"}) == []


def test_refused_event_publishes_nothing(spot: Harness):
    h = spot
    h.feed(EventRequest("e1", "power_switchoff"))
    assert h.feed(EventResponse("e1", E["GUARD_FAILURE"])) == []
    assert h.status(SPOT_INITIAL) == []
    assert any("power_switchoff" in n and "GUARD_FAILURE" in n for n in h.notes)


def test_internal_event_is_named_from_the_model(spot_ready: Harness):
    """id == status info: raised by the implementation; spot has one event that explains it."""
    h = spot_ready
    h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
    # Invariant cascade: both of teleop's invariants fail; the response names the last one.
    h.feed(response("teleop", "t1", "INVARIANT_FAILURE", "upright"))
    h.feed(EventResponse(INFO, E["SUCCESS"]))
    [ev] = h.status(SPOT_OFF, ids={"teleop": "t1"})
    assert h.apply([ev]) == ["power_switchoff"]
    assert "teleop.inv.upright" in ev.info


def test_internal_event_with_ambiguous_name_is_left_to_the_monitor(lab: Harness):
    h = lab
    h.feed(EventResponse("lab", E["SUCCESS"]))  # cut or trip: same guard, same effect
    [ev] = h.status({"power": "Off", "mode": "Idle", "arm": "Home"})
    assert ev.transition is None and ev.status.resources["power"] == "Off"
    assert h.live.apply("lab", None, ev.status.model_dump()).divergence is None


def test_skill_stop_and_event_in_one_status(spot_ready: Harness):
    """Two changes in one status: the order the net accepts, whatever the arrival order."""
    for first_event in (True, False):
        h = Harness(spot_ready.live.system, "spot")
        h.live.apply("spot", None, {"resources": SPOT_READY, "running": []})
        h.status(SPOT_READY)
        h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
        msgs = [EventRequest("e1", "power_switchoff"), EventResponse("e1", E["SUCCESS"]),
                response("teleop", "t1", "SUCCESS", "done")]
        for m in msgs if first_event else msgs[2:] + msgs[:2]:
            h.feed(m)
        events = h.status(SPOT_OFF, ids={"teleop": "t1"})
        assert [e.status is None for e in events] == [True, False]
        # power_switchoff first would have stopped teleop by an invariant instead.
        assert h.apply(events) == ["teleop.success.done", "power_switchoff"]


def test_invariant_failure_applying_several_effects(lab: Harness):
    h = lab
    h.feed(EventRequest("e1", "jam"))
    h.feed(EventResponse("e1", E["SUCCESS"]))
    assert h.apply(h.status({"power": "On", "mode": "Idle", "arm": "Moving"})) == ["jam"]
    assert h.apply(h.status({"power": "On", "mode": "Busy", "arm": "Moving"}, {"work": "w1"})) == ["work.start"]
    # cut: work's invariant fails and applies both its effects (mode -> Idle, arm -> Away).
    h.feed(EventRequest("e2", "cut"))
    h.feed(response("work", "w1", "INVARIANT_FAILURE", "powered"))
    h.feed(EventResponse("e2", E["SUCCESS"]))
    [ev] = h.status({"power": "Off", "mode": "Idle", "arm": "Away"}, ids={"work": "w1"})
    assert h.apply([ev]) == ["cut"]
    assert ev.info == "invariant failures: work.inv.powered"


def test_invariant_cascade_over_two_skills(lab: Harness):
    h = lab
    h.apply(h.status({"power": "On", "mode": "Busy", "arm": "Home"}, {"work": "w1"}))
    h.apply(h.status({"power": "On", "mode": "Busy", "arm": "Moving"}, {"work": "w1", "reach": "r1"}))
    h.feed(EventRequest("e1", "trip"))
    for m in (response("work", "w1", "INVARIANT_FAILURE", "powered"),
              response("reach", "r1", "INVARIANT_FAILURE", "powered", effect=False),
              EventResponse("e1", E["SUCCESS"])):
        h.feed(m)
    [ev] = h.status({"power": "Off", "mode": "Idle", "arm": "Away"}, ids={"work": "w1", "reach": "r1"})
    assert h.apply([ev]) == ["trip"]
    assert ev.info == "invariant failures: work.inv.powered, reach.inv.powered"


def test_start_whose_own_invariant_fails_at_once(lab: Harness):
    """reach has no precondition: started unpowered, it stops at once (READY with the new id)."""
    h = lab
    h.feed(EventRequest("e1", "cut"))
    h.feed(EventResponse("e1", E["SUCCESS"]))
    h.apply(h.status({"power": "Off", "mode": "Idle", "arm": "Home"}))
    h.feed(response("reach", "r1", "INVARIANT_FAILURE", "powered", effect=False))
    [ev] = h.status({"power": "Off", "mode": "Idle", "arm": "Moving"}, ids={"reach": "r1"})
    assert h.apply([ev]) == ["reach.start"]
    assert "reach.inv.powered" in ev.info


def test_interrupting_then_interrupted(spot_ready: Harness):
    h = spot_ready
    h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
    assert h.status(SPOT_BUSY, {"teleop": "t1"}, interrupting=("teleop",)) == []  # INTERRUPTING is still i_k
    h.feed(response("teleop", "t1", "INTERRUPT"))
    assert h.apply(h.status(SPOT_READY, ids={"teleop": "t1"})) == ["teleop.interrupt"]


def test_restart_in_one_status(spot_ready: Harness):
    """A lost status: the skill ended and started again; stop first, then start."""
    h = spot_ready
    h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
    h.feed(response("teleop", "t1", "FAILURE", "link_lost"))
    events = h.status(SPOT_BUSY, {"teleop": "t2"})
    assert h.apply(events) == ["teleop.failure.link_lost", "teleop.start"]


def test_response_after_its_status(spot_ready: Harness):
    """Without the response the stop cannot be named; the late response is then dropped."""
    h = spot_ready
    h.apply(h.status(SPOT_BUSY, {"teleop": "t1"}))
    [ev] = h.status(SPOT_READY, ids={"teleop": "t1"})
    assert ev.transition is None and "teleop stopped without a response" in ev.info
    assert h.apply([ev]) == [None]  # the monitor finds a transition explaining it
    assert h.feed(response("teleop", "t1", "SUCCESS", "done")) == []
    assert any("after its status" in n for n in h.notes)
    assert h.apply(h.status(SPOT_BUSY, {"go_to_waypoint": "g1"})) == ["go_to_waypoint.start"]


def test_event_response_after_its_status(spot_ready: Harness):
    h = spot_ready
    h.feed(EventRequest("e1", "power_switchoff"))
    [ev] = h.status(SPOT_OFF)
    assert ev.transition is None
    h.apply([ev])
    assert h.feed(EventResponse("e1", E["SUCCESS"])) == []
    assert h.status(SPOT_OFF) == []  # not taken for a second event


def test_status_the_model_cannot_read(spot: Harness):
    [ev] = spot.status({**SPOT_INITIAL, "posture": "Flying"})
    assert ev.transition is None and ev.status.resources["posture"] == "Flying"
    assert "without a response or request" in spot.notes[-1]


def test_change_no_transition_explains(spot: Harness):
    """A named trigger the net refuses is still published with its name (the monitor reports it)."""
    h = spot
    [ev] = h.status(SPOT_BUSY, {"teleop": "t1"})  # teleop cannot start sitting and unpowered
    assert ev.transition == "teleop.start" and "model cannot order" in ev.info
    assert h.live.apply("spot", ev.transition, ev.status.model_dump()).divergence is not None


def test_views_from_decoded_messages(paper_system: System):
    ss = paper_system.component("spot").skillset
    skills = {f"skill_{k}": {"name": k, "id": "", "state": 0, "input": {}} for k in
              ("init_power", "safe_poweroff", "stand_up", "sit_down", "go_to_waypoint", "teleop")}
    skills["skill_teleop"] = {"name": "teleop", "id": "t1", "state": 2, "input": {}}
    msg = {"stamp": {"sec": 3, "nanosec": 250_000_000}, "info": INFO,
           "resources": [{"name": r, "state": s} for r, s in SPOT_BUSY.items()], **skills}
    st = status_from_plain(ss, msg)
    assert st.stamp == 3.25 and st.info == INFO and st.resources == SPOT_BUSY
    assert st.running() == ["teleop"] and st.skills["teleop"] == SkillView(2, "t1")
    r = skill_response_from_plain(ss, "teleop", {"id": "t1", "result": 2, "standing": False, "free": True,
                                                 "powered": True, "name": "", "effect": False, "postcondition": True})
    assert r.result == R["PRECONDITION_FAILURE"] and dict(r.preconditions) == {"standing": False, "free": True,
                                                                               "powered": True}
    assert event_response_from_plain({"id": "x", "response": 3}) == EventResponse("x", 3)
    with pytest.raises(KeyError):
        status_from_plain(ss, {"resources": []})
