"""Disjunctive normal form of skillset guards (docs/semantics.md §3, *Guards*).

A clause is a mapping ``resource -> state``: the conjunction of ``R == s`` atoms.
``R != s`` expands to the other states of ``R``, ``a => b`` is ``not a or b``,
contradictory clauses (two states of one resource) are dropped, and duplicate
clauses are kept once, in first-seen order.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from skinet.errors import SkinetError
from skinet.lang.expr import And, Const, Expr, Implies, Not, Or, StateAtom

Clause = dict[str, str]


class TooManyClauses(SkinetError):
    """A disjunctive normal form exceeded the clause limit it was computed with."""


def dnf(expr: Expr | None, states: Mapping[str, Sequence[str]], limit: int | None = None) -> list[Clause]:
    """Clauses of ``expr``; ``None`` (no guard) is ``true``, i.e. ``[{}]``.

    ``states`` maps each resource name to its states (needed to expand ``!=``).
    The result is empty exactly when ``expr`` is unsatisfiable.  Worst case
    exponential in the number of ``or`` under ``and``, as DNF must be; with a
    ``limit``, raises :class:`TooManyClauses` as soon as an intermediate result
    holds more clauses, so the cost is at most O(size x limit^2).
    """
    if expr is None:
        return [{}]
    out: list[Clause] = []
    seen: set[frozenset[tuple[str, str]]] = set()
    for clause in _dnf(expr, True, states, limit):
        key = frozenset(clause.items())
        if key not in seen:
            seen.add(key)
            out.append(clause)
    return out


def _dnf(expr: Expr, positive: bool, states: Mapping[str, Sequence[str]], limit: int | None) -> list[Clause]:
    if isinstance(expr, Const):
        return [{}] if expr.value == positive else []
    if isinstance(expr, StateAtom):
        if positive:
            return [{expr.resource: expr.state}]
        return [{expr.resource: s} for s in states[expr.resource] if s != expr.state]
    if isinstance(expr, Not):
        return _dnf(expr.arg, not positive, states, limit)
    if isinstance(expr, Implies):
        return _dnf(Or(Not(expr.left), expr.right), positive, states, limit)
    if isinstance(expr, (And, Or)):
        conjunctive = isinstance(expr, And) == positive
        left = _dnf(expr.left, positive, states, limit)
        right = _dnf(expr.right, positive, states, limit)
        if not conjunctive:
            out = left + right
        else:
            out = [c for a in left for b in right if (c := _merge(a, b)) is not None]
        if limit is not None and len(out) > limit:
            raise TooManyClauses(f"more than {limit} clauses")
        return out
    raise TypeError(f"not a skillset expression: {expr!r}")


def _merge(a: Clause, b: Clause) -> Clause | None:
    """Conjunction of two clauses, or ``None`` when they contradict."""
    merged = dict(a)
    for resource, state in b.items():
        if merged.setdefault(resource, state) != state:
            return None
    return merged
