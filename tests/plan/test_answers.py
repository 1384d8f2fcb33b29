"""Answers, reasons and the pilot's API of the planner (docs/semantics.md §8): exact plans on the paper's
system, each reason of ``none``, ``unknown`` never ``none`` when the search is cut, the strict
check's commands, determinism, races and replanning."""

from __future__ import annotations

import random
from itertools import product
from unittest import mock

import pytest

from services.monitor.check import Checker, parse_policy
from skinet.errors import SkinetError
from skinet.lang.parser import parse_skillset
from skinet.net.semantics import steps
from skinet.plan import Command, Plan, Planner, Reached, Wait, parse_goal
from skinet.plan import planner as planner_module
from skinet.system.model import System, build_system, marking_from_json, marking_to_json
from skinet.verify.algorithm1 import analyse
from skinet.verify.component import explore_component
from skinet.verify.explore import Deadline, resident_bytes
from skinet.verify.predict import forecast
from skinet.verify.symbolic import available
from skinet.wire.messages import CheckRequest
from tests.plan.brute import Brute
from tests.plan.systems import corpus, mobile, paper, random_goal, random_marking

ENGINES = ["explicit", pytest.param("symbolic", marks=pytest.mark.skipif(not available(), reason="no dd.cudd"))]
TARGET = {"go_to_waypoint": {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}}

CART = """
skillset cart {
    resource {
        place { state { Home Dock Lost } initial Home transition all }
        power { state { Off On } initial On transition all }
    }
    event { brownout { guard power == On effect power -> Off } }
    skill go_dock {
        precondition { at_home: place == Home }
        success arrived { effect place -> Dock }
        failure lost { effect place -> Lost }
    }
}
"""


def cart(props: str = "") -> System:
    return build_system("cart", [(parse_skillset(CART, "cart.rl"), "")], props)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_walk_returns_the_arm_home_first(engine: str) -> None:
    """From arm at RD (Spot standing), running go_to_waypoint must bring the arm home first (safety_guard)."""
    system = paper()
    start = marking_from_json(system, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing"}},
                                       "manipulator": {"resources": {"arm_status": "RD"}}})
    plan = Planner(system, engine).plan(parse_goal(system, "run spot:go_to_waypoint", TARGET), start)
    assert (plan.answer, plan.moves, plan.reason) == ("cyclic", 4, None)
    assert [(s.skillset, s.action, s.expect) for s in plan.steps] == [
        ("manipulator", "arm_RD_to_HP.start", None), ("manipulator", "wait", "arm_RD_to_HP.success.at_home"),
        ("spot", "go_to_waypoint.start", None), ("spot", "wait", "go_to_waypoint.success.arrived")]
    assert plan.steps[2].inputs == TARGET["go_to_waypoint"]
    assert plan.action(start) == Command("manipulator", "arm_RD_to_HP.start", {})
    assert plan.retries == ["manipulator:arm_moving_to_RD.failure.blocked", "spot:go_to_waypoint.failure.not_arrived"]
    (branch,) = plan.steps[1].branches  # the arm blocked on its way home: back to RD, then home again
    assert (branch.transition, branch.then, branch.step) == ("arm_RD_to_HP.failure.blocked", "route", "1")
    assert [(s.number, s.action) for s in branch.steps] == [("2.1", "arm_moving_to_RD.start"), ("2.2", "wait")]


@pytest.mark.parametrize("engine", ENGINES)
def test_goals_that_hold_answer_strong_with_no_move(engine: str) -> None:
    system = paper()
    planner = Planner(system, engine)
    for text in ("reach spot:Sitting", "reach manipulator:HP and not spot:Busy", "reach true"):
        plan = planner.plan(parse_goal(system, text))
        assert (plan.answer, plan.moves, plan.steps, plan.retries) == ("strong", 0, [], []), text
        assert plan.action(system.initial_marking()) == Reached()
        assert plan.policy() == ([(system.initial_marking(), Reached(), 0)], True)


@pytest.mark.parametrize("engine", ENGINES)
def test_strong_plans(engine: str) -> None:
    """teleop ends whatever its outcome: waiting is a strong plan of 1 move (an interrupt would do
    as well, but the policy never interrupts a skill that waiting ends as well); from a standing,
    idle Spot, starting teleop reaches i_teleop whatever comes."""
    system = paper()
    planner = Planner(system, engine)
    teleop = marking_from_json(system, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing",
                                                               "control_mode": "Busy"}, "running": ["teleop"]}})
    plan = planner.plan(parse_goal(system, "reach not spot:i_teleop"), teleop)
    assert (plan.answer, plan.moves, plan.action(teleop)) == ("strong", 1, Wait())
    (step,) = plan.steps
    assert (step.action, step.expect, [(b.transition, b.then) for b in step.branches]) == (
        "wait", "teleop.success.done", [("teleop.failure.link_lost", "reached")])
    Brute(system, teleop).check(plan)
    standing = marking_from_json(system, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing"}}})
    plan = planner.plan(parse_goal(system, "reach spot:i_teleop and spot:Busy"), standing)
    assert (plan.answer, plan.moves, plan.action(standing)) == ("strong", 1, Command("spot", "teleop.start", {}))
    Brute(system, standing).check(plan)


# -- the reasons of none ------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ENGINES)
def test_an_unsafe_goal_names_its_property(engine: str) -> None:
    system = paper()
    plan = Planner(system, engine).plan(parse_goal(system, "reach spot:i_go_to_waypoint and manipulator:RD"))
    assert plan.answer == "none"
    assert plan.reason == ("the goal is unsafe: every marking where it holds is forced for safety_guard "
                           "(violated there: spot go_to_waypoint runs while manipulator arm_status at RD)")
    assert plan.action(system.initial_marking()) is None and plan.steps == [] and plan.moves is None


@pytest.mark.parametrize("engine", ENGINES)
def test_a_skill_without_its_inputs_is_never_started(engine: str) -> None:
    system = paper()
    planner = Planner(system, engine)
    plan = planner.plan(parse_goal(system, "reach spot:i_go_to_waypoint"))
    assert (plan.answer, plan.reason) == (
        "none", "a skill the plan needs has inputs the goal does not give: spot:go_to_waypoint (input target)")
    given = planner.plan(parse_goal(system, "reach spot:i_go_to_waypoint", TARGET))
    assert (given.answer, given.moves) == ("cyclic", 5)
    assert given.steps[-1].action == "go_to_waypoint.start" and given.steps[-1].inputs == TARGET["go_to_waypoint"]


@pytest.mark.parametrize("engine", ENGINES)
def test_every_way_crosses_a_forced_marking(engine: str) -> None:
    """go_dock may fail and leave the cart Lost (never_lost): starting it is never admissible."""
    system = cart("never_lost = not cart:Lost")
    plan = Planner(system, engine).plan(parse_goal(system, "reach cart:Dock"))
    assert (plan.answer, plan.reason) == ("none", (
        "every way to it crosses a forced marking: the shortest, cart:go_dock.start, may lead to one forced for "
        "never_lost (go_dock may fail (lost) (1 step) and leave cart place at Lost)"))


@pytest.mark.parametrize("engine", ENGINES)
def test_outcomes_that_lead_away_for_good(engine: str) -> None:
    """Without the property, Lost is safe but a dead end: no retry can reach the dock from it."""
    system = cart()
    plan = Planner(system, engine).plan(parse_goal(system, "reach cart:Dock"))
    assert (plan.answer, plan.reason) == ("none", (
        "outcomes can lead away from it for good: on the shortest safe way (cart:go_dock.start, "
        "cart:go_dock.success.arrived), cart:go_dock.failure.lost may come instead, and no safe way reaches the "
        "goal from there"))
    run = Planner(system, engine).plan(parse_goal(system, "run cart:go_dock"))
    assert run.reason == (
        "outcomes can lead away from it for good: on the shortest safe way (cart:go_dock.start, "
        "cart:go_dock.success.arrived), cart:go_dock.failure.lost may come instead, and no safe way reaches the "
        "goal from there")


@pytest.mark.parametrize("engine", ENGINES)
def test_unreachable_goals_and_forced_starts(engine: str) -> None:
    system = cart("powered = cart:On")
    planner = Planner(system, engine)
    lost = marking_from_json(system, {"cart": {"resources": {"place": "Lost"}}})
    assert planner.plan(parse_goal(system, "reach cart:Home"), lost).reason == "no marking reachable from here satisfies it"
    assert planner.plan(parse_goal(system, "run cart:go_dock"), lost).reason == (
        "cart:go_dock never runs from here: no reachable marking lets it start")
    off = marking_from_json(system, {"cart": {"resources": {"power": "Off"}}})
    plan = planner.plan(parse_goal(system, "reach cart:Dock"), off)
    assert (plan.answer, plan.reason) == ("none", "the robot is in a marking forced for powered (violated there: "
                                                  "cart power at Off): no plan can promise safety from here; no "
                                                  "command leads back into Safe whatever its outcome")
    assert plan.recovery == []


# -- unknown, never none, when the search is cut -----------------------------------------------


def test_a_cut_exploration_answers_unknown_never_none() -> None:
    """2 + 2 corpus copies, explicit engine, a memory limit that leaves room for a few layers only
    (the limit is the whole process's: each question gets a fresh planner with room above what is
    resident now)."""
    system = corpus(2, 2)

    def cut(text: str) -> Plan:
        planner = Planner(system, "explicit", memory_limit=resident_bytes() + (24 << 20))
        return planner.plan(parse_goal(system, text), budget=30)

    full = Planner(system, "explicit")
    for text in ("reach spot:i_go_to_waypoint and not manipulator:Hp",  # none after a complete search
                 "reach spot:HeadingSet and spot2:HeadingSet"):  # cyclic, 12 moves
        plan = cut(text)
        assert full.plan(parse_goal(system, text)).answer in ("none", "cyclic")
        assert plan.answer == "unknown", text
        assert plan.reason.startswith("no plan within the ") and plan.reason.endswith(
            " markings explored: the exploration was cut by the memory limit"), plan.reason
        assert not plan.stats.complete and plan.stats.markings < 246_016
    near = cut("reach spot:Standing and spot2:Standing")  # a partial search may still plan
    whole = full.plan(parse_goal(system, "reach spot:Standing and spot2:Standing"))
    assert (near.answer, near.moves, near.stats.complete) == ("cyclic", 8, False)
    assert 0 < near.stats.markings < whole.stats.markings == 246_016
    assert (near.moves, repr(near.steps)) == (whole.moves, repr(whole.steps))


@pytest.mark.skipif(not available(), reason="no dd.cudd")
def test_the_symbolic_engine_keeps_to_the_memory_limit_with_unknown() -> None:
    """The BDDs have no exploration to cut: the fixpoints stop once the process's resident memory passes the
    limit, and the answer is unknown with that reason, never none.  A limit below what is resident now stops
    them at their first iteration; with room, the same question is answered."""
    system = corpus(2, 2)
    text = "reach spot:i_go_to_waypoint and not manipulator:Hp"  # none after a complete search
    tight = Planner(system, "symbolic", memory_limit=resident_bytes() // 2).plan(parse_goal(system, text), budget=30)
    assert tight.answer == "unknown" and tight.stats.engine == "symbolic"
    assert tight.reason.startswith("the memory limit (") and tight.reason.endswith(
        " MiB, the whole process) was reached before the fixpoints ended (246016 markings, complete)"), tight.reason
    assert Planner(system, "symbolic").plan(parse_goal(system, text), budget=30).answer == "none"


@pytest.mark.parametrize("engine", ENGINES)
def test_a_deadline_at_any_step_never_contradicts_the_answer(engine: str) -> None:
    """Cut the budget after every number of deadline checks: the answer is the full one or unknown
    (for none: none, possibly without its reason), never another."""
    system = paper()
    planner = Planner(system, engine)
    rng = random.Random(11)
    goals = [parse_goal(system, t, TARGET) for t in ("run spot:go_to_waypoint", "reach spot:Standing and manipulator:RD",
                                                      "reach spot:i_go_to_waypoint and manipulator:RD")]
    goals += [random_goal(system, rng) for _ in range(6)]
    for goal in goals:
        full = planner.plan(goal)
        answers = set()
        for cut in range(0, 60):
            calls = [0]

            def expired(cut: int = cut) -> bool:
                calls[0] += 1
                return calls[0] > cut

            fake = mock.Mock(spec=Deadline)
            fake.expired.side_effect = expired
            with mock.patch.object(planner_module.Deadline, "after", return_value=fake):
                plan = planner.plan(goal)
            answers.add(plan.answer)
            assert plan.answer in (full.answer, "unknown"), (goal.text, cut)
            if plan.answer == full.answer and full.answer != "none":
                assert (plan.moves, plan.steps) == (full.moves, full.steps)
            if plan.answer == "unknown":
                assert plan.reason.startswith("the budget ran out before the fixpoints ended")
        assert answers == {"unknown", full.answer}, goal.text


# -- the strict check ---------------------------------------------------------------------------


def reachable(system: System) -> list[dict[str, int]]:
    """Every marking the robot can be in (events included): the product of each component's."""
    comps = system.components
    sets = [explore_component(c.name, c.net, [c.net.initial]).states for c in comps]
    return [dict(zip([c.name for c in comps], combo)) for combo in product(*sets)]


def strict_allows(system: System, marking: dict[str, int], predict: bool) -> set[tuple[str, str]]:
    """The commands the monitor's check with the strict policy does not deny."""
    checker = Checker(system, parse_policy("strict"))
    analysis = analyse(system, marking, forecast(system, marking) if predict else None)
    out = set()
    for c in system.components:
        for name in sorted({t.name for t, _ in steps(c.net, marking[c.name]) if t.controllable}):
            reply = checker.answer(CheckRequest(skillset=c.name, transition=name), analysis, id(analysis))
            if reply.decision != "deny":
                out.add((c.name, name))
    return out


@pytest.mark.parametrize("predict", [False, True], ids=["explicit-forced", "with-prediction"])
def test_admissible_commands_are_those_the_strict_check_allows(predict: bool) -> None:
    """Over all 70 markings of the paper's system (events included).  Where a property is already
    violated the check judges only the others (docs/semantics.md §5's operator view) and so allows the arm's
    interrupts while go_to_waypoint runs with the arm out; the planner never starts from there."""
    system = paper()
    planner = Planner(system)
    markings = reachable(system)
    assert len(markings) == 70
    differ = []
    for m in markings:
        allowed = set(planner.admissible(m))
        if allowed != strict_allows(system, m, predict):
            differ.append((marking_to_json(system, m), sorted(allowed ^ strict_allows(system, m, predict))))
    assert len(differ) == 4
    for state, extra in differ:
        assert state["spot"]["running"] == ["go_to_waypoint"] and state["manipulator"]["running"]
        assert extra == [("manipulator", f"{state['manipulator']['running'][0]}.interrupt")]


# -- the pilot's use ----------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ENGINES)
def test_the_same_question_gets_the_same_plan(engine: str) -> None:
    system = mobile()
    rng = random.Random(3)
    for _ in range(20):
        goal = random_goal(system, rng)
        marking = random_marking(system, rng)
        a, b = Planner(system, engine).plan(goal, marking), Planner(mobile(), engine).plan(goal, marking)
        assert (a.answer, a.moves, a.reason, repr(a.steps)) == (b.answer, b.moves, b.reason, repr(b.steps))
        assert [(m, x, r) for m, x, r in a.policy()[0]] == [(m, x, r) for m, x, r in b.policy()[0]]


@pytest.mark.parametrize("engine", ENGINES)
def test_races_an_outcome_before_a_command_takes_effect(engine: str) -> None:
    """Wherever a policy sends a command while a skill runs (the mobile manipulator's arm and base
    work side by side), any outcome that comes first leaves a safe marking, from which the plan
    goes on where it covers the marking and the planner answers again where it does not."""
    system = mobile()
    planner = Planner(system, engine)
    rng = random.Random(1)
    raced = covered = 0
    for _ in range(60):
        goal, start = random_goal(system, rng), random_marking(system, rng)
        plan = planner.plan(goal, start)
        if plan.answer not in ("strong", "cyclic"):
            continue
        for marking, action, _ in plan.policy()[0]:
            if not isinstance(action, Command):
                continue
            for c in system.components:
                for t, results in steps(c.net, marking[c.name]):
                    if t.kind not in ("success", "failure") or goal.target(c.name, t.name):
                        continue
                    for r in results:
                        after = {**marking, c.name: r}
                        raced += 1
                        assert planner.arena(after).safe_at(planner.arena(after).root)
                        if plan.covers(after):
                            covered += 1
                            assert plan.action(after) is not None
                        else:
                            assert plan.action(after) is None
                            assert planner.plan(goal, after).answer in ("strong", "cyclic", "none")
    assert raced > 20 and covered > 0


@pytest.mark.parametrize("engine", ENGINES)
def test_the_pilot_follows_a_plan_and_replans_off_it(engine: str) -> None:
    system = paper()
    planner = Planner(system, engine)
    goal = parse_goal(system, "reach spot:Standing")
    plan = planner.plan(goal)
    marking = system.initial_marking()
    assert plan.action(marking) == Command("spot", "init_power.start", {})
    marking = {**marking, "spot": min(steps_named(system, "spot", marking, "init_power.start"))}
    assert (plan.rank(marking), plan.action(marking)) == (3, Wait())
    marking = {**marking, "spot": min(steps_named(system, "spot", marking, "init_power.failure.no_battery"))}
    assert plan.action(marking) == Command("spot", "init_power.start", {})  # a retry: the same plan covers it
    # An event off the game (the battery dies once standing): outside the plan's arena, plan again.
    standing = marking_from_json(system, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing"}}})
    after_event = {**standing, "spot": min(steps_named(system, "spot", standing, "power_switchoff"))}
    assert planner.plan(goal, after_event).action(after_event) == Command("spot", "init_power.start", {})
    assert planner.plan(goal, standing).action(standing) == Reached()
    assert planner.plan(goal).action(system.initial_marking()) == plan.action(system.initial_marking())
    with pytest.raises(SkinetError, match="impossible state: 'spot' is not stable"):
        planner.plan(goal, {**marking, "spot": marking_from_json(system, {"spot": {
            "resources": {"power_status": "PowerOff"}, "running": ["stand_up"]}})["spot"]})


def steps_named(system: System, skillset: str, marking: dict[str, int], name: str) -> set[int]:
    net = system.component(skillset).net
    return {r for t, results in steps(net, marking[skillset]) if t.name == name for r in results}


@pytest.mark.parametrize("engine", ENGINES)
def test_a_mission_goes_goal_after_goal(engine: str) -> None:
    system = paper()
    goals = [parse_goal(system, "reach manipulator:RD"), parse_goal(system, "run spot:go_to_waypoint", TARGET),
             parse_goal(system, "reach spot:i_go_to_waypoint and manipulator:RD"), parse_goal(system, "reach spot:Sitting")]
    plans = Planner(system, engine).mission(goals)
    assert [(p.answer, p.moves) for p in plans] == [("cyclic", 2), ("cyclic", 8), ("none", None)]
    assert marking_to_json(system, plans[0].end)["manipulator"]["resources"]["arm_status"] == "RD"
    assert marking_to_json(system, plans[1].arena.marking(plans[1].start)) == marking_to_json(system, plans[0].end)
    assert [s.action for s in plans[1].steps][4:6] == ["arm_RD_to_HP.start", "wait"]
    end = marking_to_json(system, plans[1].end)
    assert end["spot"]["running"] == [] and end["manipulator"]["resources"]["arm_status"] == "HP"


def test_engines_need_cudd_or_say_so() -> None:
    with pytest.raises(SkinetError, match="unknown engine 'fast'"):
        Planner(paper(), "fast")
    with mock.patch.object(planner_module, "_cudd", return_value=False):
        with pytest.raises(SkinetError, match="the symbolic engine needs dd's CUDD extension"):
            Planner(paper(), "symbolic")
        assert Planner(corpus(2, 2)).engine_for(Planner(corpus(2, 2)).arena(corpus(2, 2).initial_marking())) == "explicit"


def test_every_violated_marking_of_the_paper_names_each_violation_and_a_way_back() -> None:
    """Issue 30: from a violated marking the answer named only the first property, and no way out.  Now it
    names every violated property and the admissible commands (every result in Safe, docs/semantics.md §8) that recover;
    each really leads into Safe (checked on the plain-sets game of tests/plan/brute.py)."""
    from skinet.props.evaluate import holds

    system = paper()
    planner = Planner(system)
    brute = Brute(system, system.initial_marking())
    violated = {m: [p.name for p in system.properties if not holds(p.expr, brute.as_dict(m), system.nets)]
                for m in sorted(brute.markings)}
    violated = {m: names for m, names in violated.items() if names}
    assert len(violated) == 26 and max(len(n) for n in violated.values()) == 2
    for m, names in violated.items():
        plan = planner.plan(parse_goal(system, "reach true"), brute.as_dict(m))
        assert plan.answer == "none", m
        head = f"{len(names)} properties: " if len(names) > 1 else ""
        assert plan.reason.startswith(f"the robot is in a marking forced for {head}"), plan.reason
        assert all(f"{n} (violated there: " in plan.reason for n in names), (names, plan.reason)
        assert plan.recovery, m
        for skillset, transition in plan.recovery:
            i = brute.names.index(skillset)
            results = brute.commands[m][(i, transition)]
            assert results and results <= brute.safe, (m, skillset, transition)
        assert plan.reason.endswith("recover first with one of " + ", ".join(f"{c}:{t}" for c, t in plan.recovery)
                                    + " (each leads back into Safe whatever its outcome), then plan again")
