"""TOML texts (system and scenario files) with every decoder failure as a SourceError.

``tomllib`` reports a syntax error "at end of document" without a position and
recurses on nested arrays and tables: both become one ``FILE:LINE:COL`` error.
Pure; cost linear in the text.
"""

from __future__ import annotations

import re
import tomllib

from skinet.errors import Pos, SourceError


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


_HEADER = re.compile(r"\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_PART = r"(?:[A-Za-z0-9_-]+|\"[^\"]*\"|'[^']*')"  # a bare or quoted key
_KEY = re.compile(rf"\s*({_PART}(?:\s*\.\s*{_PART})*)\s*=\s*")


def _dotted(text: str) -> tuple[str, ...]:
    return tuple(part.strip().strip("\"'") for part in re.findall(r"\"[^\"]*\"|'[^']*'|[^.]+", text))


def locate(text: str, path: tuple[str, ...], value: bool = False) -> Pos | None:
    """Where the key at ``path`` is written (``value``: where its value starts; inside a string,
    the character after the opening quote), or ``None`` when it cannot be found.

    Understands table headers (``[skills.navigate]``, ``[[skillsets]]``), dotted keys and
    one-line inline tables (``states = { Low = "percentage < 0.2" }``); a ``[[...]]`` array
    of tables is addressed by its name alone (its first entry).  Cost: one pass over the text.
    """
    table: tuple[str, ...] = ()
    for n, line in enumerate(text.splitlines(), 1):
        header = _HEADER.match(line)
        if header:
            table = _dotted(header.group(1))
            if table == path and not value:
                return Pos(n, line.index("[") + 1)
            continue
        column = 0
        scope = table
        while True:
            key = _KEY.match(line, column)
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
                inner = _KEY.match(line, column)
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
