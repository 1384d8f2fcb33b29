"""Turn lark syntax errors into ``FILE:LINE:COL: error: ...`` diagnostics.

Shared by the skillset grammar and the property/CTL grammar.
"""

from __future__ import annotations

from typing import Any

from lark import Lark, Token, Tree
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from skinet.errors import Diagnostic, Pos, SourceError

_MAX_EXPECTED = 10
_DISPLAY = {"$END": "end of input", "NAME": "identifier", "NUMBER": "number", "_NL": "end of line",
            "REACH": "'reach'", "RUN": "'run'", "FORMULA": "a formula"}  # the last three: goals (skinet/plan)
# Accepted but not suggested: `parameter` sections and `include` only exist in old
# ONERA dialects (robot_language 2022, rl_model 2023), and listing them would push the keywords
# every file uses past the cap of an expected list.
_UNSUGGESTED = frozenset({"PARAMETER", "INCLUDE"})


# Deepest nesting of operators accepted in one expression.  The expression walkers
# of the core (DNF, evaluation, CTL, rendering) recurse once or twice per level,
# so this keeps every one of them far below Python's recursion limit of 1000.
# Real guards and properties nest fewer than ten operators.
MAX_NESTING = 100

# Largest source text accepted, in characters (256 KiB).  Real skillset files are
# about 10 KB.  Parsing costs up to about 550 bytes of memory and 30 us per input
# character (lark), so any accepted text parses within about 150 MB and 10 s.
MAX_SOURCE_CHARS = 2**18
# Largest properties file or CTL formula (64 KiB); real ones are under 1 KB.
MAX_FORMULA_CHARS = 2**16


def check_size(text: str, source: str, limit: int = MAX_SOURCE_CHARS) -> None:
    """Refuse a text longer than ``limit`` characters before parsing it."""
    if len(text) > limit:
        raise SourceError.at(source, None, f"input too large: {len(text)} characters (the limit is {limit})")


def check_nesting(tree: Tree, operators: frozenset[str], source: str) -> None:
    """Refuse an expression nesting more than :data:`MAX_NESTING` operators.

    Iterative (the tree may be arbitrarily deep); cost linear in the tree size.
    ``operators`` are the names of the tree nodes that count as one level.
    """
    stack: list[tuple[Tree, int]] = [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        if node.data in operators:
            depth += 1
            if depth > MAX_NESTING:
                meta = node.meta
                pos = Pos(meta.line, meta.column) if not meta.empty else None
                raise SourceError.at(
                    source, pos,
                    f"expression nested too deeply (more than {MAX_NESTING} levels of operators);"
                    " split it into several named parts",
                )
        stack.extend((child, depth) for child in node.children if isinstance(child, Tree))


# Said instead of the offending text where the text must not be shown (an included file).
UNQUOTED = "text (not quoted from an included file)"


def syntax_error(parser: Lark, exc: UnexpectedInput, text: str, source: str) -> SourceError:
    """:func:`syntax_diagnostic` wrapped in a :class:`SourceError`."""
    return SourceError([syntax_diagnostic(parser, exc, text, source)])


def syntax_diagnostic(parser: Lark, exc: UnexpectedInput, text: str, source: str, quote: bool = True) -> Diagnostic:
    """A readable ``unexpected 'X', expected one of: ...`` diagnostic.

    Without ``quote`` the offending token or character is not shown, only its
    position (an included file may be anything: a secret must not be echoed).
    """
    if isinstance(exc, UnexpectedToken):
        expected = _expected_before(parser, text, exc.token) or exc.accepts or exc.expected
        if exc.token.type == "$END":
            stripped = text.rstrip()
            line = stripped.count("\n") + 1
            column = len(stripped) - (stripped.rfind("\n") + 1) + 1
            found = "end of input"
            return Diagnostic(source, Pos(line, column), "error", f"unexpected {found}, expected {_expected_text(parser, expected)}")
        found = "end of line" if exc.token.type == "_NL" else f"'{exc.token}'" if quote else UNQUOTED
        return Diagnostic(
            source, Pos(exc.line, exc.column), "error", f"unexpected {found}, expected {_expected_text(parser, expected)}"
        )
    if isinstance(exc, UnexpectedCharacters):
        if text.startswith("/*", exc.pos_in_stream):
            return Diagnostic(source, Pos(exc.line, exc.column), "error", "unterminated comment '/*'")
        char = text[exc.pos_in_stream] if exc.pos_in_stream < len(text) else ""
        found = f"character '{char}'" if quote else UNQUOTED
        return Diagnostic(
            source, Pos(exc.line, exc.column), "error",
            f"unexpected {found}, expected {_expected_text(parser, exc.allowed)}",
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
    if name in parser.lexer_conf.ignore or name in _UNSUGGESTED:
        return None
    for term in parser.terminals:
        if term.name == name:
            if term.pattern.type == "str":
                return f"'{term.pattern.value}'"
            return None
    return None
