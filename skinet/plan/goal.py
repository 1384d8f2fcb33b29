"""The goal language (docs/semantics.md §8, *Goals*): ``reach FORMULA`` and ``run SKILLSET:SKILL[.success.MODE]``.

``reach FORMULA`` asks for a marking of Safe where FORMULA holds; FORMULA is a
state formula of the property language (docs/semantics.md §4: atoms, ``not``, ``and``,
``or``, ``=>``; no temporal operator).  ``run SKILLSET:SKILL`` asks that the
skill be started and end in a success mode (any, or the one named with
``.success.MODE``): the goal is reached by that outcome itself; should the
skill already run, its success counts.  A goal carries its skill inputs
(:mod:`skinet.plan.inputs`); the skill a ``run`` goal names must have all of
them.  Grammar: ``goal.lark``; errors are ``SourceError`` with the position
in the goal text, shifted by ``at`` when the text sits inside a file.
Cost: linear in the text.

Examples:
    >>> from skinet.system.load import load_system
    >>> system, _ = load_system("skillsets/spot_arm.toml")
    >>> parse_goal(system, "run manipulator:arm_ready.success.ready").target("manipulator", "arm_ready.success.ready")
    True
    >>> parse_goal(system, "reach spot:Standing and manipulator:HP").text
    'reach spot:Standing and manipulator:HP'
    >>> parse_goal(system, "run spot:go_to_waypoint")
    Traceback (most recent call last):
    ...
    skinet.errors.SourceError: <goal>:1:5: error: run spot:go_to_waypoint needs input 'target' (GeoPoint): give it in the goal's inputs, e.g. go_to_waypoint.target = ...

A missing input's hint is written as the user gives inputs (``given_with``, :data:`INPUTS_HINTS`):
a goals file's ``inputs = {...}``, the command line's ``--inputs '...'``, or (the default: the
pilot's requests, the dashboard's inputs box) the TOML line alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any, Literal

from lark import Lark, Token
from lark.exceptions import UnexpectedInput

from skinet.closenames import unknown
from skinet.errors import Diagnostic, Pos, SourceError
from skinet.lang.expr import Expr
from skinet.lang.larkcache import cached_lark
from skinet.lang.larkerrors import MAX_FORMULA_CHARS, check_size, syntax_error
from skinet.plan.inputs import Inputs, missing, parse_inputs
from skinet.props.evaluate import holds
from skinet.props.formula import is_temporal
from skinet.props.parser import parse_formula
from skinet.system.model import System


GivenWith = Literal["file", "flag", "text"]
INPUTS_HINTS: dict[str, str] = {  # how to give a missing input, by where the goal was written (GivenWith)
    "file": "give it in the goal's inputs, e.g. inputs = {{ {skill} = {{ {name} = ... }} }}",
    "flag": "give it with --inputs, e.g. --inputs '{skill}.{name} = ...'",
    "text": "give it in the goal's inputs, e.g. {skill}.{name} = ...",
}


@dataclass(frozen=True, eq=False)
class Goal:
    """One goal with its inputs.  ``text`` is the goal as written (normalised blanks)."""

    kind: Literal["reach", "run"]
    text: str
    formula: Expr | None = None  # reach
    skillset: str = ""  # run
    skill: str = ""
    mode: str | None = None  # run: the success mode named, None for any
    inputs: Inputs = field(default_factory=dict)

    def holds(self, system: System, marking: Mapping[str, int]) -> bool:
        """A ``reach`` goal's formula at ``marking`` (a ``run`` goal never holds at a marking)."""
        return self.formula is not None and holds(self.formula, marking, system.nets)

    def target(self, skillset: str, transition: str) -> bool:
        """Whether the outcome ``skillset:transition`` reaches this ``run`` goal."""
        if self.kind != "run" or skillset != self.skillset:
            return False
        if self.mode is not None:
            return transition == f"{self.skill}.success.{self.mode}"
        return transition == f"{self.skill}.success" or transition.startswith(f"{self.skill}.success.")

    def given(self, skillset: str, skill: str) -> Mapping[str, Any] | None:
        """The inputs the goal gives ``skillset:skill`` (None: none)."""
        return self.inputs.get((skillset, skill))


@cache
def _lark() -> Lark:
    return cached_lark(Path(__file__).with_name("goal.lark"), parser="lalr", propagate_positions=True)


def shift(exc: SourceError, at: Pos | None) -> SourceError:
    """``exc`` with its positions moved from a text that starts at ``at`` of its file."""
    if at is None:
        return exc

    def moved(pos: Pos | None) -> Pos | None:
        if pos is None:
            return at
        if pos.line == 1:
            return Pos(at.line, at.column + pos.column - 1)
        return Pos(at.line + pos.line - 1, pos.column)

    return SourceError([Diagnostic(d.file, moved(d.pos), d.level, d.message) for d in exc.diagnostics])


def parse_goal(system: System, text: str, inputs: Inputs | Mapping[str, Any] | None = None,
               source: str = "<goal>", at: Pos | None = None, types: Mapping[str, str] | None = None,
               given_with: GivenWith = "text") -> Goal:
    """Parse one goal.  ``inputs``: checked inputs (:data:`Inputs`) or a raw table for
    :func:`skinet.plan.inputs.parse_inputs`; ``at``: where ``text`` starts in ``source``;
    ``types``: the system's type map, to check raw inputs; ``given_with``: how the user gives inputs
    (the hint of a missing one, :data:`INPUTS_HINTS`)."""
    try:
        return _parse(system, text, inputs, source, types, given_with)
    except SourceError as exc:
        raise shift(exc, at) from None


def _parse(system: System, text: str, inputs: Inputs | Mapping[str, Any] | None, source: str,
           types: Mapping[str, str] | None, given_with: GivenWith) -> Goal:
    check_size(text, source, MAX_FORMULA_CHARS)
    try:
        tree = _lark().parse(text)
    except UnexpectedInput as exc:
        raise syntax_error(_lark(), exc, text, source) from None
    checked = _inputs(system, inputs, source, types)
    tokens: list[Token] = [c for c in tree.children if isinstance(c, Token)]
    if tree.data == "reach":
        formula_token = tokens[1]
        skillsets = {c.name: c.skillset for c in system.components}
        written = str(formula_token)
        try:  # the property language ends a formula at a line break; a goal may span lines
            formula = parse_formula(written.replace("\r", " ").replace("\n", " "), skillsets, source)
        except SourceError as exc:
            raise SourceError([_relocate(d, written, formula_token) for d in exc.diagnostics]) from None
        if is_temporal(formula):
            raise SourceError.at(source, Pos(formula_token.line, formula_token.column),
                                 "reach takes a state formula (atoms, not, and, or, =>), not a temporal operator")
        return Goal("reach", f"reach {' '.join(str(formula_token).split())}", formula, inputs=checked)
    names = [t for t in tokens if t.type == "NAME"]
    skillset, skill = str(names[0]), str(names[1])
    mode = str(names[2]) if len(names) > 2 else None
    where = Pos(names[0].line, names[0].column)
    comps = {c.name: c for c in system.components}
    if skillset not in comps:
        raise SourceError.at(source, where, unknown("skillset", skillset, list(comps)))
    declared = {k.name: k for k in comps[skillset].skillset.skills}
    if skill not in declared:
        raise SourceError.at(source, Pos(names[1].line, names[1].column),
                             unknown("skill", skill, list(declared), f" of '{skillset}'"))
    k = declared[skill]
    if mode is not None:
        successes = [m.name for m in k.successes if m.name]
        if mode not in successes:
            raise SourceError.at(source, Pos(names[2].line, names[2].column),
                                 unknown("success mode", mode, successes, f" of '{skillset}:{skill}'"))
    elif not k.successes:
        raise SourceError.at(source, Pos(names[1].line, names[1].column),
                             f"'{skillset}:{skill}' has no success mode: it can never succeed")
    lacking = missing(k, checked.get((skillset, skill)))
    if lacking:
        v = lacking[0]
        hint = INPUTS_HINTS[given_with].format(skill=skill, name=v.name)
        raise SourceError.at(source, where, f"run {skillset}:{skill} needs input '{v.name}' ({v.type}): {hint}")
    shown = f"run {skillset}:{skill}" + (f".success.{mode}" if mode is not None else "")
    return Goal("run", shown, None, skillset, skill, mode, checked)


def _relocate(d: Diagnostic, written: str, token: Token) -> Diagnostic:
    """A diagnostic of the formula (one line) placed in the goal text."""
    if d.pos is None:
        return Diagnostic(d.file, Pos(token.line, token.column), d.level, d.message)
    before = written[:d.pos.column - 1]
    line = token.line + before.count("\n")
    column = (token.column if "\n" not in before else 1) + len(before.rsplit("\n", 1)[-1])
    return Diagnostic(d.file, Pos(line, column), d.level, d.message)


def _inputs(system: System, inputs: Inputs | Mapping[str, Any] | None, source: str,
            types: Mapping[str, str] | None) -> Inputs:
    if not inputs:
        return {}
    if all(isinstance(k, tuple) for k in inputs):
        return dict(inputs)  # type: ignore[arg-type]  # already checked
    return parse_inputs(system, inputs, source, types=types)

