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
