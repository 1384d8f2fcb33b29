"""Why there is no plan (SPEC §8: the reasons of a ``none`` answer).

Asked only after a complete search found the start marking outside ``W_c``.
The reasons, first that applies:

1. no marking reachable from the start satisfies the goal (a ``run`` goal: its
   skill never runs from here);
2. the goal is unsafe: every marking where it holds is forced for a property
   (violated at once, or by skill outcomes alone), named with an example;
3. a skill the plan needs has inputs the goal does not give: with every start
   allowed, a plan exists, and its policy starts that skill;
4. every way to the goal crosses a forced marking (SPEC §6.3): no safe way
   exists (the weak fixpoint ``E`` misses the start); the shortest way over all
   moves is shown up to its first move into a marking forced for a property;
5. outcomes can lead where no safe way reaches the goal any more (the start is
   in ``E`` but not in ``W_c``): the shortest safe way to such a marking is shown.

Paths come from breadth-first rings of pre-images towards the set sought,
then one walk forward from the start through the rings, taking the first
move (fixed order) into the next ring.  Cost: at most one ring per move of
the shortest path, each a pre-image (one pass over the game).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from skinet import explain
from skinet.plan.arena import Arena, Local
from skinet.plan.goal import Goal
from skinet.plan.inputs import missing
from skinet.plan.solve import Expired, cyclic, strong, weak
from skinet.verify.forced import oracle

GameFactory = Callable[[bool], Any]  # relaxed -> game


def diagnose(arena: Arena, goal: Goal, game: Any, relaxed_game: GameFactory, expired: Expired) -> str:
    """The reason why ``goal`` has no plan from ``arena.root``; ``game`` is the goal's game."""
    start = arena.root
    system = arena.system
    if game.empty(game.goal_markings):
        if goal.kind == "run":
            return f"{goal.skillset}:{goal.skill} never runs from here: no reachable marking lets it start"
        return "no marking reachable from here satisfies it"
    if game.empty(game.goal_markings & game.safe):
        example = game.pick(game.goal_markings)
        where = "wherever it can succeed" if goal.kind == "run" else "every marking where it holds"
        return f"the goal is unsafe: {where} is forced for {_forced_words(arena, example)}"
    relaxed = relaxed_game(True)
    for solve in (strong, cyclic):
        layers = solve(relaxed, expired)
        if layers is None:
            return _late()
        if relaxed.member(layers[-1], start):
            from skinet.plan.policy import Command, Plan, Stats  # a plan, once: no cycle at import

            plan = Plan(goal, arena, start, "strong" if solve is strong else "cyclic", None,
                        Stats("", 0, True, None, 0.0), relaxed, layers)
            plan._allowed = arena.enabled(goal, relaxed=True)
            needed: list[str] = []
            for _, action, _ in plan.policy()[0]:
                if isinstance(action, Command) and action.transition.endswith(".start"):
                    skill = system.component(action.skillset).skillset.skill(action.transition[:-len(".start")])
                    lacking = missing(skill, goal.given(action.skillset, skill.name))
                    if lacking:
                        needed.append(f"{action.skillset}:{skill.name} (input {', '.join(v.name for v in lacking)})")
            if needed:
                return ("a skill the plan needs has inputs the goal does not give: "
                        + ", ".join(dict.fromkeys(needed)))
            break
    way = weak(relaxed, expired)
    if way is None:
        return _late()
    if not relaxed.member(way[-1], start):
        path = _shortest(arena, goal, relaxed, game.goal_markings & game.safe, False, expired)
        if path is None:
            return _late()
        for n, (label, before, after, results) in enumerate(path):
            bad = [r for r in results if not arena.safe_at(r)]
            if bad:
                shown = ", ".join(label for label, *_ in path[:n + 1])
                return (f"every way to it crosses a forced marking: the shortest, {shown}, may reach one forced "
                        f"for {_forced_words(arena, bad[0], {label.split(':', 1)[0]})}")
        return "every way to it crosses a forced marking"
    dead = game.safe & ~way[-1]
    path = _shortest(arena, goal, relaxed, dead, True, expired)
    if path is None:
        return _late()
    shown = ", ".join(label for label, *_ in path)
    return ("outcomes can lead where no safe way reaches the goal any more"
            + (f": {shown} leads to such a marking" if shown else ""))


def _late() -> str:
    return "no plan exists (the search was complete); the budget ran out before the reason was found"


def _forced_words(arena: Arena, local: Local, moved: set[str] | None = None) -> str:
    """``safety_guard (it is violated at once: ...)`` for the first property ``local`` is forced for."""
    system = arena.system
    marking = arena.marking(local)
    prop = system.property(arena.forced_for(local)[0])
    verdict = oracle(system, arena.events).verdict(prop, marking)
    if verdict is None or verdict.steps == 0:
        first, rest = explain.violation_words(system, prop, marking, moved or set())
        return f"{prop.name} (violated there: {' while '.join(first + rest)})"
    return f"{prop.name} ({explain.forced_reason(system, prop, verdict.witness, verdict.reached)})"


def _shortest(arena: Arena, goal: Goal, game: Any, target: Any, allowed: bool,
              expired: Expired) -> list[tuple[str, Local, Local, list[Local]]] | None:
    """The fewest moves from the start into ``target`` (``allowed``: moves of A(m) only), as
    ``(move, from, to, every result of the move)``; None when the deadline passes or none exists."""
    rings = [target]
    reached = target
    start = arena.root
    while not game.member(reached, start):
        if expired():
            return None
        grown = reached | game.preimage(reached, allowed)
        if game.same(grown, reached):
            return None
        rings.append(grown)
        reached = grown
    local = start
    path = []
    for ring in reversed(rings[:-1]):
        if game.member(ring, local):
            continue
        step = _step_into(arena, goal, game, local, ring, allowed)
        if step is None:
            return None
        path.append(step)
        local = step[2]
    return path


def _step_into(arena: Arena, goal: Goal, game: Any, local: Local, ring: Any,
               allowed: bool) -> tuple[str, Local, Local, list[Local]] | None:
    """The first move from ``local`` with a result in ``ring``: commands in order, then outcomes."""
    masks = arena.enabled(goal, relaxed=True) if allowed else None
    for i, g in enumerate(arena.games):
        for mv in g.commands[local[i]]:
            results = [local[:i] + (r,) + local[i + 1:] for r in mv.results]
            if allowed and (not all(arena.safe_at(r) for r in results)
                            or masks is not None and not masks[i][g.command_names.index(mv.name)]):
                continue
            for r in results:
                if game.member(ring, r):
                    return f"{g.name}:{mv.name}", local, r, results
    for i, g in enumerate(arena.games):
        for mv in g.outcomes[local[i]]:
            results = [local[:i] + (r,) + local[i + 1:] for r in mv.results]
            for r in results:
                if game.member(ring, r):
                    return f"{g.name}:{mv.name}", local, r, results
    return None
