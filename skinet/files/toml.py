"""TOML texts (system, scenario and goal files): decoding, positions of keys, strict key sets.

``tomllib`` reports a syntax error "at end of document" without a position and
recurses on nested arrays and tables: both become one ``FILE:LINE:COL`` error.
``tomllib`` gives no positions for what it decoded, so :func:`locate` finds
where a table or a key is written (a line scan that follows table headers);
:func:`locate_path` also finds keys of inline tables and where values start;
:func:`check_tables` and :func:`check_keys` refuse names a reader does not
know, at their position, with the close names (:mod:`skinet.closenames`): a
misspelt key is an error, never ignored.  Pure; cost linear in the text.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Iterator, Mapping, Sequence

from skinet.closenames import unknown
from skinet.errors import Pos, SourceError

Path = tuple[str | int, ...]  # a table: ("system",), ("skillsets", 0) for the first [[skillsets]], () for the top

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\[\]#]+?)\s*\]\]?\s*(?:#.*)?$")
_KEY = re.compile(r"""^\s*(?:"([^"]*)"|'([^']*)'|([A-Za-z0-9_-]+))\s*[=.]""")


def parse_toml(text: str, source: str) -> dict[str, object]:
    """``tomllib.loads`` with its errors (and its recursion on deep nesting) as SourceError."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _toml_error(source, text, exc) from None
    except RecursionError:
        raise SourceError.at(source, None, "invalid TOML: nested too deeply") from None


def _toml_error(source: str, text: str, exc: tomllib.TOMLDecodeError) -> SourceError:
    """The decoder's message at its position; "at end of document" is the last character."""
    match = re.search(r"\(at line (\d+), column (\d+)\)$", str(exc))
    message = re.sub(r"\s*\(at line \d+, column \d+\)$|\s*\(at end of document\)$", "", str(exc))
    if match:
        pos: Pos | None = Pos(int(match.group(1)), int(match.group(2)))
    else:
        stripped = text.rstrip()  # as for syntax errors: just after the last character
        pos = Pos(stripped.count("\n") + 1, len(stripped.rsplit("\n", 1)[-1]) + 1)
    return SourceError.at(source, pos, f"invalid TOML: {message}")


def locate(text: str, table: Path = (), key: str | None = None) -> Pos | None:
    """Where ``key = ...`` is written inside ``table`` (its header without ``key``), if it is.

    Follows ``[a.b]`` and ``[[a]]`` headers (the n-th ``[[a]]`` is ``("a", n)``,
    from 0) and skips multi-line strings; dotted keys and inline tables are
    found by their first name only.  For many look-ups in one text, build
    :class:`Locations` once (each call here scans the text).
    """
    return next((pos for t, k, pos in _positions(text) if t == tuple(table) and k == key), None)


class Locations:
    """Every position :func:`locate` can give for ``text``, found in one pass (cost linear in the text);
    ``get(table, key)`` answers as ``locate(text, table, key)`` does, in constant time."""

    def __init__(self, text: str):
        self._at: dict[tuple[Path, str | None], Pos] = {}
        for table, key, pos in _positions(text):
            self._at.setdefault((table, key), pos)

    def get(self, table: Path = (), key: str | None = None) -> Pos | None:
        return self._at.get((tuple(table), key))


def _positions(text: str) -> Iterator[tuple[Path, str | None, Pos]]:
    """Each table header (key None) and each key line's first name, with its table, in text order."""
    current: Path = ()
    counts: dict[Path, int] = {}
    in_string: str | None = None  # the quotes of a multi-line string left open
    for n, line in enumerate(text.splitlines(), 1):
        if in_string is not None:
            if line.count(in_string) % 2:
                in_string = None
            continue
        in_string = next((q for q in ('"""', "'''") if line.count(q) % 2), None)
        header = _HEADER.match(line)
        if header:
            names: Path = tuple(part.strip().strip("\"'") for part in header.group(2).split("."))
            if header.group(1) == "[[":
                counts[names] = counts.get(names, -1) + 1
                names = (*names, counts[names])
            current = names
            yield current, None, Pos(n, line.index("[") + 1)
            continue
        found = _KEY.match(line)
        if found:
            group = next(i for i in (1, 2, 3) if found.group(i) is not None)
            yield current, found.group(group), Pos(n, found.start(group) + (1 if group == 3 else 0))  # quoted: its quote


def check_tables(data: Mapping[str, object], tables: Sequence[str], source: str, text: str) -> None:
    """Refuse a top-level table or key of ``data`` not named in ``tables`` (``[system]``, ``[[skillsets]]``)."""
    known = {t.strip("[]"): t for t in tables}
    for name, value in data.items():
        if name in known:
            continue
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            shown, pos = f"[[{name}]]", locate(text, (name, 0))
        elif isinstance(value, dict):
            shown, pos = f"[{name}]", locate(text, (name,)) or _first_subtable(text, name)
        else:
            raise SourceError.at(source, locate(text, (), name),
                                 unknown("key", name, list(tables), " at the top level (keys belong in a table)"))
        close = unknown("table", shown, list(tables))
        raise SourceError.at(source, pos, close)


def check_keys(data: Mapping[str, object], allowed: Sequence[str], source: str, text: str, table: Path,
               label: str) -> None:
    """Refuse a key of ``data`` (the table ``table``, shown as ``label``) not in ``allowed``."""
    for name in data:
        if name not in allowed:
            pos = locate(text, table, name) or locate(text, table)
            raise SourceError.at(source, pos, unknown("key", name, allowed, f" in {label}"))


def _first_subtable(text: str, name: str) -> Pos | None:
    """The first ``[name.x]`` header: a table that has sub-tables only."""
    for n, line in enumerate(text.splitlines(), 1):
        header = _HEADER.match(line)
        if header and header.group(2).split(".")[0].strip().strip("\"'") == name:
            return Pos(n, line.index("[") + 1)
    return None


_PART = r"(?:[A-Za-z0-9_-]+|\"[^\"]*\"|'[^']*')"  # a bare or quoted key
_KEY_PATH = re.compile(rf"\s*({_PART}(?:\s*\.\s*{_PART})*)\s*=\s*")


def _dotted(text: str) -> tuple[str, ...]:
    return tuple(part.strip().strip("\"'") for part in re.findall(r"\"[^\"]*\"|'[^']*'|[^.]+", text))


def locate_path(text: str, path: tuple[str, ...], value: bool = False) -> Pos | None:
    """Where the key at ``path`` is written (``value``: where its value starts; inside a string,
    the character after the opening quote), or ``None`` when it cannot be found.

    Understands table headers (``[skills.navigate]``, ``[[skillsets]]``), dotted keys and
    one-line inline tables (``states = { Low = "percentage < 0.2" }``); a ``[[...]]`` array
    of tables is addressed by its name alone (its first entry).  Binding files use it: their
    conditions are strings inside inline tables, and errors point into them.  Cost: one pass
    over the text.
    """
    table: tuple[str, ...] = ()
    for n, line in enumerate(text.splitlines(), 1):
        header = _HEADER.match(line)
        if header:
            table = _dotted(header.group(2))
            if table == path and not value:
                return Pos(n, line.index("[") + 1)
            continue
        column = 0
        scope = table
        while True:
            key = _KEY_PATH.match(line, column)
            if key is None:
                break
            full = scope + _dotted(key.group(1))
            if full == path:
                return Pos(n, key.end() + 1 + (line[key.end():key.end() + 1] in "\"'")) if value else \
                    Pos(n, key.start(1) + 1)
            if path[: len(full)] != full or line[key.end():key.end() + 1] != "{":
                break
            scope, column = full, key.end() + 1  # into the inline table
            while True:  # skip to the next key of the inline table that could be on the path
                inner = _KEY_PATH.match(line, column)
                if inner is None:
                    break
                keys = _dotted(inner.group(1))
                if scope + keys == path[: len(scope) + len(keys)]:
                    break
                end = _value_end(line, inner.end())
                column = end + 1 if end < len(line) and line[end] == "," else end
    return None


def _value_end(line: str, start: int) -> int:
    """Index just after the value starting at ``start`` of an inline table (a string, or up to , or })."""
    if start < len(line) and line[start] in "\"'":
        close = line.find(line[start], start + 1)
        return len(line) if close < 0 else close + 1
    depth, i = 0, start
    while i < len(line):
        c = line[i]
        if c in "[{":
            depth += 1
        elif c in "]}":
            if depth == 0:
                return i
            depth -= 1
        elif c == "," and depth == 0:
            return i
        i += 1
    return i
