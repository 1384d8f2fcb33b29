"""Goal files: a mission as an ordered list of goals, in TOML (docs/semantics.md §8, *Goals*)::

    # Ready the arm, then walk to a waypoint.
    [[goals]]
    reach = "manipulator:RD"

    [[goals]]
    run = "spot:go_to_waypoint"
    inputs = { go_to_waypoint = { target = { x = 12.0, y = 3.5, z = 0.0 } } }

Each ``[[goals]]`` table has ``reach = "FORMULA"`` or ``run = "SKILLSET:SKILL[.success.MODE]"``
and, for the skills that need them, ``inputs`` (:mod:`skinet.plan.inputs`).
Errors carry the file, line and column: TOML syntax, unknown tables and keys
(with the close names, as in system files: :mod:`skinet.files.toml`), a goal's own
errors at their place inside its string, an input's at its key inside the
inline tables.  Pure; cost linear in the text.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

from skinet.errors import Pos, SourceError
from skinet.plan.goal import Goal, parse_goal
from skinet.plan.inputs import parse_inputs
from skinet.system.model import System
from skinet.files.toml import Locations, check_keys, check_tables, locate, parse_toml

GOAL_KEYS = ("reach", "run", "inputs")


def count_goals(text: str, source: str = "<goals>") -> int:
    """How many ``[[goals]]`` tables a goals file has (0 when it has none, or ``goals`` is not a list of
    tables); its TOML decoded, nothing else checked.  Cost: linear in the text.  Raises ``SourceError``
    on invalid TOML."""
    entries = parse_toml(text, source).get("goals")
    return len(entries) if isinstance(entries, list) else 0


def parse_goals(text: str, system: System, source: str = "<goals>",
                types: Mapping[str, str] | None = None, max_goals: int | None = None) -> list[Goal]:
    """The goals of a goals file, in order; ``types`` is the system's type map (for inputs); more than
    ``max_goals`` goals are refused before any goal is parsed."""
    data = parse_toml(text, source)
    check_tables(data, ["[[goals]]"], source, text)
    entries = data.get("goals")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise SourceError.at(source, locate(text, (), "goals") or Pos(1, 1),
                             "no goals: a goals file lists [[goals]] tables, each with reach = \"FORMULA\" or "
                             "run = \"SKILLSET:SKILL\"")
    if max_goals is not None and len(entries) > max_goals:
        raise SourceError.at(source, locate(text, ("goals", max_goals)),
                             f"{len(entries)} goals: a mission has at most {max_goals}")
    lines = text.splitlines()
    where = Locations(text)
    goals = []
    for n, entry in enumerate(entries):
        table = ("goals", n)
        header = where.get(table)
        check_keys(entry, GOAL_KEYS, source, text, table, "[[goals]]")
        kinds = [k for k in ("reach", "run") if k in entry]
        if len(kinds) != 1:
            problem = "has both reach and run" if kinds else "needs reach = \"FORMULA\" or run = \"SKILLSET:SKILL\""
            raise SourceError.at(source, where.get(table, kinds[1]) if kinds else header, f"goal {n + 1} {problem}")
        kind = kinds[0]
        at = where.get(table, kind) or header
        value = entry[kind]
        if not isinstance(value, str):
            raise SourceError.at(source, at, f"goal {n + 1}: {kind} must be a string")
        inputs = {}
        if "inputs" in entry:
            start = where.get(table, "inputs") or header
            inputs = parse_inputs(system, entry["inputs"], source, lambda keys: nested(lines, start, keys), types)
        goals.append(parse_goal(system, f"{kind} {value}", inputs, source, _value_start(lines, at, len(kind) + 1), types,
                                "file"))
    return goals


def nested(lines: list[str], start: Pos | None, keys: Sequence[str]) -> Pos | None:
    """Where the path ``keys`` is written from ``start`` on (keys of inline tables and dotted keys,
    which :func:`skinet.files.toml.locate` finds by their first name only): each key searched after
    the previous one; ``start`` itself when a key cannot be found."""
    if start is None or not keys:
        return start
    line, column = start.line, start.column
    for key in keys:
        pattern = re.compile(rf"(?<![\w\"'-])(\"|'|){re.escape(key)}\1\s*[=.]")
        found = None
        for n in range(line, len(lines) + 1):
            m = pattern.search(lines[n - 1], column - 1 if n == line else 0)
            if m:
                found = Pos(n, m.start() + 1)
                break
        if found is None:
            return start
        line, column = found.line, found.column + 1
    return Pos(line, column - 1)


def _value_start(lines: list[str], key: Pos | None, skip: int) -> Pos | None:
    """Where a goal's text would start so that its value lands where the string is written:
    the string's first character, moved back by ``skip`` (``reach `` or ``run ``)."""
    if key is None:
        return None
    m = re.compile(r"=\s*(\"|')").search(lines[key.line - 1], key.column - 1)
    if m is None or lines[key.line - 1][m.end():m.end() + 2] in ("\"\"", "''"):
        return key  # a multi-line string: its key
    return Pos(key.line, m.end() + 1 - skip)
