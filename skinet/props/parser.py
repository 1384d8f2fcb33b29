"""Parser for safety properties and CTL formulas (docs/semantics.md §4, §6).

Atoms ``skillset:NAME``, ``skillset:resource.state``, ``skillset:i_skill`` and
``skillset:e_skill`` are resolved against the system's skillsets; an unknown or
ambiguous name is an error that lists the candidates.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from functools import cache
from pathlib import Path

from lark import Lark, Token, Transformer, Tree, v_args
from lark.exceptions import UnexpectedInput, VisitError

from skinet.errors import Pos, SourceError
from skinet.lang.expr import And, Const, Implies, Not, Or
from skinet.lang.larkcache import cached_lark
from skinet.lang.larkerrors import MAX_FORMULA_CHARS, check_nesting, check_size, syntax_error
from skinet.lang.model import Skillset
from skinet.net.build import idle_place, resource_place, running_place
from skinet.props.formula import PlaceAtom, Property, Temporal, Until, is_temporal


@cache
def _lark(start: str) -> Lark:
    return cached_lark(Path(__file__).with_name("formula.lark"), start=start, parser="lalr", propagate_positions=True,
                       maybe_placeholders=False)


def atom_candidates(skillset: Skillset) -> dict[str, list[str]]:
    """Short names usable after ``skillset:``, each with the places it may denote."""
    names: dict[str, list[str]] = {}
    for r in skillset.resources:
        for s in r.states:
            names.setdefault(s, []).append(resource_place(r.name, s))
            names.setdefault(f"{r.name}.{s}", []).append(resource_place(r.name, s))
    for k in skillset.skills:
        names.setdefault(running_place(k.name), []).append(running_place(k.name))
        names.setdefault(idle_place(k.name), []).append(idle_place(k.name))
    return names


def resolve_atom(skillsets: Mapping[str, Skillset], text: str) -> PlaceAtom:
    """Resolve ``skillset:name`` (raises ``ValueError`` with the candidates)."""
    ss_name, _, name = text.partition(":")
    if ss_name not in skillsets:
        raise ValueError(f"unknown skillset '{ss_name}' in '{text}' (skillsets: {', '.join(sorted(skillsets))})")
    names = atom_candidates(skillsets[ss_name])
    places = names.get(name, [])
    if len(places) == 1:
        return PlaceAtom(ss_name, places[0], text)
    if len(places) > 1:
        options = ", ".join(f"{ss_name}:{p}" for p in places)
        raise ValueError(f"ambiguous name '{text}': could be {options}")
    close = difflib.get_close_matches(name, list(names), n=6, cutoff=0.6) or sorted(
        n for n in names if "." not in n
    )
    raise ValueError(f"unknown name '{text}' (candidates: {', '.join(f'{ss_name}:{c}' for c in close)})")


class _Build(Transformer):
    def __init__(self, skillsets: Mapping[str, Skillset], source: str, text: str):
        super().__init__()
        self.skillsets = skillsets
        self.source = source
        self.text = text

    @v_args(meta=True)
    def atom(self, meta, children: list[Token]) -> PlaceAtom:
        ss, name, *rest = [str(c) for c in children]
        written = f"{ss}:{name}" + (f".{rest[0]}" if rest else "")
        try:
            atom = resolve_atom(self.skillsets, written)
        except ValueError as exc:
            raise SourceError.at(self.source, Pos(meta.line, meta.column), str(exc)) from None
        return PlaceAtom(atom.skillset, atom.place, written, Pos(meta.line, meta.column))

    def true(self, _: list) -> Const:
        return Const(True)

    def false(self, _: list) -> Const:
        return Const(False)

    @v_args(meta=True)
    def not_(self, meta, c: list) -> Not:
        return Not(c[0], Pos(meta.line, meta.column))

    @v_args(meta=True)
    def and_(self, meta, c: list) -> And:
        return And(c[0], c[1], Pos(meta.line, meta.column))

    @v_args(meta=True)
    def or_(self, meta, c: list) -> Or:
        return Or(c[0], c[1], Pos(meta.line, meta.column))

    @v_args(meta=True)
    def implies(self, meta, c: list) -> Implies:
        return Implies(c[0], c[1], Pos(meta.line, meta.column))

    @v_args(meta=True)
    def temporal(self, meta, c: list) -> Temporal:
        return Temporal(str(c[0]), c[1], Pos(meta.line, meta.column))  # type: ignore[arg-type]

    @v_args(meta=True)
    def until(self, meta, c: list) -> Until:
        return Until(str(c[0]), c[1], c[2], Pos(meta.line, meta.column))  # type: ignore[arg-type]

    @v_args(meta=True)
    def property(self, meta, c: list) -> Property:
        name, expr = c
        start = self.text.index("=", name.end_pos) + 1
        return Property(str(name), expr, self.text[start:meta.end_pos].strip(), Pos(meta.line, meta.column))

    def properties(self, c: list) -> list[Property]:
        return [p for p in c if isinstance(p, Property)]


# Tree nodes that nest a formula one level deeper (see check_nesting).
_OPERATORS = frozenset({"not_", "and_", "or_", "implies", "temporal", "until"})


def _parse(text: str, start: str, skillsets: Mapping[str, Skillset], source: str):
    check_size(text, source, MAX_FORMULA_CHARS)
    try:
        tree: Tree = _lark(start).parse(text)
    except UnexpectedInput as exc:
        raise syntax_error(_lark(start), exc, text, source) from None
    check_nesting(tree, _OPERATORS, source)
    try:
        return _Build(skillsets, source, text).transform(tree)
    except VisitError as exc:
        if isinstance(exc.orig_exc, SourceError):
            raise exc.orig_exc from None
        raise


def parse_properties(text: str, skillsets: Mapping[str, Skillset], source: str = "<string>") -> list[Property]:
    """Parse a properties file: one ``name = expr`` per line, ``#`` comments.

    Raises :class:`SourceError` on syntax errors, unresolvable atoms and
    duplicate property names.
    """
    props: list[Property] = _parse(text, "properties", skillsets, source)
    seen: dict[str, Property] = {}
    for p in props:
        if p.name in seen:
            first = seen[p.name].pos
            where = f" (first defined at {first.line}:{first.column})" if first else ""
            raise SourceError.at(source, p.pos, f"duplicate property '{p.name}'{where}")
        seen[p.name] = p
    for p in props:
        if is_temporal(p.expr):
            raise SourceError.at(source, p.pos, f"property '{p.name}' uses a temporal operator; properties are state formulas")
    return props


def parse_formula(text: str, skillsets: Mapping[str, Skillset], source: str = "<formula>"):
    """Parse one CTL formula (docs/semantics.md §6): boolean operators, EX AX EF AF EG AG, E[U], A[U]."""
    return _parse(text.strip(), "expr", skillsets, source)
