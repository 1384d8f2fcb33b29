"""The planner: a goal, or a mission goal after goal, from a marking (docs/semantics.md §8).

:class:`Planner` builds what does not depend on the goal once per start
marking and keeps it (the arena, the explored graph or its BDDs), so that the
pilot may ask at every marking change.  Per question: strong first, then
strong cyclic (:mod:`skinet.plan.solve`); ``none`` only after a complete search
(:mod:`skinet.plan.diagnose` says why, and :meth:`Planner.plan` adds the events a plan
would need that no binding commands); ``unknown`` when the budget or the
memory limit cut the search and no plan lies within what was searched.

Engines: ``explicit`` on the explored graph (:mod:`skinet.plan.explicit`),
``symbolic`` on BDDs of the whole product (:mod:`skinet.plan.symbolic`); both
give the same answers and the same policies.  ``auto`` takes the explicit one
up to :data:`EXPLICIT_UP_TO` markings in the product of the component graphs
and the symbolic one beyond (the explicit engine where dd's CUDD extension is
missing).  Cost: see the engines; the goal-independent part is paid once per
start marking.
"""

from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from collections.abc import Hashable, Mapping, Sequence
from typing import Any

from skinet.errors import SkinetError
from skinet.net.build import build_net
from skinet.plan.arena import Arena
from skinet.plan.diagnose import _forced_words, diagnose
from skinet.plan.goal import Goal
from skinet.plan.policy import Command, Plan, Stats
from skinet.plan.solve import cyclic, strong
from skinet.system.model import System, marking_problems
from skinet.verify.explore import DEFAULT_MEMORY_LIMIT, Deadline, resident_bytes

ENGINES = ("auto", "explicit", "symbolic")
# Up to this many markings in the product, the explicit engine answers faster than the BDDs.
# Warm plans of a goal over every component (benchmarks/bench_plan.py and corpus copies,
# thread CPU time): the paper's system, 63 markings, 0.18 ms against 0.53 ms; 1 + 1, 496,
# 0.54 against 3.1 ms; 1 + 3, 7 936, 14 against 24 ms; 2 + 1, 61 504, 99 against 24 ms;
# 2 + 2, 246 016, 522 against 23 ms.
EXPLICIT_UP_TO = 1 << 14
CACHE_SIZE = 8  # start markings whose goal-independent structures are kept


class Planner:
    """Plans goals on one system; see the package docstring (:mod:`skinet.plan`) for the pilot's use.
    Not thread-safe: one planner per thread (it keeps the structures of recent start markings)."""

    def __init__(self, system: System, engine: str = "auto", memory_limit: int | None = DEFAULT_MEMORY_LIMIT):
        if engine not in ENGINES:
            raise SkinetError(f"unknown engine '{engine}' (engines: {', '.join(ENGINES)})")
        if engine == "symbolic" and not _cudd():
            raise SkinetError("the symbolic engine needs dd's CUDD extension (dd.cudd), which is not installed here")
        self.system = system
        self.engine = engine
        self.memory_limit = memory_limit
        opts = system.prediction
        self.events = opts.default.events_uncontrollable or any(o.events_uncontrollable for o in opts.overrides.values())
        self._cache: OrderedDict[Hashable, dict[str, Any]] = OrderedDict()
        self._uncommanded_reason = True  # off in the planner that asks with every event commanded

    def arena(self, marking: Mapping[str, int]) -> Arena:
        """The arena from ``marking`` (kept for the next questions from the same marking)."""
        return self._entry(marking)["arena"]

    def _entry(self, marking: Mapping[str, int]) -> dict[str, Any]:
        key = tuple(marking[c.name] for c in self.system.components)
        entry = self._cache.get(key)
        if entry is None:
            problems = marking_problems(self.system, marking)
            if problems:
                raise SkinetError("impossible state: " + "; ".join(problems))
            entry = {"arena": Arena(self.system, marking, self.events)}
            self._cache[key] = entry
            while len(self._cache) > CACHE_SIZE:
                self._cache.popitem(last=False)
        self._cache.move_to_end(key)
        return entry

    def engine_for(self, arena: Arena) -> str:
        """The engine ``auto`` takes for ``arena`` (or the one forced)."""
        if self.engine != "auto":
            return self.engine
        return "explicit" if arena.box <= EXPLICIT_UP_TO or not _cudd() else "symbolic"

    def plan(self, goal: Goal, marking: Mapping[str, int] | None = None, budget: float | None = None) -> Plan:
        """The answer to ``goal`` from ``marking`` (default: initial) within ``budget`` seconds."""
        started = time.perf_counter()
        return self._plan(goal, marking, Deadline.after(budget, started), started)

    def _plan(self, goal: Goal, marking: Mapping[str, int] | None, deadline: Deadline, started: float) -> Plan:
        marking = dict(marking or self.system.initial_marking())
        entry = self._entry(marking)
        arena: Arena = entry["arena"]
        engine = self.engine_for(arena)
        if engine == "explicit":
            from skinet.plan.explicit import ExplicitGame, ExplicitSpace

            space = entry.get("explicit")
            if space is None:
                space = ExplicitSpace(arena, deadline, self.memory_limit)
                if space.space.complete:  # a cut exploration depends on this budget: not kept
                    entry["explicit"] = space
            game = ExplicitGame(space, goal)
            relaxed = lambda r: ExplicitGame(space, goal, r)  # noqa: E731
            markings, complete, cut = space.space.markings, space.space.complete, space.space.truncated_by
        else:
            from skinet.plan.symbolic import SymbolicGame, SymbolicSpace

            space = entry.get("symbolic")
            if space is None:
                space = entry["symbolic"] = SymbolicSpace(arena)
            game = SymbolicGame(space, goal)
            relaxed = lambda r: SymbolicGame(space, goal, r)  # noqa: E731
            markings, complete, cut = arena.box, True, None

        def stats() -> Stats:
            return Stats(engine, markings, complete, cut, time.perf_counter() - started)

        start = arena.root
        if not arena.safe_at(start):
            recovery = self.admissible(marking)
            back = (f"; recover first with one of {', '.join(f'{c}:{t}' for c, t in recovery)} (each leads "
                    "back into Safe whatever its outcome), then plan again" if recovery else
                    "; no command leads back into Safe whatever its outcome")
            n = len(arena.forced_for(start))
            plan = Plan(goal, arena, start, "none",
                        f"the robot is in a marking forced for {f'{n} properties: ' if n > 1 else ''}"
                        f"{_forced_words(arena, start, every=True)}: no plan can promise safety from here{back}",
                        stats())
            plan.recovery = recovery
            return plan
        stop = _Stop(deadline, self.memory_limit)
        for answer, solve in (("strong", strong), ("cyclic", cyclic)):
            layers = solve(game, stop)
            if layers is None:
                return Plan(goal, arena, start, "unknown", _cut_short(markings, complete, cut, stop), stats())
            if game.member(layers[-1], start):
                return Plan(goal, arena, start, answer, None, stats(), game, layers)  # type: ignore[arg-type]
        if not complete:
            return Plan(goal, arena, start, "unknown",
                        f"no plan within the {markings} markings explored: the exploration was cut by the "
                        f"{'memory limit' if cut == 'memory' else cut}", stats())
        reason = diagnose(arena, goal, game, relaxed, stop)
        needed = self._uncommanded_needed(goal, marking, deadline)
        if needed:
            reason += (f"; a plan needs {', '.join(needed)}, which no binding commands (a plan sends an event only "
                       "when its binding says the resource it changes is commanded)")
        return Plan(goal, arena, start, "none", reason, stats())

    def _uncommanded_needed(self, goal: Goal, marking: Mapping[str, int], deadline: Deadline) -> list[str]:
        """The events (``skillset:event``) that a plan sends when every event that changes a resource bound to a
        lifecycle node is commanded (``Component.commandable``; a battery running low is nobody's command), and
        that no binding commands here: why there is no plan when a command is not available (docs/planning.md).
        Empty when those are all commanded already, no such plan exists, or the budget runs out.  Cost: one
        more plan, on the arena where they are commands, and a walk of its policy."""
        if not self._uncommanded_reason or deadline.expired():
            return []
        components = []
        for c in self.system.components:
            every = c.commanded | c.commandable
            components.append(c if every <= c.commanded else dataclasses.replace(
                c, net=build_net(c.skillset, commanded=every), commanded=every))
        if all(a is b for a, b in zip(components, self.system.components)):
            return []
        relaxed = Planner(dataclasses.replace(self.system, components=tuple(components)), self.engine,
                          self.memory_limit)
        relaxed._uncommanded_reason = False
        plan = relaxed._plan(goal, marking, _Within(deadline), time.perf_counter())
        if plan.answer not in ("strong", "cyclic"):
            return []
        needed: list[str] = []
        for _, action, _ in plan.policy()[0]:
            if isinstance(action, Command):
                c = self.system.component(action.skillset)
                if action.transition not in c.commanded and any(e.name == action.transition for e in c.skillset.events):
                    needed.append(f"{action.skillset}:{action.transition}")
        return list(dict.fromkeys(needed))

    def admissible(self, marking: Mapping[str, int]) -> list[tuple[str, str]]:
        """The commands at ``marking`` after which every result is in Safe, ``(skillset, transition)``
        in the fixed order: those the ``strict`` check allows wherever no property is violated
        (docs/semantics.md §8; where one is, the check judges only the others, docs/semantics.md §5: tests/plan/test_answers.py)."""
        arena = self.arena(marking)
        local = arena.root
        out = []
        for action in arena.actions(local, None):
            if action.component is not None and action.move is not None and all(
                    arena.safe_at(r) for _, r in arena.post(local, action, None) if r is not None):
                out.append((arena.names[action.component], action.move.name))
        return out

    def mission(self, goals: Sequence[Goal], marking: Mapping[str, int] | None = None,
                budget: float | None = None) -> list[Plan]:
        """Plans for ``goals`` one after another, each from where the previous one's favourable
        path ends; stops after the first goal without a plan.  ``budget`` is per goal."""
        plans: list[Plan] = []
        here = dict(marking or self.system.initial_marking())
        for goal in goals:
            plan = self.plan(goal, here, budget)
            plans.append(plan)
            if plan.answer not in ("strong", "cyclic"):
                break
            here = plan.end or here
        return plans


class _Within(Deadline):
    """The caller's deadline, for a second search inside the same budget."""

    def __init__(self, outer: Deadline):
        super().__init__(getattr(outer, "at", None))
        self.outer = outer

    def expired(self) -> bool:
        self.hit = self.hit or self.outer.expired()
        return self.hit


class _Stop:
    """When the fixpoints stop: the deadline, or this process's resident memory past the limit (read once per
    fixpoint iteration, about 20 us; the BDDs of the symbolic engine are bounded this way only)."""

    def __init__(self, deadline: Deadline, memory_limit: int | None):
        self.deadline, self.memory_limit = deadline, memory_limit
        self.memory = False  # stopped by the memory limit

    def __call__(self) -> bool:
        if self.deadline.expired():
            return True
        self.memory = self.memory_limit is not None and resident_bytes() > self.memory_limit
        return self.memory


def _cut_short(markings: int, complete: bool, cut: str | None, stop: _Stop) -> str:
    searched = f"{markings} markings, complete" if complete else f"{markings} markings, exploration cut by the {cut}"
    if stop.memory:
        return (f"the memory limit ({(stop.memory_limit or 0) >> 20} MiB, the whole process) was reached before the "
                f"fixpoints ended ({searched})")
    return f"the budget ran out before the fixpoints ended ({searched})"


def _cudd() -> bool:
    from skinet.verify.symbolic import available

    return available()
