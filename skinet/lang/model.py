"""Typed objects for a parsed skillset model (docs/semantics.md §2).

Built by :mod:`skinet.lang.parser`; every element keeps its source position so
later stages can report ``FILE:LINE:COL`` errors.  Objects are immutable.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from skinet.errors import Diagnostic, Pos
from skinet.lang.expr import Expr


@dataclass(frozen=True)
class TypeDecl:
    name: str
    pos: Pos | None = None


@dataclass(frozen=True)
class Variable:
    """A typed field: data, parameter, skill input/output, progress message field.

    ``period_seconds`` is a data field's publication period, when declared.
    """

    name: str
    type: str
    pos: Pos | None = None
    type_pos: Pos | None = None
    period_seconds: float | None = None


@dataclass(frozen=True)
class Resource:
    """A finite-state resource; ``transitions is None`` means ``transition all``."""

    name: str
    states: tuple[str, ...]
    initial: str
    transitions: tuple[tuple[str, str], ...] | None
    pos: Pos | None = None
    initial_pos: Pos | None = None
    state_pos: tuple[Pos | None, ...] = ()
    transition_pos: tuple[Pos | None, ...] = ()
    # Position of each transition's target state (``transition_pos`` is the source's).
    transition_target_pos: tuple[Pos | None, ...] = ()

    def allows(self, source: str, target: str) -> bool:
        """Legality of a move (docs/semantics.md §3): identity, ``transition all``, or declared."""
        if source == target:
            return True
        if self.transitions is None:
            return True
        return (source, target) in self.transitions


@dataclass(frozen=True)
class Effect:
    """``resource -> state``."""

    resource: str
    state: str
    pos: Pos | None = None
    state_pos: Pos | None = None


@dataclass(frozen=True)
class Event:
    name: str
    guard: Expr | None
    effects: tuple[Effect, ...]
    pos: Pos | None = None


@dataclass(frozen=True)
class Precondition:
    name: str
    expr: Expr
    pos: Pos | None = None


@dataclass(frozen=True)
class Invariant:
    name: str
    guard: Expr
    effects: tuple[Effect, ...]
    pos: Pos | None = None


@dataclass(frozen=True)
class Progress:
    period_seconds: float
    fields: tuple[Variable, ...]
    pos: Pos | None = None


@dataclass(frozen=True)
class Interrupt:
    """Every skill has one; ``declared`` is false when the model omits it."""

    interrupting: bool = False
    effects: tuple[Effect, ...] = ()
    postcondition: Expr | None = None
    declared: bool = False
    pos: Pos | None = None


@dataclass(frozen=True)
class Mode:
    """A success or failure mode.  An unnamed mode has ``name == ""``."""

    name: str
    kind: Literal["success", "failure"]
    effects: tuple[Effect, ...] = ()
    postcondition: Expr | None = None
    pos: Pos | None = None


@dataclass(frozen=True)
class Skill:
    name: str
    parameters: tuple[Variable, ...] = ()
    inputs: tuple[Variable, ...] = ()
    outputs: tuple[Variable, ...] = ()
    preconditions: tuple[Precondition, ...] = ()
    start: tuple[Effect, ...] = ()
    invariants: tuple[Invariant, ...] = ()
    progress: Progress | None = None
    interrupt: Interrupt = field(default_factory=Interrupt)
    successes: tuple[Mode, ...] = ()
    failures: tuple[Mode, ...] = ()
    pos: Pos | None = None

    @property
    def modes(self) -> tuple[Mode, ...]:
        return self.successes + self.failures


@dataclass(frozen=True)
class Skillset:
    name: str
    resources: tuple[Resource, ...] = ()
    events: tuple[Event, ...] = ()
    skills: tuple[Skill, ...] = ()
    data: tuple[Variable, ...] = ()
    parameters: tuple[Variable, ...] = ()
    type_params: tuple[str, ...] = ()
    types: tuple[TypeDecl, ...] = ()
    source: str = "<string>"
    pos: Pos | None = None

    def resource(self, name: str) -> Resource:
        for r in self.resources:
            if r.name == name:
                return r
        raise KeyError(name)

    def skill(self, name: str) -> Skill:
        for s in self.skills:
            if s.name == name:
                return s
        raise KeyError(name)

    def event(self, name: str) -> Event:
        for e in self.events:
            if e.name == name:
                return e
        raise KeyError(name)


@dataclass(frozen=True)
class Model:
    """Everything one ``.rl`` file declares, plus the warnings validation gave.

    ``includes`` are the ``include "file"`` lines, with their positions; the core
    does no I/O, :func:`skinet.system.load.load_model` resolves them.
    """

    source: str
    types: tuple[TypeDecl, ...]
    skillsets: tuple[Skillset, ...]
    warnings: tuple[Diagnostic, ...] = ()
    includes: tuple[tuple[str, Pos | None], ...] = ()
