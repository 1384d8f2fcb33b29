"""The planner against an independent plain-sets version of docs/semantics.md §8 (tests/plan/brute.py).

For hundreds of random goals from random reachable markings of the paper's
system, the mobile manipulator, the corpus pair, two cranes whose commands may have several results
(tests/plan/crane.rl) and random mutations of them:
the answer and the moves equal the plain fixpoints' (strong iff the start is
in W, cyclic iff it is in W_c only, none iff it is in neither), every policy
passes the brute-force checker (it plays every outcome), and the explicit
and the symbolic solvers give the same answers, reasons, steps and policies.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import replace

import pytest

from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.plan.planner import Planner
from skinet.plan.policy import Plan
from skinet.system.model import System
from skinet.verify.symbolic import available
from tests.plan.brute import Brute
from tests.plan.systems import corpus, cranes, mobile, mutants, paper, random_goal, random_marking

needs_cudd = pytest.mark.skipif(not available(), reason="dd.cudd (CUDD) is not installed")


def policy_view(plan: Plan) -> list:
    """What a plan tells: its steps, and its action and rank at every marking its policy reaches."""
    entries, whole = plan.policy()
    return [repr(plan.steps), whole, [(sorted(m.items()), a, r) for m, a, r in entries]]


def compare(system: System, goals_per_start: int, starts: int, seed: int) -> dict[str, int]:
    """Plan random goals with both engines; check each against the plain fixpoints and the checker."""
    rng = random.Random(seed)
    engines = [Planner(system, "explicit"), Planner(system, "symbolic")]
    seen: dict[str, int] = {"strong": 0, "cyclic": 0, "none": 0, "markings checked": 0}
    for n in range(starts):
        marking = system.initial_marking() if n == 0 else random_marking(system, rng, safe=n != 1)
        brute = Brute(system, marking, engines[0].events)
        for _ in range(goals_per_start):
            goal = random_goal(system, rng)
            explicit, symbolic = (p.plan(goal, marking) for p in engines)
            assert (symbolic.answer, symbolic.moves, symbolic.reason) == (explicit.answer, explicit.moves, explicit.reason), goal.text
            assert policy_view(symbolic) == policy_view(explicit), goal.text
            strong, cyclic = brute.strong(goal), brute.cyclic(goal)
            where = f"{goal.text} from {marking}"
            if brute.start in strong:
                assert (explicit.answer, explicit.moves) == ("strong", strong[brute.start]), where
            elif brute.start in cyclic:
                assert (explicit.answer, explicit.moves) == ("cyclic", cyclic[brute.start]), where
            else:
                assert explicit.answer == "none", where
                reason = explicit.reason or ""
                if reason.startswith("every way to it crosses a forced marking"):
                    assert brute.start not in brute.weak(goal), where
                elif reason.startswith("outcomes can lead away from it for good"):
                    assert brute.start in brute.weak(goal) and brute.start not in brute.cyclic(goal, relaxed=True), where
                elif reason.startswith("a skill the plan needs has inputs"):
                    assert brute.start in brute.cyclic(goal, relaxed=True), where
                elif reason.startswith("the goal is unsafe"):
                    assert not any(goal.holds(system, brute.as_dict(m)) for m in brute.safe), where
                elif reason == "no marking reachable from here satisfies it":
                    assert not any(goal.holds(system, brute.as_dict(m)) for m in brute.markings), where
                elif reason.startswith("the robot is in a marking forced for"):
                    assert brute.start not in brute.safe, where
                else:
                    assert reason.endswith("never runs from here: no reachable marking lets it start"), where
                seen[reason.split(":")[0]] = seen.get(reason.split(":")[0], 0) + 1
            seen[explicit.answer] += 1
            if explicit.answer != "none":
                seen["markings checked"] += brute.check(explicit)
    return seen


SYSTEMS: dict[str, tuple[Callable[[], System], int, int]] = {  # goals per start, starts
    "paper": (paper, 40, 6),
    "mobile": (mobile, 40, 6),
    "corpus": (corpus, 15, 4),
    "cranes": (cranes, 40, 5),  # commands with several results (invariant cascades in either order)
    "paper, events uncontrollable": (lambda: with_events(paper()), 30, 4),  # events are outcomes too (docs/semantics.md §6.3)
    "mobile, events uncontrollable": (lambda: with_events(mobile()), 30, 4),
}


def with_events(system: System) -> System:
    """``system`` with ``events_uncontrollable``: the game is played on the full nets, events being outcomes."""
    return replace(system, prediction=PredictionOptions(PropertyOptions(events_uncontrollable=True)))


@needs_cudd
@pytest.mark.parametrize("name", SYSTEMS)
def test_random_goals_match_the_plain_fixpoints(name: str) -> None:
    make, goals, starts = SYSTEMS[name]
    seen = compare(make(), goals, starts, seed=23)
    # every kind of answer occurs, so that no branch of the comparison is vacuous
    assert seen["strong"] and seen["cyclic"] and seen["none"], seen


@needs_cudd
@pytest.mark.parametrize("base", ["paper", "mobile"])
def test_random_mutations_match_the_plain_fixpoints(base: str) -> None:
    totals = {"strong": 0, "cyclic": 0, "none": 0}
    for system in mutants(SYSTEMS[base][0](), 8, seed={"paper": 11, "mobile": 6}[base]):
        seen = compare(system, 15, 3, seed=5)
        for k, v in seen.items():
            totals[k] = totals.get(k, 0) + v
    assert all(totals.values()), totals
    # the mutations make the last two reasons of none occur, which the base systems hardly do
    assert totals.get("every way to it crosses a forced marking") and totals.get(
        "outcomes can lead away from it for good"), totals
