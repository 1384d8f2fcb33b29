"""Canonical events from action statuses, lifecycle transitions and topics (docs/semantics.md §9; skinet.ros.bound).

The nav2 example (examples/nav2): every GoalStatus code, every lifecycle transition,
goal-id races, results naming modes, start-up readings, and the drift cases the
issue lists, each with the message that showed it.  Derived events are fed to
:class:`~skinet.system.live.LiveSystem`, as the monitor would: clean runs give no
divergence there, drifts give one.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.system.load import load_bindings, load_system
from skinet.system.live import LiveSystem
from skinet.ros.actions import SentGoal
from skinet.ros.bound import BoundDeriver, BoundOutput, Goal, goal_text, goals_from_plain

REPO = Path(__file__).resolve().parents[2]
A, B, C, D, E = (bytes(range(i, i + 16)) for i in range(5))
ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = 1, 2, 3, 4, 5, 6
NAV = "/navigate_to_pose/_action/status"


@pytest.fixture(scope="module")
def nav2():
    system, _ = load_system(REPO / "examples" / "nav2" / "nav2.toml")
    bindings, _ = load_bindings(system)
    return system, bindings["nav2"]


class Run:
    """A deriver and the live marking the monitor would follow from its events."""

    def __init__(self, nav2, synced: bool = True, results: bool = True):  # type: ignore[no-untyped-def]
        system, binding = nav2
        self.d = BoundDeriver(system.component("nav2"), binding, synced=synced, results=results)
        self.live = LiveSystem(system)
        self.divergences: list[str] = []
        self.t = 0.0

    def feed(self, out: BoundOutput) -> BoundOutput:
        for ev in out.events:
            got = self.live.apply("nav2", ev.transition, ev.status.model_dump() if ev.status else None)
            if got.divergence:
                self.divergences.append(got.divergence)
        return out

    def stamp(self) -> float:
        self.t += 1.0
        return self.t

    def status(self, skill: str, *goals: tuple[bytes, float, int]) -> BoundOutput:
        return self.feed(self.d.on_status(skill, [Goal(*g) for g in goals], self.stamp()))

    def lifecycle(self, start: int, goal: int) -> BoundOutput:
        return self.feed(self.d.on_transition_event("navigator", start, goal, self.stamp()))

    def battery(self, percentage: float, charging: bool = True) -> BoundOutput:
        return self.feed(self.d.on_topic("/battery_state", {"percentage": percentage,
                                                            "power_supply_status": 1 if charging else 2}, self.stamp()))

    def activate(self) -> None:
        for start, goal in ((1, 10), (10, 2), (2, 13), (13, 3)):
            self.lifecycle(start, goal)

    def undock(self) -> None:
        self.status("undock_robot", (C, 0.5, EXECUTING))
        self.status("undock_robot", (C, 0.5, SUCCEEDED))
        self.battery(0.9, charging=False)

    def result(self, skill: str, goal: bytes, result: dict | None) -> BoundOutput:
        return self.feed(self.d.on_result(skill, goal, result, self.stamp()))


def names(out: BoundOutput) -> list[str | None]:
    return [e.transition for e in out.events]


def test_every_goal_status_code(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)
    run.activate()
    run.undock()
    assert names(run.status("navigate", (A, 10.0, ACCEPTED))) == ["navigate.start"]
    assert names(run.status("navigate", (A, 10.0, EXECUTING))) == []  # ACCEPTED -> EXECUTING: nothing
    assert names(run.status("navigate", (A, 10.0, CANCELING))) == []  # CANCELING changes nothing
    assert names(run.status("navigate", (A, 10.0, CANCELED))) == ["navigate.interrupt"]
    assert names(run.status("navigate", (A, 10.0, CANCELED), (B, 11.0, EXECUTING))) == ["navigate.start"]  # first seen
    assert names(run.status("navigate", (B, 11.0, SUCCEEDED))) == ["navigate.success.arrived"]
    assert names(run.status("navigate", (C, 12.0, CANCELING))) == ["navigate.start"]  # first seen canceling
    out = run.status("navigate", (C, 12.0, ABORTED))  # failure modes depend on the result: it is asked for
    assert names(out) == [] and [(r.skill, r.goal) for r in out.results] == [("navigate", C)]
    out = run.result("navigate", C, {"error_code": 9003, "error_msg": "too slow"})
    assert names(out) == ["navigate.failure.timed_out"]
    assert out.events[0].info == f"{NAV}: goal {goal_text(C)} ABORTED (mode timed_out)"
    out = run.status("navigate", (A, 13.0, ACCEPTED))  # a goal id that ended: a status after its end is ignored
    assert names(out) == [] and out.bad == [("goal status after its end", f"{NAV}: goal {goal_text(A)} ACCEPTED "
                                                                          "after CANCELED: ignored")]
    run.status("navigate", (D, 14.0, ACCEPTED))
    out = run.status("navigate", (D, 14.0, ABORTED))
    assert names(run.result("navigate", D, {"error_code": 9000, "error_msg": ""})) == ["navigate.failure.failed"]
    bad = run.status("navigate", (E, 15.0, 0), (E, 16.0, 7))
    assert bad.bad == [
        ("unknown goal status", f"{NAV}: goal {goal_text(E)} has status 0, not an action_msgs/msg/GoalStatus code"),
        ("unknown goal status", f"{NAV}: goal {goal_text(E)} has status 7, not an action_msgs/msg/GoalStatus code")]
    assert run.divergences == [] and run.d.running() == []
    assert [(r.skill, r.goal) for r in out.results] == [("navigate", D)]


def test_every_lifecycle_transition(nav2) -> None:  # type: ignore[no-untyped-def]
    """Transition states (10-15) change nothing; each settled state is named by the model's event."""
    run = Run(nav2)
    steps = [((1, 10), []), ((10, 2), ["navigator_configured"]), ((2, 13), []), ((13, 3), ["navigator_activated"]),
             ((3, 14), []), ((14, 2), ["navigator_deactivated"]), ((2, 11), []), ((11, 1), ["navigator_cleaned_up"]),
             ((1, 10), []), ((10, 2), ["navigator_configured"]), ((2, 12), []), ((12, 4), ["navigator_shut_down"])]
    for (start, goal), expected in steps:
        assert names(run.lifecycle(start, goal)) == expected, (start, goal)
    assert run.divergences == [] and run.d.resource_states()["navigator"] == "Finalized"
    # get_state answers set it too; the same state again is nothing
    assert names(run.feed(run.d.on_lifecycle_state("navigator", 4, 99.0))) == []


def test_a_lifecycle_transition_the_model_forbids_is_drift(nav2) -> None:  # type: ignore[no-untyped-def]
    """Active -> errorprocessing -> unconfigured (an error in an active node): the model declares no
    Active -> Unconfigured move; reported with the message, then adopted (the monitor diverges too)."""
    run = Run(nav2)
    run.activate()
    assert names(run.lifecycle(3, 15)) == []
    out = run.lifecycle(15, 1)
    assert [str(d) for d in out.drifts] == [
        "/bt_navigator/transition_event: errorprocessing -> unconfigured (navigator Active -> Unconfigured): "
        "navigator became Unconfigured, but no event of the model takes navigator from Active to Unconfigured here"]
    assert names(out) == [None] and out.events[0].info.startswith("model divergence: /bt_navigator/transition_event")
    assert run.d.resource_states()["navigator"] == "Unconfigured"
    assert run.divergences == ["no transition explains the observed status of 'nav2'; observed marking adopted"]


def test_several_goals_in_one_status_array_are_taken_by_stamp(nav2) -> None:  # type: ignore[no-untyped-def]
    """The array lists the new goal first; its stamp is later: the old goal ends, then the new one starts."""
    run = Run(nav2)
    run.activate()
    run.undock()
    run.status("navigate", (A, 5.0, EXECUTING))
    out = run.status("navigate", (B, 9.0, ACCEPTED), (A, 5.0, SUCCEEDED))
    assert names(out) == ["navigate.success.arrived", "navigate.start"]
    assert [e.info for e in out.events] == [f"{NAV}: goal {goal_text(A)} SUCCEEDED (mode arrived)",
                                            f"{NAV}: goal {goal_text(B)} ACCEPTED"]
    assert run.divergences == []


def test_a_result_holds_later_observations_in_order(nav2) -> None:  # type: ignore[no-untyped-def]
    """While the result of an ABORTED goal is fetched, the lifecycle event that came after it waits;
    without a result in time (None), the binding's default mode is taken and said so."""
    run = Run(nav2)
    run.activate()
    run.undock()
    run.status("navigate", (A, 5.0, EXECUTING))
    held = run.status("navigate", (A, 5.0, ABORTED))
    assert names(held) == [] and len(held.results) == 1
    assert names(run.lifecycle(3, 14)) == [] and names(run.lifecycle(14, 2)) == []  # queued behind the result
    out = run.result("navigate", A, None)
    assert names(out) == ["navigate.failure.failed", "navigator_deactivated"]
    assert out.notes == [f"{NAV}: goal {goal_text(A)} ABORTED: result not received in time: mode 'failed' "
                         "(the binding's default)"]
    assert run.result("navigate", A, {"error_code": 9003}).notes == [
        f"nav2: result of goal {goal_text(A)} not waited for"]
    assert run.divergences == []


def test_replay_has_no_results_and_says_so(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2, results=False)
    run.activate()
    run.undock()
    run.status("navigate", (A, 5.0, EXECUTING))
    out = run.status("navigate", (A, 5.0, ABORTED))
    assert names(out) == ["navigate.failure.failed"] and out.results == []
    assert out.bad == [("result not recorded", f"{NAV}: goal {goal_text(A)} ABORTED: the result is not in the "
                                               "recording: mode from the binding's default")]


def test_goal_accepted_while_the_model_says_the_skill_cannot_start(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)  # navigator still Unconfigured
    out = run.status("navigate", (A, 1.0, ACCEPTED))
    assert [str(d) for d in out.drifts] == [
        f"{NAV}: goal {goal_text(A)} ACCEPTED: navigate started, but the model says navigate cannot start: "
        "precondition 'active' (navigator == Active) false (navigator is Unconfigured, motion is Still, dock is "
        "Docked, battery is Ok, charging is Charging)"]
    assert names(out) == ["navigate.start"] and run.d.running() == ["navigate"]  # the observed marking is adopted
    assert run.d.resource_states()["motion"] == "Moving"  # with the start's effects (a stable marking)
    assert run.divergences == ["'navigate.start' is not enabled in the live marking; observed marking adopted"]
    # the goal then ends normally: no further drift
    assert names(run.status("navigate", (A, 1.0, SUCCEEDED))) == ["navigate.success.arrived"]
    assert len(run.divergences) == 1


def test_a_second_concurrent_goal_is_drift(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)
    run.activate()
    run.undock()
    run.status("navigate", (A, 5.0, EXECUTING))
    out = run.status("navigate", (A, 5.0, EXECUTING), (B, 6.0, ACCEPTED))
    assert [str(d) for d in out.drifts] == [
        f"{NAV}: goal {goal_text(B)} ACCEPTED: a second goal of navigate, but navigate already runs goal "
        f"{goal_text(A)} (one goal at a time per skill)"]
    assert names(out) == []
    # the first ends: the second takes over, as a new start
    out = run.status("navigate", (A, 5.0, SUCCEEDED), (B, 6.0, EXECUTING))
    assert names(out) == ["navigate.success.arrived", "navigate.start"]
    assert names(run.status("navigate", (B, 6.0, SUCCEEDED))) == ["navigate.success.arrived"]
    assert run.divergences == []


def test_a_topic_value_matching_no_state_and_an_event_whose_guard_is_false(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)
    out = run.battery(float("nan"))  # percentage unknown (BatteryState uses NaN): neither < 0.2 nor >= 0.2
    assert [str(d) for d in out.drifts] == [
        "/battery_state: percentage=nan: battery observed, but no state of battery matches"]
    assert names(out) == []
    run.feed(run.d.on_topic("/emergency_stop", {"data": False}, 1.0))
    out = run.feed(run.d.on_topic("/emergency_stop", {"data": True}, 2.0))  # rising edge, but nothing moves
    assert [str(d) for d in out.drifts] == [
        "/emergency_stop: data=True (data): event emergency_stop, but the model says emergency_stop cannot happen "
        "now: its guard motion == Moving is false"]
    assert names(run.feed(run.d.on_topic("/emergency_stop", {"data": True}, 3.0))) == []  # no edge


def test_an_event_stops_a_skill_by_its_invariant_and_the_goal_ends_later(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)
    run.activate()
    run.undock()
    run.feed(run.d.on_topic("/emergency_stop", {"data": False}, 1.0))
    run.status("navigate", (A, 5.0, EXECUTING))
    out = run.feed(run.d.on_topic("/emergency_stop", {"data": True}, 6.0))
    assert names(out) == ["emergency_stop"] and out.events[0].status.running == []  # in_motion failed
    out = run.status("navigate", (A, 5.0, ABORTED))
    assert names(out) == [] and out.results == [] and out.notes == [
        f"{NAV}: goal {goal_text(A)} ABORTED: the model had already stopped navigate (an invariant failed)"]
    assert names(run.status("navigate", (B, 7.0, ACCEPTED))) == ["navigate.start"]
    assert run.divergences == []


def test_a_goal_never_seen_accepted_and_a_vanished_goal(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)
    run.activate()
    run.undock()
    out = run.status("navigate", (A, 5.0, SUCCEEDED))
    assert out.bad == [("goal never accepted", f"{NAV}: goal {goal_text(A)} SUCCEEDED without having been seen "
                                               "accepted: no transition derived (its start was not seen)")]
    run.status("navigate", (B, 6.0, EXECUTING))
    out = run.status("navigate")  # the server restarted: an empty array
    assert [str(d) for d in out.drifts] == [
        f"{NAV}: goal {goal_text(B)} absent: navigate no longer runs it, but no outcome of it was seen (did the "
        "action server restart?)"]
    assert run.d.running() == []


def test_start_up_reads_every_interface_before_the_initial_status(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2, synced=False)
    assert run.d.missing() == ["the status of /navigate_to_pose", "the status of /dock_robot",
                               "the status of /undock_robot", "the state of /bt_navigator",
                               "a first /battery_state message"]
    assert names(run.status("navigate", (A, 1.0, SUCCEEDED), (B, 2.0, EXECUTING))) == []  # transient local history
    assert names(run.feed(run.d.no_status("dock_robot", 3.0))) == []
    assert names(run.feed(run.d.no_status("undock_robot", 3.0))) == []
    assert names(run.lifecycle(2, 13)) == [] and run.d.missing() == ["the state of /bt_navigator",
                                                                     "a first /battery_state message"]
    assert names(run.feed(run.d.on_lifecycle_state("navigator", 3, 4.0))) == []  # get_state
    out = run.battery(0.1, charging=False)
    assert names(out) == [None] and out.events[0].info == "initial status"
    assert out.events[0].status.model_dump() == {
        "resources": {"navigator": "Active", "motion": "Still", "dock": "Docked", "battery": "Low",
                      "charging": "NotCharging"}, "running": ["navigate"]}
    # history goals are known: A's end is no event; B's is
    assert names(run.status("navigate", (A, 1.0, SUCCEEDED), (B, 2.0, SUCCEEDED))) == ["navigate.success.arrived"]


def test_a_clean_nav2_run_raises_no_drift(nav2) -> None:  # type: ignore[no-untyped-def]
    run = Run(nav2)
    run.activate()
    outputs = [run.status("undock_robot", (A, 1.0, ACCEPTED)), run.status("undock_robot", (A, 1.0, EXECUTING)),
               run.status("undock_robot", (A, 1.0, SUCCEEDED)), run.battery(0.8, charging=False),
               run.status("navigate", (B, 2.0, ACCEPTED)), run.status("navigate", (B, 2.0, SUCCEEDED)),
               run.battery(0.15, charging=False), run.status("dock_robot", (C, 3.0, EXECUTING)),
               run.status("dock_robot", (C, 3.0, SUCCEEDED)), run.battery(0.15, charging=True),
               run.battery(0.5, charging=True)]
    assert [n for out in outputs for n in names(out)] == [
        "undock_robot.start", "undock_robot.success.undocked", "charging_stopped", "navigate.start",
        "navigate.success.arrived", "battery_low", "dock_robot.start", "dock_robot.success.docked",
        "charging_started", "battery_recharged"]
    assert all(not out.drifts and not out.bad for out in outputs) and run.divergences == []


def test_status_arrays_from_plain_messages() -> None:
    msg = {"status_list": [{"goal_info": {"goal_id": {"uuid": list(A)}, "stamp": {"sec": 3, "nanosec": 500000000}},
                            "status": 2}]}
    assert goals_from_plain(msg) == [Goal(A, 3.5, 2)]
    with pytest.raises(KeyError):
        goals_from_plain({"status": []})


def test_a_sent_goal_is_accepted_by_whichever_comes_first() -> None:
    """The status array may overtake the server's reply to send_goal (each has its own route)."""
    goal = SentGoal(A)
    assert not goal.on_status([Goal(B, 1.0, EXECUTING)])
    assert goal.on_status([Goal(B, 1.0, EXECUTING), Goal(A, 2.0, ACCEPTED)]) and goal.accepted
    goal.on_reply(True)
    assert goal.accepted and not goal.done
    goal.on_status([Goal(A, 2.0, SUCCEEDED)])
    assert goal.done and str(goal) == f"goal {A.hex()}: SUCCEEDED"
    late = SentGoal(B)
    late.on_status([Goal(B, 1.0, SUCCEEDED)])  # even its end before the reply
    late.on_reply(True)
    assert late.accepted and late.done
    rejected = SentGoal(C)
    rejected.on_reply(False)
    assert rejected.done and str(rejected) == f"goal {C.hex()}: rejected"
