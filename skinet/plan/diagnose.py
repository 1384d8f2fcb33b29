"""Why there is no plan (docs/semantics.md §8: the reasons of a ``none`` answer).

Asked only after a complete search found the start marking outside ``W_c``.
The reasons, first that applies:

1. no marking reachable from the start satisfies the goal (a ``run`` goal: its
   skill never runs from here);
2. the goal is unsafe: every marking where it holds is forced for a property
   (violated at once, or by skill outcomes alone), named with an example;
3. a skill the plan needs has inputs the goal does not give: with every start
   allowed, a plan exists, and its policy starts that skill;
4. every way to the goal crosses a forced marking (docs/semantics.md §6.3): no safe way
   exists (the weak fixpoint ``E`` misses the start); the shortest way over all
   moves is shown up to its first move into a marking forced for a property;
5. outcomes can lead away from the goal for good (the start is in ``E`` but not
   in ``W_c``): on the shortest safe way to the goal, the last marking outside
   ``W_c`` has its move's other results, one of them outside ``W_c`` (else that
   marking would be in ``W_c``); that result is named, and whether a safe way
   still leads on from it.

Paths come from breadth-first rings of pre-images towards the set sought,
then one walk forward from the start through the rings, taking the first
move (fixed order) into the next ring.  Cost: at most one ring per move of
the shortest path, each a pre-image (one pass over the game).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from skinet.verify import explain
from skinet.plan.arena import DONE, WAIT, Arena, Local
from skinet.plan.goal import Goal
from skinet.plan.inputs import missing
from skinet.plan.policy import Command, Plan, Stats
from skinet.plan.solve import Expired, cyclic, strong, weak
from skinet.verify.forced import oracle

GameFactory = Callable[[bool], Any]  # relaxed -> game


def diagnose(arena: Arena, goal: Goal, game: Any, relaxed_game: GameFactory, expired: Expired) -> str:
    """The reason why ``goal`` has no plan from ``arena.root``; ``game`` is the goal's game."""
    start = arena.root
    if game.empty(game.goal_markings):
        if goal.kind == "run":
            return f"{goal.skillset}:{goal.skill} never runs from here: no reachable marking lets it start"
        return "no marking reachable from here satisfies it"
    if game.empty(game.goal_markings & game.safe):
        example = game.pick(game.goal_markings)
        where = (f"every marking where {goal.skillset}:{goal.skill} can succeed" if goal.kind == "run"
                 else "every marking where it holds")
        return f"the goal is unsafe: {where} is forced for {_forced_words(arena, example)}"
    relaxed = relaxed_game(True)
    region = None
    for solve in (strong, cyclic):
        layers = solve(relaxed, expired)
        if layers is None:
            return _late()
        region = layers[-1]
        if relaxed.member(layers[-1], start):
            return _inputs_reason(arena, goal, relaxed, layers, "strong" if solve is strong else "cyclic")
    way = weak(relaxed, expired)
    if way is None:
        return _late()
    safely = relaxed.member(way[-1], start)
    path = _shortest(arena, goal, relaxed, game.goal_markings & game.safe, safely, expired)
    if path is None:
        return _late()
    if not safely:
        for n, (label, before, post) in enumerate(path):
            bad = [r for _, r in post if r is not DONE and not arena.safe_at(r)]
            if bad:
                shown = ", ".join(label for label, *_ in path[:n + 1])
                return (f"every way to it crosses a forced marking: the shortest, {shown}, may lead to one forced "
                        f"for {_forced_words(arena, bad[0], {label.split(':', 1)[0]})}")
        return "every way to it crosses a forced marking"
    if goal.kind == "run":  # the last move is waiting for the goal's outcome
        last = _after(path[-1]) if path else start
        path.append((_target_label(arena, goal, last), last, arena.post(last, WAIT, goal)))
    # The last marking of the way outside W_c has a move with a result outside W_c (else it would be in W_c).
    for n in range(len(path) - 1, -1, -1):
        label, before, post = path[n]
        if relaxed.member(region, before):
            continue
        away = [(other, r) for other, r in post if r is not DONE and not relaxed.member(region, r)]
        if away:
            other, r = away[0]
            shown = ", ".join(step[0] for step in path[:n + 1])
            dead = "no safe way" if not relaxed.member(way[-1], r) else "no plan"
            return (f"outcomes can lead away from it for good: on the shortest safe way ({shown}), {other} may come "
                    f"instead, and {dead} reaches the goal from there")
    return "outcomes can lead where no plan reaches it any more"


def _after(step: tuple[str, Local, list[tuple[str, Local | None]]]) -> Local:
    """The marking a path step leads to (its first result named by its label)."""
    label, _, post = step
    return next(r for name, r in post if name == label and r is not DONE)


def _target_label(arena: Arena, goal: Goal, local: Local) -> str:
    i = arena.names.index(goal.skillset)
    return next(f"{goal.skillset}:{mv.name}" for mv in arena.games[i].outcomes[local[i]]
                if goal.target(goal.skillset, mv.name))


def _inputs_reason(arena: Arena, goal: Goal, relaxed: Any, layers: list[Any], answer: str) -> str:
    """A plan exists once every start is allowed: name the starts it makes that lack inputs."""
    plan = Plan(goal, arena, arena.root, answer, None, Stats("", 0, True, None, 0.0), relaxed, layers)  # type: ignore[arg-type]
    plan._allowed = arena.enabled(goal, relaxed=True)
    needed: list[str] = []
    for _, action, _ in plan.policy()[0]:
        if isinstance(action, Command) and action.transition.endswith(".start"):
            skill = arena.system.component(action.skillset).skillset.skill(action.transition[:-len(".start")])
            lacking = missing(skill, goal.given(action.skillset, skill.name))
            if lacking:
                needed.append(f"{action.skillset}:{skill.name} (input {', '.join(v.name for v in lacking)})")
    return "a skill the plan needs has inputs the goal does not give: " + ", ".join(dict.fromkeys(needed))


def _late() -> str:
    return ("no plan exists (the search was complete); the budget or the memory limit ran out before the reason "
            "was found")


def _forced_words(arena: Arena, local: Local, moved: set[str] | None = None, every: bool = False) -> str:
    """``safety_guard (it is violated at once: ...)`` for the first property ``local`` is forced for
    (``every``: for each of them, joined by ``; ``)."""
    system = arena.system
    marking = arena.marking(local)
    forced = arena.forced_for(local)
    out = []
    for name in forced if every else forced[:1]:
        prop = system.property(name)
        verdict = oracle(system, arena.events).verdict(prop, marking)
        if verdict is None or verdict.steps == 0:
            first, rest = explain.violation_words(system, prop, marking, moved or set())
            out.append(f"{prop.name} (violated there: {' while '.join(first + rest)})")
        else:
            out.append(f"{prop.name} ({explain.forced_reason(system, prop, verdict.witness, verdict.reached)})")
    return "; ".join(out)


def _shortest(arena: Arena, goal: Goal, game: Any, target: Any, allowed: bool,
              expired: Expired) -> list[tuple[str, Local, list[tuple[str, Local | None]]]] | None:
    """The fewest moves from the start into ``target`` (``allowed``: moves of A(m) only), each as
    ``(move, from, every result of the action with its transition)``; None when the deadline passes
    or none exists."""
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
        path.append(step[:3])
        local = step[3]
    return path


def _step_into(arena: Arena, goal: Goal, game: Any, local: Local, ring: Any, allowed: bool
               ) -> tuple[str, Local, list[tuple[str, Local | None]], Local] | None:
    """The first action at ``local`` (the policy's order) with a result in ``ring``: its move, ``local``,
    its results (waiting: every outcome's) and the result taken."""
    masks = arena.enabled(goal, relaxed=True)
    for action in arena.actions(local, masks):
        post = arena.post(local, action, goal if action is WAIT else None)
        if allowed and action is not WAIT and not all(arena.safe_at(r) for _, r in post if r is not DONE):
            continue
        for label, r in post:
            if r is not DONE and game.member(ring, r):
                return label, local, post, r
    return None
