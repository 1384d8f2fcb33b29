"""From a skillset model to its Petri net (docs/semantics.md §3).

Places: one per resource state (``R.s``), and per skill ``k`` an idle place
``e_k`` and a running place ``i_k``.  Transitions follow the table of docs/semantics.md §3:
events, starts, invariant failures, interrupts and success/failure modes, one
variant per guard clause and per combination of effect source states.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from itertools import product

from skinet.lang.dnf import Clause, dnf
from skinet.lang.expr import And, Const, Expr, Not
from skinet.lang.model import Effect, Skillset
from skinet.net.petrinet import Kind, PetriNet, Transition


def resource_place(resource: str, state: str) -> str:
    return f"{resource}.{state}"


def idle_place(skill: str) -> str:
    return f"e_{skill}"


def running_place(skill: str) -> str:
    return f"i_{skill}"


@dataclass(frozen=True)
class _Spec:
    """A logical transition before expansion into variants."""

    name: str
    kind: Kind
    skill: str | None
    element: str | None
    guard: list[Clause]
    effects: dict[str, str]
    postcondition: list[Clause] | None  # None: no postcondition
    apply_illegal: bool  # False: an illegal move voids the transition


def build_net(skillset: Skillset, eventless: bool = False, commanded: frozenset[str] = frozenset(),
              without: frozenset[str] = frozenset()) -> PetriNet:
    """The full net ``SkN`` of ``skillset`` or, with ``eventless``, ``SkN^e``.

    Invariant transitions get priority over every other transition (one
    priority pair).  Variants of one logical transition are numbered in
    generation order: ``name``, ``name#2``, ...  The events named in
    ``commanded`` are controllable (a binding's commanded resources, docs/semantics.md §9);
    those named in ``without`` are left out.
    """
    states = {r.name: r.states for r in skillset.resources}
    places: list[str] = []
    for r in skillset.resources:
        places.extend(resource_place(r.name, s) for s in r.states)
    for k in skillset.skills:
        places.extend((idle_place(k.name), running_place(k.name)))
    index = {p: i for i, p in enumerate(places)}

    transitions: list[Transition] = []
    for spec in _specs(skillset, states, eventless):
        if spec.kind == "event" and spec.name in without:
            continue
        seen: set[tuple[frozenset[int], frozenset[int]]] = set()
        for pre, post in _variants(spec, skillset, states):
            pre_i = frozenset(index[p] for p in pre)
            post_i = frozenset(index[p] for p in post)
            if (pre_i, post_i) in seen:
                continue
            seen.add((pre_i, post_i))
            tid = spec.name if len(seen) == 1 else f"{spec.name}#{len(seen)}"
            transitions.append(
                Transition(tid, spec.name, spec.kind, pre_i, post_i, skillset.name, spec.skill, spec.element,
                           spec.kind == "event" and spec.name in commanded)
            )

    initial = {resource_place(r.name, r.initial) for r in skillset.resources}
    initial |= {idle_place(k.name) for k in skillset.skills}
    high = frozenset(i for i, t in enumerate(transitions) if t.is_invariant)
    low = frozenset(range(len(transitions))) - high
    priority = ((high, low),) if high and low else ()
    name = f"{skillset.name}_eventless" if eventless else skillset.name
    return PetriNet(
        name, tuple(places), tuple(transitions), sum(1 << index[p] for p in initial), priority
    )


def _effects(effects: Iterable[Effect]) -> dict[str, str]:
    # A later effect on the same resource wins, as an assignment would.
    return {e.resource: e.state for e in effects}


def _specs(skillset: Skillset, states: Mapping[str, tuple[str, ...]], eventless: bool) -> Iterator[_Spec]:
    if not eventless:
        for ev in skillset.events:
            yield _Spec(ev.name, "event", None, ev.name, dnf(ev.guard, states), _effects(ev.effects), None, False)
    for k in skillset.skills:
        pre: Expr = Const(True)
        for p in k.preconditions:
            pre = And(pre, p.expr)
        yield _Spec(f"{k.name}.start", "start", k.name, None, dnf(pre, states), _effects(k.start), None, False)
        for inv in k.invariants:
            yield _Spec(
                f"{k.name}.inv.{inv.name}", "invariant", k.name, inv.name,
                dnf(Not(inv.guard), states), _effects(inv.effects), None, True,
            )
        it = k.interrupt
        yield _Spec(
            f"{k.name}.interrupt", "interrupt", k.name, None, [{}], _effects(it.effects),
            None if it.postcondition is None else dnf(it.postcondition, states), True,
        )
        for mode in k.modes:
            name = f"{k.name}.{mode.kind}.{mode.name}" if mode.name else f"{k.name}.{mode.kind}"
            yield _Spec(
                name, mode.kind, k.name, mode.name, [{}], _effects(mode.effects),
                None if mode.postcondition is None else dnf(mode.postcondition, states), True,
            )


def _variants(
    spec: _Spec, skillset: Skillset, states: Mapping[str, tuple[str, ...]]
) -> Iterator[tuple[list[str], list[str]]]:
    """Yield ``(pre places, post places)`` for every variant of ``spec``."""
    skill_pre: list[str] = []
    skill_post: list[str] = []
    if spec.kind == "start":
        skill_pre, skill_post = [idle_place(spec.skill or "")], [running_place(spec.skill or "")]
    elif spec.skill is not None:
        skill_pre, skill_post = [running_place(spec.skill)], [idle_place(spec.skill)]
    # An unsatisfiable postcondition moves nothing: the skill still stops.
    post_clauses: list[Clause] = spec.postcondition or [{}]
    for clause in spec.guard:
        for post_clause in post_clauses:
            moved = [r for r in states if r in spec.effects or r in post_clause]
            choices = [[clause[r]] if r in clause else list(states[r]) for r in moved]
            for sources in product(*choices):
                src = dict(zip(moved, sources))
                legal = all(skillset.resource(r).allows(src[r], t) for r, t in spec.effects.items())
                if not legal and not spec.apply_illegal:
                    continue
                pre = list(skill_pre)
                post = list(skill_post)
                for r in states:
                    if r in src:
                        target = src[r]
                        if legal and r in spec.effects:
                            target = spec.effects[r]
                        target = post_clause.get(r, target)
                        pre.append(resource_place(r, src[r]))
                        post.append(resource_place(r, target))
                    elif r in clause:
                        pre.append(resource_place(r, clause[r]))
                        post.append(resource_place(r, clause[r]))
                yield pre, post
