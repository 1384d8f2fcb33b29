"""Turn lark syntax errors into ``FILE:LINE:COL: error: ...`` diagnostics."""

from __future__ import annotations

from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

from skinet.errors import Pos, SourceError

_READABLE = {
    "NAME": "name", "IDENT": "identifier", "IDENTIFIER": "identifier", "NUMBER": "number",
    "LBRACE": "'{'", "RBRACE": "'}'", "LPAR": "'('", "RPAR": "')'", "LSQB": "'['", "RSQB": "']'",
    "COLON": "':'", "COMMA": "','", "DOT": "'.'", "EQUAL": "'='", "MORETHAN": "'>'", "LESSTHAN": "'<'",
    "_NL": "end of line", "$END": "end of input", "TEMPORAL": "temporal operator", "QUANT": "'E' or 'A'",
}


def readable(terminal: str) -> str:
    """A user-facing name for a lark terminal (``RBRACE`` -> ``'}'``)."""
    if terminal in _READABLE:
        return _READABLE[terminal]
    if terminal.startswith("__ANON") or terminal.startswith("ANON"):
        return "token"
    return f"'{terminal.lower()}'" if terminal.isupper() else f"'{terminal}'"


def syntax_error(exc: UnexpectedInput, text: str, source: str) -> SourceError:
    """A :class:`SourceError` at the position of ``exc`` naming what was expected."""
    expected: set[str] = set()
    if isinstance(exc, UnexpectedToken):
        expected = set(exc.accepts or exc.expected)
        token = exc.token
        if token.type == "$END":
            found = "end of input"
        else:
            found = "end of line" if token.type == "_NL" else f"'{token}'"
    elif isinstance(exc, UnexpectedCharacters):
        expected = set(exc.allowed or ())
        found = f"character '{text[exc.pos_in_stream]}'" if exc.pos_in_stream < len(text) else "end of input"
    elif isinstance(exc, UnexpectedEOF):
        expected = set(exc.expected)
        found = "end of input"
    else:  # pragma: no cover - lark has no other subclasses
        found = "input"
    line, column = _position(exc, text)
    names = sorted({readable(t) for t in expected})
    message = f"unexpected {found}"
    if names:
        message += f", expected {names[0]}" if len(names) == 1 else f", expected one of: {', '.join(names)}"
    return SourceError.at(source, Pos(line, column), message)


def _position(exc: UnexpectedInput, text: str) -> tuple[int, int]:
    line = getattr(exc, "line", -1)
    column = getattr(exc, "column", -1)
    if line is None or line < 1:
        lines = text.split("\n")
        return len(lines), len(lines[-1]) + 1
    return line, column
