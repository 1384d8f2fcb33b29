"""Property and CTL formula objects (docs/semantics.md §4, §6).

Boolean structure reuses :mod:`skinet.lang.expr`; atoms are resolved to one
place of one skillset net.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from skinet.errors import Pos
from skinet.lang.expr import And, Expr, Implies, Not, Or


@dataclass(frozen=True)
class PlaceAtom:
    """True when ``place`` of ``skillset`` is marked; ``text`` is how it was written."""

    skillset: str
    place: str
    text: str = field(default="", compare=False)
    pos: Pos | None = field(default=None, compare=False)

    def __str__(self) -> str:
        return self.text or f"{self.skillset}:{self.place}"


TemporalOp = Literal["EX", "AX", "EF", "AF", "EG", "AG"]


@dataclass(frozen=True)
class Temporal:
    op: TemporalOp
    arg: Expr
    pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Until:
    """``E[left U right]`` or ``A[left U right]``."""

    quantifier: Literal["E", "A"]
    left: Expr
    right: Expr
    pos: Pos | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Property:
    """A named safety property ``name = expr``; ``text`` is the source expression."""

    name: str
    expr: Expr
    text: str
    pos: Pos | None = None


def is_temporal(expr: Expr) -> bool:
    """True when ``expr`` uses a CTL operator anywhere (it is not a state formula)."""
    if isinstance(expr, (Temporal, Until)):
        return True
    if isinstance(expr, Not):
        return is_temporal(expr.arg)
    if isinstance(expr, (And, Or, Implies)):
        return is_temporal(expr.left) or is_temporal(expr.right)
    return False
