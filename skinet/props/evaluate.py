"""Evaluation of state formulas on combined markings (docs/semantics.md §4, ``safe(phi, m)``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or
from skinet.net.petrinet import PetriNet
from skinet.props.formula import PlaceAtom


def evaluate(expr: Expr, atom: Callable[[PlaceAtom], Any], const: Callable[[bool], Any] | None = None) -> Any:
    """Evaluate a boolean formula; ``atom`` gives each atom's value, ``const`` each constant's
    (default: the Python bool).

    Values are Python bools, numpy boolean arrays (evaluated over many markings
    at once, broadcasting as numpy does) or anything with ``~``, ``&`` and ``|``
    such as decision diagrams (then ``const`` gives their true and false).
    """
    if isinstance(expr, Const):
        return expr.value if const is None else const(expr.value)
    if isinstance(expr, PlaceAtom):
        return atom(expr)
    if isinstance(expr, Not):
        v = evaluate(expr.arg, atom, const)
        return (not v) if isinstance(v, bool) else ~v
    if isinstance(expr, And):
        return evaluate(expr.left, atom, const) & evaluate(expr.right, atom, const)
    if isinstance(expr, Or):
        return evaluate(expr.left, atom, const) | evaluate(expr.right, atom, const)
    if isinstance(expr, Implies):
        left = evaluate(expr.left, atom, const)
        return evaluate(expr.right, atom, const) | ((not left) if isinstance(left, bool) else ~left)
    raise TypeError(f"not a state formula: {expr!r}")


def holds(expr: Expr, marking: Mapping[str, int], nets: Mapping[str, PetriNet]) -> bool:
    """``safe(expr, marking)``: ``marking`` maps each skillset to its bit-mask marking."""
    return bool(evaluate(expr, lambda a: bool(marking[a.skillset] >> nets[a.skillset].place_index(a.place) & 1)))
