"""Firing rule, priorities and invariant cascades (docs/semantics.md §3, *Priority*).

Markings are bit masks (see :mod:`skinet.net.petrinet`).  A marking where an
invariant transition is enabled is *transient*; :func:`stable_successors`
collapses the cascade of invariant failures so callers only see *stable*
markings.
"""

from __future__ import annotations

from skinet.net.petrinet import PetriNet, Transition


def is_enabled(t: Transition, marking: int) -> bool:
    """Enabledness ignoring priorities."""
    return marking & t.pre_mask == t.pre_mask


def fire(t: Transition, marking: int) -> int:
    """Fire ``t`` (assumed enabled): consume ``pre``, produce ``post``."""
    return (marking & ~t.pre_mask) | t.post_mask


def enabled(net: PetriNet, marking: int) -> list[Transition]:
    """Transitions firable at ``marking`` under the net's priority relation."""
    on = [i for i, t in enumerate(net.transitions) if marking & t.pre_mask == t.pre_mask]
    if not net.priority:
        return [net.transitions[i] for i in on]
    blocked: set[int] = set()
    on_set = set(on)
    for high, low in net.priority:
        if not on_set.isdisjoint(high):
            blocked |= low
    return [net.transitions[i] for i in on if i not in blocked]


def invariants_enabled(net: PetriNet, marking: int) -> list[Transition]:
    """Invariant transitions enabled at ``marking`` (non-empty: transient)."""
    return [t for t in net.invariant_transitions if marking & t.pre_mask == t.pre_mask]


def is_stable(net: PetriNet, marking: int) -> bool:
    """A marking is stable when no invariant transition is enabled."""
    return not invariants_enabled(net, marking)


def stabilize(net: PetriNet, marking: int) -> frozenset[int]:
    """Every stable marking the invariant cascade from ``marking`` can end in.

    All orders of simultaneously enabled invariants are explored.  Each
    invariant firing stops one running skill, so the cascade terminates.
    """
    if not invariants_enabled(net, marking):  # the common case: already stable
        return frozenset((marking,))
    done: set[int] = set()
    result: set[int] = set()
    todo = [marking]
    while todo:
        m = todo.pop()
        if m in done:
            continue
        done.add(m)
        invs = invariants_enabled(net, m)
        if not invs:
            result.add(m)
        else:
            todo.extend(fire(t, m) for t in invs)
    return frozenset(result)


def stable_successors(net: PetriNet, marking: int, t: Transition) -> frozenset[int]:
    """Stable markings reached by one step: fire ``t`` then its invariant cascade."""
    return stabilize(net, fire(t, marking))


def steps(net: PetriNet, marking: int) -> list[tuple[Transition, frozenset[int]]]:
    """Every step from a stable ``marking``: each firable transition with its results."""
    return [(t, stable_successors(net, marking, t)) for t in enabled(net, marking)]
