"""The pilot's drive mode on the core: a mission flown without Zenoh (docs/semantics.md §8, *The pilot*).

What the pilot service does on the live robot, as one loop over the live nets: plan the
current goal from the marking (reusing the plan while ``plan.action`` answers there),
send its command, or, when it waits, let the running skill end in the mode
:class:`skinet.pilot.run.Outcomes` gave it when it started (as the simulated
implementations of :mod:`services.simulator.world` do); a ``run`` goal is reached by its
success outcome, a ``reach`` goal when the plan says so; ``max_retries`` failures of
one skill in one goal end the mission ``failed``.  ``skinet demo --core`` flies the
demo's pilot run with it, and the tests compare the chain's moves with its moves.
Cost: one plan per marking outside the current plan (:mod:`skinet.plan.planner`),
one ``plan.action`` per move.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Literal

from skinet.system.live import LiveSystem
from skinet.pilot.run import Outcomes
from skinet.plan import Command, Goal, Plan, Planner, Reached
from skinet.system.model import System


@dataclass
class Flight:
    """A mission flown: every move (``skillset``, ``transition``) in order, and how it ended."""

    moves: list[tuple[str, str]] = field(default_factory=list)
    end: Literal["reached", "failed"] = "reached"
    reason: str = ""
    goals: int = 0  # goals reached
    failures: dict[str, int] = field(default_factory=dict)  # 'skillset:skill' -> failures, the whole mission


def fly(system: System, goals: list[Goal], outcomes: Outcomes, *, max_retries: int = 3,
        budget: float | None = None, max_moves: int = 10_000, planner: Planner | None = None) -> Flight:
    """Fly ``goals`` from the initial marking (see the module docstring)."""
    planner = planner or Planner(system)
    live = LiveSystem(system)
    flight = Flight()
    running: deque[tuple[str, str, str, str]] = deque()  # (skillset, skill, kind, mode) in start order
    plan: Plan | None = None
    retries: dict[str, int] = {}
    index = 0
    while index < len(goals):
        if len(flight.moves) >= max_moves:
            return _failed(flight, f"more than {max_moves} moves")
        goal = goals[index]
        if plan is None or plan.action(live.marking) is None:
            plan = planner.plan(goal, live.marking, budget)
            if plan.answer not in ("strong", "cyclic"):
                return _failed(flight, f"no plan for '{goal.text}': {plan.answer}: {plan.reason}")
        action = plan.action(live.marking)
        if isinstance(action, Reached):
            index, plan, retries = index + 1, None, {}
            flight.goals += 1
            continue
        if isinstance(action, Command):
            skill, _, kind = action.transition.partition(".")
            live.apply(action.skillset, action.transition)
            flight.moves.append((action.skillset, action.transition))
            if kind == "start":
                running.append((action.skillset, skill, *outcomes.outcome(action.skillset, skill)))
            else:
                running = deque(r for r in running if r[:2] != (action.skillset, skill))
            continue
        while running:  # wait: the first skill started ends (one that stopped meanwhile is left alone)
            skillset, skill, kind, mode = running.popleft()
            transition = f"{skill}.{kind}.{mode}" if mode else f"{skill}.{kind}"
            if live.apply(skillset, transition).divergence is None:
                break
        else:
            return _failed(flight, f"the plan of '{goal.text}' waits, and no skill runs")
        flight.moves.append((skillset, transition))
        if kind == "failure":
            name = f"{skillset}:{skill}"
            retries[name] = retries.get(name, 0) + 1
            flight.failures[name] = flight.failures.get(name, 0) + 1
            if retries[name] >= max_retries:
                return _failed(flight, f"{name} failed {retries[name]} times (last: {mode})")
        if goal.target(skillset, transition):
            index, plan, retries = index + 1, None, {}
            flight.goals += 1
    return flight


def _failed(flight: Flight, reason: str) -> Flight:
    flight.end, flight.reason = "failed", reason
    return flight


__all__ = ["Flight", "fly"]
