"""Parser of the skillset language (docs/semantics.md §2).

``parse_model`` turns the text of a ``.rl`` file into a :class:`~skinet.lang.model.Model`,
validates it (:mod:`skinet.lang.validate`) and raises :class:`~skinet.errors.SourceError`
with ``FILE:LINE:COL: error: ...`` diagnostics on any syntax or validation error.
The grammar (``skillset.lark``) accepts every dialect listed in docs/semantics.md §2.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache
from pathlib import Path
from collections.abc import Sequence
from typing import Any, NamedTuple

from lark import Lark, Token, Transformer, UnexpectedInput
from lark.exceptions import VisitError

from skinet.errors import Diagnostic, Pos, SourceError
from skinet.lang.expr import And, Const, Expr, Implies, Not, Or, StateAtom
from skinet.lang.model import (
    Effect,
    Event,
    Interrupt,
    Invariant,
    Mode,
    Model,
    Precondition,
    Progress,
    Resource,
    Skill,
    Skillset,
    TypeDecl,
    Variable,
)
from skinet.lang.larkcache import cached_lark
from skinet.lang.larkerrors import check_nesting, check_size, syntax_diagnostic
from skinet.lang.validate import sort_diagnostics, validate

__all__ = ["parse_model", "parse_skillset", "parse_unit", "link"]

_GRAMMAR_PATH = Path(__file__).with_name("skillset.lark")

# Seconds per unit of a progress period (docs/semantics.md §2: `1 sec`, `100 ms`, bare `1.0`).
_UNIT_DIVISOR = {"sec": 1.0, "s": 1.0, "ms": 1000.0}

# Tree nodes that nest an expression one level deeper (see check_nesting).
_OPERATORS = frozenset({"not_", "and_", "or_", "implies"})



@lru_cache(maxsize=2)
def _parser(start: str = "start") -> Lark:
    """The grammar, loaded once per start rule (LALR, contextual lexer, positions propagated).

    ``start`` is a file given to a command, ``library`` a file it includes.
    """
    return cached_lark(
        _GRAMMAR_PATH,
        start=start,
        parser="lalr",
        lexer="contextual",
        propagate_positions=True,
        maybe_placeholders=False,
    )


def parse_model(text: str, source: str = "<string>") -> Model:
    """Parse and validate a whole ``.rl`` file (docs/semantics.md §2).

    Raises :class:`SourceError` carrying every error, sorted by position; on success
    the returned model's ``warnings`` hold the validation warnings.  ``include``
    lines are recorded, not followed (see :func:`skinet.system.load.load_model`).
    """
    return link([parse_unit(text, source)])


Unit = tuple[Model, list[Diagnostic]]


def parse_unit(text: str, source: str, library: bool = False) -> Unit:
    """The syntax and structure of one file, not yet validated (see :func:`link`).

    A ``library`` (a file named by an ``include``) may declare no skillset, and
    its syntax errors quote none of its text.  Raises :class:`SourceError` on a
    syntax error.  Cost: linear in the text.
    """
    check_size(text, source)
    parser = _parser("library" if library else "start")
    try:
        tree = parser.parse(text)
    except UnexpectedInput as exc:
        raise SourceError([syntax_diagnostic(parser, exc, text, source, quote=not library)]) from None
    check_nesting(tree, _OPERATORS, source)
    builder = _Builder(source)
    try:
        model: Model = builder.transform(tree)
    except VisitError as exc:  # pragma: no cover - only on a bug in the builder
        if isinstance(exc.orig_exc, SourceError):
            raise exc.orig_exc from None
        raise
    return model, builder.errors


def link(units: Sequence[Unit]) -> Model:
    """Validate files together as one model: the first one and those it includes.

    Every skillset sees the types of every file.  Raises :class:`SourceError`
    carrying every error; the model's ``warnings`` hold the rest.
    """
    main = units[0][0]
    types = tuple(t for model, _ in units for t in model.types)
    diagnostics: list[Diagnostic] = []
    first: dict[str, Skillset] = {}
    for model, found in units:
        own = tuple(dataclasses.replace(s, types=types) for s in model.skillsets)
        diagnostics += found + validate(dataclasses.replace(model, skillsets=own))
        for s in own:
            if s.name in first and first[s.name].source != s.source:
                at = first[s.name]
                where = f"{at.source}:{at.pos.line}:{at.pos.column}" if at.pos else at.source
                diagnostics.append(Diagnostic(s.source, s.pos, "error", f"duplicate skillset '{s.name}' (first declared at {where})"))
            first.setdefault(s.name, s)
    skillsets = tuple(dataclasses.replace(s, types=types) for model, _ in units for s in model.skillsets)
    model = Model(source=main.source, types=types, skillsets=skillsets, includes=main.includes)
    errors = [d for d in diagnostics if d.level == "error"]
    if errors:
        raise SourceError(sort_diagnostics(errors))
    warnings = sort_diagnostics([d for d in diagnostics if d.level != "error"])
    return dataclasses.replace(model, warnings=tuple(warnings))


def parse_skillset(text: str, source: str = "<string>") -> Skillset:
    """Parse a text declaring exactly one skillset (docs/semantics.md §2) and return it."""
    model = parse_model(text, source)
    if len(model.skillsets) != 1:
        extra = model.skillsets[1]
        raise SourceError.at(
            source,
            extra.pos,
            f"expected exactly one skillset, found {len(model.skillsets)}"
            f" ('{extra.name}' is the second)",
        )
    return model.skillsets[0]


# ---------------------------------------------------------------------------
# tree -> model


def _pos(token: Token) -> Pos:
    return Pos(token.line, token.column)


class _Item(NamedTuple):
    """One clause of a body: its kind, its payload and the position of its keyword."""

    kind: str
    value: Any
    pos: Pos | None = None


class _Named(NamedTuple):
    """A postcondition with its name (``""`` when unnamed)."""

    name: str
    expr: Expr
    pos: Pos | None


class _PartialMode(NamedTuple):
    name: str
    effects: tuple[Effect, ...]
    postcondition: Expr | None
    pos: Pos | None


class _Builder(Transformer):  # type: ignore[type-arg]
    """Builds the typed model bottom-up; collects structural errors in ``errors``."""

    def __init__(self, source: str) -> None:
        super().__init__()
        self.source = source
        self.errors: list[Diagnostic] = []

    def _error(self, pos: Pos | None, message: str) -> None:
        self.errors.append(Diagnostic(self.source, pos, "error", message))

    def _single(self, items: list[_Item], kind: str, where: str) -> _Item | None:
        """The only clause of ``kind`` (an error for each repetition)."""
        found = [i for i in items if i.kind == kind]
        for extra in found[1:]:
            self._error(extra.pos, f"duplicate {kind} in {where}")
        return found[0] if found else None

    @staticmethod
    def _concat(items: list[_Item], kind: str) -> tuple[Any, ...]:
        return tuple(x for i in items if i.kind == kind for x in i.value)

    # ---- expressions --------------------------------------------------------

    def eq(self, c: list[Token]) -> StateAtom:
        return StateAtom(str(c[0]), str(c[1]), _pos(c[0]), _pos(c[1]))

    def ne(self, c: list[Token]) -> Not:
        return Not(StateAtom(str(c[0]), str(c[1]), _pos(c[0]), _pos(c[1])), _pos(c[0]))

    def true_(self, c: list[Token]) -> Const:
        return Const(True, _pos(c[0]))

    def false_(self, c: list[Token]) -> Const:
        return Const(False, _pos(c[0]))

    def not_(self, c: list[Any]) -> Not:
        return Not(c[1], _pos(c[0]))

    def and_(self, c: list[Any]) -> And:
        return And(c[0], c[1], getattr(c[0], "pos", None))

    def or_(self, c: list[Any]) -> Or:
        return Or(c[0], c[1], getattr(c[0], "pos", None))

    def implies(self, c: list[Any]) -> Implies:
        return Implies(c[0], c[1], getattr(c[0], "pos", None))

    # ---- shared pieces ------------------------------------------------------

    def variable(self, c: list[Token]) -> Variable:
        return Variable(str(c[0]), str(c[1]), _pos(c[0]), _pos(c[1]))

    def effect(self, c: list[Token]) -> Effect:
        return Effect(str(c[0]), str(c[1]), _pos(c[0]), _pos(c[1]))

    def effect_clause(self, c: list[Effect]) -> _Item:
        return _Item("effect", tuple(c))

    def guard_clause(self, c: list[Any]) -> _Item:
        return _Item("guard", c[1], _pos(c[0]))

    def named_postcondition(self, c: list[Any]) -> _Named:
        return _Named(str(c[0]), c[1], _pos(c[0]))

    def postcondition_clause(self, c: list[Any]) -> _Item:
        """Unnamed (``postcondition e``) or named postconditions, as a tuple of _Named."""
        if len(c) > 1 and not isinstance(c[1], _Named):
            return _Item("postcondition", (_Named("", c[1], _pos(c[0])),), _pos(c[0]))
        return _Item("postcondition", tuple(c[1:]), _pos(c[0]))

    def _postcondition(self, items: list[_Item], where: str) -> Expr | None:
        """The conjunction of every postcondition of an interrupt or mode.

        Named postconditions may repeat (rl_model), an unnamed one may not
        (robot_language); names are unique per interrupt or mode.
        """
        parts: list[Expr] = []
        seen: dict[str, Pos | None] = {}
        for item in items:
            if item.kind != "postcondition":
                continue
            for named in item.value:
                if named.name in seen:
                    what = f" '{named.name}'" if named.name else ""
                    self._error(named.pos if named.name else item.pos, f"duplicate postcondition{what} in {where}")
                    continue
                seen[named.name] = named.pos
                parts.append(named.expr)
        if not parts:
            return None
        post = parts[0]
        for part in parts[1:]:
            post = And(post, part, getattr(post, "pos", None))
        return post

    # ---- file level -----------------------------------------------------------

    def start(self, c: list[Any]) -> Model:
        types = tuple(t for x in c if isinstance(x, list) for t in x)
        skillsets = tuple(
            dataclasses.replace(s, types=types) for s in c if isinstance(s, Skillset)
        )
        includes = tuple(x.value for x in c if isinstance(x, _Item) and x.kind == "include")
        return Model(source=self.source, types=types, skillsets=skillsets, includes=includes)

    library = start

    def include(self, c: list[Token]) -> _Item:
        return _Item("include", (str(c[0])[1:-1], _pos(c[0])))

    def type_section(self, c: list[Token]) -> list[TypeDecl]:
        return [TypeDecl(str(t), _pos(t)) for t in c]

    def type_params(self, c: list[Token]) -> _Item:
        return _Item("params", tuple(str(t) for t in c))

    def skillset(self, c: list[Any]) -> Skillset:
        name: Token = c[0]
        items: list[_Item] = c[1:]
        params = next((i.value for i in items if i.kind == "params"), ())
        return Skillset(
            name=str(name),
            resources=self._concat(items, "resources"),
            events=self._concat(items, "events"),
            skills=self._concat(items, "skills"),
            data=self._concat(items, "data"),
            parameters=self._concat(items, "parameter"),
            type_params=params,
            source=self.source,
            pos=_pos(name),
        )

    def data_section(self, c: list[Variable]) -> _Item:
        return _Item("data", tuple(c))

    def data_field(self, c: list[Any]) -> Variable:
        period: float | None = c[2].value if len(c) > 2 else None
        return Variable(str(c[0]), str(c[1]), _pos(c[0]), _pos(c[1]), period)

    def parameter_section(self, c: list[Variable]) -> _Item:
        return _Item("parameter", tuple(c))

    # ---- resources ------------------------------------------------------------

    def resource_section(self, c: list[Resource]) -> _Item:
        return _Item("resources", tuple(c))

    def state_clause(self, c: list[Token]) -> _Item:
        return _Item("state", tuple(c[1:]), _pos(c[0]))

    def initial_clause(self, c: list[Token]) -> _Item:
        return _Item("initial", c[1], _pos(c[0]))

    def transition_all(self, c: list[Token]) -> _Item:
        return _Item("transition", None, _pos(c[0]))

    def transition_list(self, c: list[Any]) -> _Item:
        return _Item("transition", tuple(c[1:]), _pos(c[0]))

    def transition_pair(self, c: list[Token]) -> tuple[Token, Token]:
        return (c[0], c[1])

    def resource(self, c: list[Any]) -> Resource:
        name: Token = c[0]
        items: list[_Item] = c[1:]
        where = f"resource '{name}'"
        state = self._single(items, "state", where)
        initial = self._single(items, "initial", where)
        trans = self._single(items, "transition", where)
        if state is None:
            self._error(_pos(name), f"resource '{name}' has no state declaration")
        if initial is None:
            self._error(_pos(name), f"resource '{name}' has no initial state")
        if trans is None and state is not None and len(state.value) > 1:
            self.errors.append(Diagnostic(
                self.source, _pos(name), "warning",
                f"resource '{name}' has no transition clause: no effect can change its state"
                " (write 'transition all' or 'transition { A -> B }')",
            ))
        states: tuple[Token, ...] = state.value if state else ()
        pairs: tuple[tuple[Token, Token], ...] | None = trans.value if trans else ()
        return Resource(
            name=str(name),
            states=tuple(str(s) for s in states),
            initial=str(initial.value) if initial else "",
            transitions=None if pairs is None else tuple((str(a), str(b)) for a, b in pairs),
            pos=_pos(name),
            initial_pos=_pos(initial.value) if initial else None,
            state_pos=tuple(_pos(s) for s in states),
            transition_pos=() if pairs is None else tuple(_pos(a) for a, _ in pairs),
            transition_target_pos=() if pairs is None else tuple(_pos(b) for _, b in pairs),
        )

    # ---- events -----------------------------------------------------------------

    def event_section(self, c: list[Event]) -> _Item:
        return _Item("events", tuple(c))

    def event(self, c: list[Any]) -> Event:
        name: Token = c[0]
        items: list[_Item] = c[1:]
        guard = self._single(items, "guard", f"event '{name}'")
        return Event(
            name=str(name),
            guard=guard.value if guard else None,
            effects=self._concat(items, "effect"),
            pos=_pos(name),
        )

    # ---- skills -------------------------------------------------------------------

    def skill_section(self, c: list[Skill]) -> _Item:
        return _Item("skills", tuple(c))

    def input_clause(self, c: list[Variable]) -> _Item:
        return _Item("input", tuple(c))

    def output_clause(self, c: list[Variable]) -> _Item:
        return _Item("output", tuple(c))

    def message_clause(self, c: list[Variable]) -> _Item:
        return _Item("message", tuple(c))

    def precondition(self, c: list[Any]) -> Precondition:
        return Precondition(str(c[0]), c[1], _pos(c[0]))

    def precondition_clause(self, c: list[Precondition]) -> _Item:
        return _Item("precondition", tuple(c))

    def start_clause(self, c: list[Effect]) -> _Item:
        return _Item("start", tuple(c))

    def invariant(self, c: list[Any]) -> Invariant:
        name: Token = c[0]
        items: list[_Item] = c[1:]
        guard = self._single(items, "guard", f"invariant '{name}'")
        if guard is None:
            self._error(_pos(name), f"invariant '{name}' has no guard")
        return Invariant(
            name=str(name),
            guard=guard.value if guard else Const(True),
            effects=self._concat(items, "effect"),
            pos=_pos(name),
        )

    def invariant_clause(self, c: list[Invariant]) -> _Item:
        return _Item("invariant", tuple(c))

    def time_unit(self, c: list[Token]) -> str:
        return str(c[0])

    def period_clause(self, c: list[Any]) -> _Item:
        unit = c[2] if len(c) > 2 else "sec"
        return _Item("period", float(c[1]) / _UNIT_DIVISOR[unit], _pos(c[0]))

    def progress_clause(self, c: list[Any]) -> _Item:
        keyword: Token = c[0]
        items: list[_Item] = c[1:]
        period = self._single(items, "period", "progress")
        if period is None:
            self._error(_pos(keyword), "progress has no period")
        fields = tuple(v for i in items if i.kind in ("message", "output") for v in i.value)
        progress = Progress(period.value if period else 0.0, fields, _pos(keyword))
        return _Item("progress", progress, _pos(keyword))

    def interrupting_clause(self, c: list[Token]) -> _Item:
        return _Item("interrupting", c[1].type == "TRUE", _pos(c[0]))

    def interrupt_clause(self, c: list[Any]) -> _Item:
        keyword: Token = c[0]
        items: list[_Item] = c[1:]
        interrupting = self._single(items, "interrupting", "interrupt")
        interrupt = Interrupt(
            interrupting=bool(interrupting.value) if interrupting else False,
            effects=self._concat(items, "effect"),
            postcondition=self._postcondition(items, "interrupt"),
            declared=True,
            pos=_pos(keyword),
        )
        return _Item("interrupt", interrupt, _pos(keyword))

    def _mode_body(self, items: list[_Item], name: str, pos: Pos | None) -> _PartialMode:
        where = f"mode '{name}'" if name else "unnamed mode"
        return _PartialMode(name, self._concat(items, "effect"), self._postcondition(items, where), pos)

    def mode(self, c: list[Any]) -> _PartialMode:
        return self._mode_body(c[1:], str(c[0]), _pos(c[0]))

    def unnamed_mode(self, c: list[_Item]) -> _PartialMode:
        return self._mode_body(c, "", None)

    def _modes(self, c: list[Any], kind: str) -> _Item:
        keyword: Token = c[0]
        modes = tuple(
            Mode(m.name, kind, m.effects, m.postcondition, m.pos or _pos(keyword))  # type: ignore[arg-type]
            for m in c[1:]
        )
        return _Item(kind, modes, _pos(keyword))

    def success_clause(self, c: list[Any]) -> _Item:
        return self._modes(c, "success")

    def failure_clause(self, c: list[Any]) -> _Item:
        return self._modes(c, "failure")

    def skill(self, c: list[Any]) -> Skill:
        name: Token = c[0]
        items: list[_Item] = c[1:]
        where = f"skill '{name}'"
        progress = self._single(items, "progress", where)
        interrupt = self._single(items, "interrupt", where)
        return Skill(
            name=str(name),
            parameters=self._concat(items, "parameter"),
            inputs=self._concat(items, "input"),
            outputs=self._concat(items, "output"),
            preconditions=self._concat(items, "precondition"),
            start=self._concat(items, "start"),
            invariants=self._concat(items, "invariant"),
            progress=progress.value if progress else None,
            interrupt=interrupt.value if interrupt else Interrupt(),
            successes=self._concat(items, "success"),
            failures=self._concat(items, "failure"),
            pos=_pos(name),
        )
