"""Commanded resources (docs/semantics.md §9): a bound resource's change is an event of the skillset, uncontrollable unless
the binding says the resource is ``commanded``.  Then the events that change it are commands in Algorithm 1
(docs/semantics.md §5: ``controllable``, as the check reports them), and never uncontrollable steps, for forced constraints
(§6.3) or plans (§8), even with ``events_uncontrollable``.

The Nav2 base (examples/nav2): ``bt_navigator``'s lifecycle is commanded by its lifecycle manager.  A property
that needs it active while the robot navigates is then safe to start navigating under (deactivating it is a
command the check warns about, not something that happens by itself); with the navigator the robot's own, the
start is forced and no plan may navigate.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.system.load import load_bindings, load_system
from skinet.plan import Planner, parse_goal
from skinet.system.model import System, marking_from_json
from skinet.verify.algorithm1 import analyse

REPO = Path(__file__).resolve().parents[2]
NAV2 = REPO / "examples" / "nav2"
NAVIGATOR_EVENTS = {"navigator_configured", "navigator_activated", "navigator_deactivated", "navigator_cleaned_up",
                    "navigator_shut_down"}
READY = {"nav2": {"resources": {"navigator": "Active", "dock": "Undocked", "charging": "NotCharging"}}}
NAVIGATING = {"nav2": {**READY["nav2"], "running": ["navigate"]}}
NAVIGATING["nav2"]["resources"] = {**READY["nav2"]["resources"], "motion": "Moving"}


def nav2(tmp_path: Path, commanded: bool) -> System:
    """The Nav2 base with ``nav_needs_active``, events counted as uncontrollable, its navigator commanded or not."""
    binding = (NAV2 / "nav2.binding.toml").read_text()
    assert "commanded = true" in binding
    folder = tmp_path / ("commanded" if commanded else "robot")
    folder.mkdir()
    (folder / "b.toml").write_text(binding if commanded else binding.replace("commanded = true", "commanded = false"))
    (folder / "p.props").write_text("nav_needs_active = not (nav2:i_navigate and not nav2:Active)\n")
    (folder / "s.toml").write_text(f'[system]\nname = "s"\nproperties = "p.props"\n[[skillsets]]\n'
                                   f'model = "{NAV2 / "nav2.rl"}"\nbinding = "b.toml"\n'
                                   '[prediction]\nevents_uncontrollable = true\n')
    return load_system(folder / "s.toml")[0]


def test_the_events_that_change_a_commanded_resource_are_controllable(tmp_path: Path) -> None:
    system = nav2(tmp_path, commanded=True)
    component = system.component("nav2")
    assert component.commanded == NAVIGATOR_EVENTS
    assert {t.name for t in component.net.transitions if t.kind == "event" and t.controllable} == NAVIGATOR_EVENTS
    assert load_bindings(load_system(NAV2 / "nav2.toml")[0])[0]["nav2"].commanded == NAVIGATOR_EVENTS
    robot = nav2(tmp_path, commanded=False).component("nav2")
    assert robot.commanded == frozenset() and not any(t.controllable for t in robot.net.transitions
                                                      if t.kind == "event")


@pytest.mark.parametrize("commanded", [True, False], ids=["commanded", "the robot's own"])
def test_algorithm_1_calls_a_commanded_event_a_command_and_never_forced(tmp_path: Path, commanded: bool) -> None:
    system = nav2(tmp_path, commanded)
    navigating = analyse(system, marking_from_json(system, NAVIGATING))
    forced_now = [] if commanded else [  # navigating is forced then: every step leaves it forced
        ("battery_low", "forced", False), ("charging_started", "forced", False)]
    assert sorted((u.transition, u.constraint, u.controllable) for u in navigating.operator_unsafe()) == [
        *forced_now, ("navigator_deactivated", "explicit", commanded), ("navigator_shut_down", "explicit", commanded)]
    ready = analyse(system, marking_from_json(system, READY))
    forced = [(u.transition, u.constraint, u.steps, u.witness) for u in ready.operator_unsafe()]
    assert forced == ([] if commanded else [("navigate.start", "forced", 1, ("nav2:navigator_deactivated",))])


@pytest.mark.parametrize("engine", ["explicit", "symbolic"])
@pytest.mark.parametrize("commanded", [True, False], ids=["commanded", "the robot's own"])
def test_a_plan_may_navigate_only_when_nobody_but_an_operator_deactivates_the_navigator(tmp_path: Path,
                                                                                        commanded: bool,
                                                                                        engine: str) -> None:
    system = nav2(tmp_path, commanded)
    ready = marking_from_json(system, READY)
    plan = Planner(system, engine=engine).plan(parse_goal(system, "run nav2:navigate"), ready)
    admissible = Planner(system).admissible(ready)
    if commanded:  # a commanded event is nobody's outcome: the plan needs no deactivation, and sends none
        assert (plan.answer, [(s.skillset, s.action) for s in plan.steps]) == (
            "cyclic", [("nav2", "navigate.start"), ("nav2", "wait")])
        # commanded events are commands of the game: safe to send while nothing navigates
        assert admissible == [("nav2", "navigator_deactivated"), ("nav2", "navigator_shut_down"),
                              ("nav2", "navigate.start"), ("nav2", "dock_robot.start")]
    else:
        assert (plan.answer, plan.reason) == (
            "none", "the goal is unsafe: every marking where nav2:navigate can succeed is forced for nav_needs_active "
                    "(event navigator_deactivated may occur (1 step) and leave nav2 navigate runs and nav2 navigator "
                    "at Inactive)")
        assert admissible == [("nav2", "dock_robot.start")]


@pytest.mark.parametrize("engine", ["explicit", "symbolic"])
@pytest.mark.parametrize("events", [False, True], ids=["eventless", "events uncontrollable"])
def test_a_plan_activates_a_commanded_navigator_before_navigating(tmp_path: Path, engine: str, events: bool) -> None:
    """The events a binding commands are commands of the game (docs/planning.md): from an inactive navigator the
    plan activates it, then navigates; from the initial marking it configures it first."""
    system = nav2(tmp_path, commanded=True)
    if not events:
        system = load_system(NAV2 / "nav2.toml")[0]
    planner = Planner(system, engine=engine)
    goal = parse_goal(system, "run nav2:navigate")
    inactive = marking_from_json(system, {"nav2": {"resources": {**READY["nav2"]["resources"], "navigator": "Inactive"}}})
    plan = planner.plan(goal, inactive)
    assert plan.answer == "cyclic"
    assert [(s.skillset, s.action) for s in plan.steps] == [
        ("nav2", "navigator_activated"), ("nav2", "navigate.start"), ("nav2", "wait")]
    assert plan.steps[0].inputs is None and plan.steps[0].expect is None
    first = plan.action(inactive)
    assert (first.skillset, first.transition, dict(first.inputs)) == ("nav2", "navigator_activated", {})
    initial = planner.plan(goal)
    assert [s.action for s in initial.steps][:2] == ["navigator_configured", "navigator_activated"]


@pytest.mark.parametrize("engine", ["explicit", "symbolic"])
def test_no_plan_because_an_event_is_not_commanded_says_so(tmp_path: Path, engine: str) -> None:
    """The navigator the robot's own and events not counted: from an inactive navigator nothing activates it, and
    the reason names the event a plan would send if the binding commanded it."""
    binding = (NAV2 / "nav2.binding.toml").read_text().replace("commanded = true", "commanded = false")
    (tmp_path / "b.toml").write_text(binding)
    (tmp_path / "s.toml").write_text(f'[system]\nname = "s"\nproperties = "{NAV2 / "nav2.props"}"\n[[skillsets]]\n'
                                     f'model = "{NAV2 / "nav2.rl"}"\nbinding = "b.toml"\n')
    system = load_system(tmp_path / "s.toml")[0]
    inactive = marking_from_json(system, {"nav2": {"resources": {**READY["nav2"]["resources"], "navigator": "Inactive"}}})
    plan = Planner(system, engine=engine).plan(parse_goal(system, "run nav2:navigate"), inactive)
    assert (plan.answer, plan.reason) == (
        "none", "nav2:navigate never runs from here: no reachable marking lets it start; a plan needs "
                "nav2:navigator_activated, which no binding commands (a plan sends an event only when its binding "
                "says the resource it changes is commanded)")
    # Only what a lifecycle manager could command is named: a battery recharging is nobody's command.
    low = marking_from_json(system, {"nav2": {"resources": {**READY["nav2"]["resources"], "battery": "Low"}}})
    plan = Planner(system, engine=engine).plan(parse_goal(system, "run nav2:navigate"), low)
    assert (plan.answer, plan.reason) == (
        "none", "the goal is unsafe: every marking where nav2:navigate can succeed is forced for dock_when_low "
                "(violated there: nav2 battery at Low while nav2 navigate runs)")
