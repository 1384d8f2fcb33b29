"""Turn lark syntax errors into ``FILE:LINE:COL: error: ...`` diagnostics.

Shared by the skillset grammar and the property/CTL grammar.
"""

from __future__ import annotations

from typing import Any

from lark import Lark, Token
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from skinet.errors import Diagnostic, Pos, SourceError

_MAX_EXPECTED = 10
_DISPLAY = {"$END": "end of input", "NAME": "identifier", "NUMBER": "number", "_NL": "end of line"}


def syntax_error(parser: Lark, exc: UnexpectedInput, text: str, source: str) -> SourceError:
    """:func:`syntax_diagnostic` wrapped in a :class:`SourceError`."""
    return SourceError([syntax_diagnostic(parser, exc, text, source)])


def syntax_diagnostic(parser: Lark, exc: UnexpectedInput, text: str, source: str) -> Diagnostic:
    """A readable ``unexpected 'X', expected one of: ...`` diagnostic."""
    if isinstance(exc, UnexpectedToken):
        expected = _expected_before(parser, text, exc.token) or exc.accepts or exc.expected
        if exc.token.type == "$END":
            stripped = text.rstrip()
            line = stripped.count("\n") + 1
            column = len(stripped) - (stripped.rfind("\n") + 1) + 1
            found = "end of input"
            return Diagnostic(source, Pos(line, column), "error", f"unexpected {found}, expected {_expected_text(parser, expected)}")
        found = "end of line" if exc.token.type == "_NL" else f"'{exc.token}'"
        return Diagnostic(
            source, Pos(exc.line, exc.column), "error", f"unexpected {found}, expected {_expected_text(parser, expected)}"
        )
    if isinstance(exc, UnexpectedCharacters):
        if text.startswith("/*", exc.pos_in_stream):
            return Diagnostic(source, Pos(exc.line, exc.column), "error", "unterminated comment '/*'")
        char = text[exc.pos_in_stream] if exc.pos_in_stream < len(text) else ""
        return Diagnostic(
            source, Pos(exc.line, exc.column), "error",
            f"unexpected character '{char}', expected {_expected_text(parser, exc.allowed)}",
        )
    return Diagnostic(  # pragma: no cover - lark's LALR raises only the two above
        source, Pos(exc.line, exc.column), "error", "syntax error"
    )


def _expected_before(parser: Lark, text: str, failing: Token) -> set[str] | None:
    """Terminals acceptable just before ``failing`` was read.

    LALR reduces on the failing lookahead before noticing the error, which would
    shrink the expected set (``(a == b }`` would only list ``')'`` and ``'=>'``);
    replaying the parse interactively and stopping before that token gives the
    full set.  Only runs on the error path.
    """
    interactive = parser.parse_interactive(text)
    try:
        for token in interactive.iter_parse():
            if token.start_pos == failing.start_pos and token.type == failing.type:
                return set(interactive.accepts())
    except UnexpectedInput:
        return None
    if failing.type == "$END":
        return set(interactive.accepts())
    return None


def _expected_text(parser: Lark, names: Any) -> str:
    """``one of: '{', identifier`` from a set of terminal names."""
    shown = sorted({d for d in (_terminal_display(parser, n) for n in names or ()) if d})
    if not shown:
        return "nothing"
    if len(shown) == 1:
        return shown[0]
    if len(shown) > _MAX_EXPECTED:
        shown = shown[:_MAX_EXPECTED] + ["..."]
    return "one of: " + ", ".join(shown)


def _terminal_display(parser: Lark, name: str) -> str | None:
    """Readable form of a terminal (``'{'``, ``identifier``); None for ignored ones."""
    if name in _DISPLAY:
        return _DISPLAY[name]
    if name in parser.ignore_tokens:
        return None
    for term in parser.terminals:
        if term.name == name:
            if term.pattern.type == "str":
                return f"'{term.pattern.value}'"
            return None
    return None
