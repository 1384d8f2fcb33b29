"""Boolean expressions shared by skillset guards and safety properties (docs/semantics.md §2, §4).

Atoms are left abstract: a skillset guard uses :class:`StateAtom` (``R == s``),
the property language uses its own atoms.  Precedence in both languages is
``=>`` < ``or`` < ``and`` < ``not``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Union

from skinet.errors import Pos


@dataclass(frozen=True)
class Const:
    value: bool
    pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class StateAtom:
    """``resource == state`` (``resource != state`` is ``Not(StateAtom)``)."""

    resource: str
    state: str
    pos: Pos | None = field(default=None, compare=False)
    state_pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Not:
    arg: "Expr"
    pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class And:
    left: "Expr"
    right: "Expr"
    pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Or:
    left: "Expr"
    right: "Expr"
    pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Implies:
    left: "Expr"
    right: "Expr"
    pos: Pos | None = field(default=None, compare=False)


# Any frozen dataclass can serve as an atom (StateAtom for skillsets, property atoms).
Expr = Union[Const, Not, And, Or, Implies, object]


def atoms(expr: Expr) -> list[object]:
    """Every atom of ``expr``, left to right, with repetitions."""
    if isinstance(expr, Const):
        return []
    if isinstance(expr, Not):
        return atoms(expr.arg)
    if isinstance(expr, (And, Or, Implies)):
        return atoms(expr.left) + atoms(expr.right)
    return [expr]


def holds(expr: Expr | None, resources: Mapping[str, str]) -> bool:
    """Truth of a skillset guard on resource states (``None``: no guard, true); one pass over the expression."""
    if expr is None:
        return True
    if isinstance(expr, Const):
        return expr.value
    if isinstance(expr, StateAtom):
        return resources.get(expr.resource) == expr.state
    if isinstance(expr, Not):
        return not holds(expr.arg, resources)
    if isinstance(expr, And):
        return holds(expr.left, resources) and holds(expr.right, resources)
    if isinstance(expr, Or):
        return holds(expr.left, resources) or holds(expr.right, resources)
    if isinstance(expr, Implies):
        return not holds(expr.left, resources) or holds(expr.right, resources)
    raise TypeError(f"not a skillset guard: {expr!r}")


def to_text(expr: Expr) -> str:
    """Render ``expr`` in the concrete syntax, fully parenthesised below the top."""
    if isinstance(expr, Const):
        return "true" if expr.value else "false"
    if isinstance(expr, StateAtom):
        return f"{expr.resource} == {expr.state}"
    if isinstance(expr, Not):
        if isinstance(expr.arg, StateAtom):
            return f"{expr.arg.resource} != {expr.arg.state}"
        return f"not {_wrap(expr.arg)}"
    if isinstance(expr, And):
        return f"{_wrap(expr.left)} and {_wrap(expr.right)}"
    if isinstance(expr, Or):
        return f"{_wrap(expr.left)} or {_wrap(expr.right)}"
    if isinstance(expr, Implies):
        return f"{_wrap(expr.left)} => {_wrap(expr.right)}"
    return str(expr)


def _wrap(expr: Expr) -> str:
    text = to_text(expr)
    return f"({text})" if isinstance(expr, (And, Or, Implies)) else text
