"""Goal files: a mission as an ordered list of goals, in TOML (SPEC §8, *Goals*)::

    # Ready the arm, then walk to a waypoint.
    [[goals]]
    reach = "manipulator:RD"

    [[goals]]
    run = "spot:go_to_waypoint"
    inputs = { go_to_waypoint = { target = { x = 12.0, y = 3.5, z = 0.0 } } }

Each ``[[goals]]`` table has ``reach = "FORMULA"`` or ``run = "SKILLSET:SKILL[.success.MODE]"``
and, for the skills that need them, ``inputs`` (:mod:`skinet.plan.inputs`).
Errors carry the file, line and column: TOML syntax, unknown keys (with the
close names), a goal's own errors at their place inside its string.  tomllib
gives no positions, so they are found in the text: the ``n``-th ``[[goals]]``
header, then the key inside its table (the table's header when the key cannot
be found, e.g. in an inline array).  Pure; cost linear in the text.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping, Sequence

from skinet.errors import Pos, SourceError
from skinet.plan.goal import Goal, parse_goal
from skinet.plan.inputs import parse_inputs
from skinet.system import System
from skinet.tomltext import parse_toml

GOAL_KEYS = ("reach", "run", "inputs")
_HEADER = re.compile(r"^\s*\[\[\s*goals\s*\]\]")
_TABLE = re.compile(r"^\s*\[")


def parse_goals(text: str, system: System, source: str = "<goals>",
                types: Mapping[str, str] | None = None) -> list[Goal]:
    """The goals of a goals file, in order; ``types`` is the system's type map (for inputs)."""
    data = parse_toml(text, source)
    lines = text.splitlines()
    for key in data:
        if key != "goals":
            raise SourceError.at(source, locate(lines, 0, len(lines), [key]),
                                 f"unknown key '{key}'{_close(key, ['goals'])}")
    entries = data.get("goals")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        where = locate(lines, 0, len(lines), ["goals"]) or Pos(1, 1)
        raise SourceError.at(source, where, "no goals: a goals file lists [[goals]] tables, each with reach = \"FORMULA\""
                                            " or run = \"SKILLSET:SKILL\"")
    spans = _spans(lines)
    goals = []
    for n, entry in enumerate(entries):
        lo, hi = spans[n] if n < len(spans) else (0, len(lines))
        header = Pos(lo, 1) if n < len(spans) else locate(lines, 0, len(lines), ["goals"])

        def where(keys: Sequence[str], lo: int = lo, hi: int = hi, header: Pos | None = header) -> Pos | None:
            return locate(lines, lo, hi, keys) or header

        for key in entry:
            if key not in GOAL_KEYS:
                raise SourceError.at(source, where([key]),
                                     f"goal {n + 1}: unknown key '{key}'{_close(key, list(GOAL_KEYS))}")
        kinds = [k for k in ("reach", "run") if k in entry]
        if len(kinds) != 1:
            problem = "has both reach and run" if kinds else "needs reach = \"FORMULA\" or run = \"SKILLSET:SKILL\""
            raise SourceError.at(source, where(kinds[1:] or []), f"goal {n + 1} {problem}")
        kind = kinds[0]
        value = entry[kind]
        if not isinstance(value, str):
            raise SourceError.at(source, where([kind]), f"goal {n + 1}: {kind} must be a string")
        inputs = {}
        if "inputs" in entry:
            inputs = parse_inputs(system, entry["inputs"], source,
                                  lambda keys: where(["inputs", *keys]), types)
        at = _value_start(lines, where([kind]), len(kind) + 1)
        goals.append(parse_goal(system, f"{kind} {value}", inputs, source, at, types))
    return goals


def _spans(lines: list[str]) -> list[tuple[int, int]]:
    """``(header line, last line)`` (1-based) of each ``[[goals]]`` table."""
    heads = [n for n, line in enumerate(lines, 1) if _HEADER.match(line)]
    spans = []
    for h in heads:
        end = next((n for n in range(h + 1, len(lines) + 1) if _TABLE.match(lines[n - 1])), len(lines) + 1)
        spans.append((h, end - 1))
    return spans


def locate(lines: list[str], lo: int, hi: int, keys: Sequence[str]) -> Pos | None:
    """Where the path ``keys`` (``inputs``, then a skill, ...) is written in lines ``lo..hi``
    (1-based, inclusive; 0 for the start): each key searched after the previous one."""
    line, column = max(lo, 1), 1
    for key in keys:
        pattern = re.compile(rf"(?<![\w\"'-])(\"|'|){re.escape(key)}\1\s*[=.]")
        found = None
        for n in range(line, min(hi, len(lines)) + 1):
            m = pattern.search(lines[n - 1], column - 1 if n == line else 0)
            if m:
                found = Pos(n, m.start() + 1)
                break
        if found is None:
            return None
        line, column = found.line, found.column + 1
    return Pos(line, column - 1) if keys else None


def _value_start(lines: list[str], key: Pos | None, skip: int) -> Pos | None:
    """Where a goal's text would start so that its value lands where the string is written:
    the string's first character, moved back by ``skip`` (``reach `` or ``run ``)."""
    if key is None:
        return None
    m = re.compile(r"=\s*(\"|')").search(lines[key.line - 1], key.column - 1)
    if m is None or lines[key.line - 1][m.end():m.end() + 2] in ("\"\"", "''"):
        return key  # a multi-line string: its key
    return Pos(key.line, m.end() + 1 - skip)


def _close(name: str, known: list[str]) -> str:
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    return f" (did you mean {', '.join(close)}?)" if close else f" (keys: {', '.join(known)})"
