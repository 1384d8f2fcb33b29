"""Syntax errors are one readable diagnostic, never a lark traceback (docs/semantics.md §2)."""

from __future__ import annotations

import pytest

from skinet.errors import SourceError
from skinet.lang.larkerrors import _expected_text as _expected_in
from skinet.lang.parser import _parser, parse_model, parse_skillset

SKILL_KEYWORDS = (
    "'failure', 'input', 'interrupt', 'invariant', 'output', 'precondition', "
    "'progress', 'start', 'success', '}'"
)


def syntax_error(text: str) -> str:
    with pytest.raises(SourceError) as info:
        parse_model(text, "f.rl")
    assert len(info.value.diagnostics) == 1
    assert info.value.__cause__ is None and info.value.__suppress_context__
    return str(info.value)


@pytest.mark.parametrize(
    "text, message",
    [
        ("skillset s { skill k { foo } }", f"1:24: error: unexpected 'foo', expected one of: {SKILL_KEYWORDS}"),
        ("skillset s { skill k { precondition p: r == } }", "1:45: error: unexpected '}', expected identifier"),
        (
            "skillset s {\n  skill k { precondition p: (r == A }\n}",
            "2:37: error: unexpected '}', expected one of: ')', '=>', 'and', 'or'",
        ),
        (
            "skillset s { event e { guard r == A and } }",
            "1:41: error: unexpected '}', expected one of: '(', 'false', 'not', 'true', identifier",
        ),
        ("skillset s { data { x: y: T } }", "1:25: error: unexpected ':', expected one of: 'period', '}', identifier"),
        ("type { A }\ntype B C\nskillset s {}", "2:8: error: unexpected 'C', expected one of: 'skillset', 'type'"),
        ("skillset s { skill k { progress { period fast } } }", "1:42: error: unexpected 'fast', expected number"),
        (
            "skillset s { skill k { interrupt { interrupting maybe } } }",
            "1:49: error: unexpected 'maybe', expected one of: 'false', 'true'",
        ),
        ("skillset s<T,> {}", "1:14: error: unexpected '>', expected identifier"),
        ("skillset s { event e { effect r -> } }", "1:36: error: unexpected '}', expected identifier"),
    ],
)
def test_unexpected_token(text: str, message: str) -> None:
    assert syntax_error(text) == f"f.rl:{message}"


@pytest.mark.parametrize(
    "text, message",
    [
        ("skillset s { event e { guard r = A } }", "1:32: error: unexpected character '=', expected one of: '!=', '=='"),
        ("skillset s # {}", "1:12: error: unexpected character '#', expected one of: '<', '{'"),
        (
            "skillset s { resource r { state { A } initial A transition { A - B } } }",
            "1:64: error: unexpected character '-', expected '->'",
        ),
        ("skillset s { /* never closed }", "1:14: error: unterminated comment '/*'"),
    ],
)
def test_unexpected_character(text: str, message: str) -> None:
    assert syntax_error(text) == f"f.rl:{message}"


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "1:1: error: unexpected end of input, expected one of: 'skillset', 'type'"),
        ("type A", "1:7: error: unexpected end of input, expected one of: 'skillset', 'type'"),
        (
            "skillset s {",
            "1:13: error: unexpected end of input, expected one of: 'data', 'event', 'resource', 'skill', '}'",
        ),
        (
            "skillset s {\n  skill k {\n\n",
            f"2:12: error: unexpected end of input, expected one of: {SKILL_KEYWORDS}",
        ),
        (
            "skillset s {\n// done\n",
            "2:8: error: unexpected end of input, expected one of: 'data', 'event', 'resource', 'skill', '}'",
        ),
    ],
)
def test_unexpected_end_of_input(text: str, message: str) -> None:
    assert syntax_error(text) == f"f.rl:{message}"


def test_default_source_name() -> None:
    with pytest.raises(SourceError) as info:
        parse_skillset("skillset")
    assert str(info.value) == "<string>:1:9: error: unexpected end of input, expected identifier"


def _expected_text(names: object) -> str:
    return _expected_in(_parser(), names)


def test_expected_list_is_capped() -> None:
    assert _expected_text({"NAME", "NUMBER"}) == "one of: identifier, number"
    assert _expected_text(set()) == "nothing"
    many = [
        "SKILLSET", "STATE", "INITIAL", "TRANSITION", "GUARD", "PROGRESS", "PERIOD",
        "SUCCESS", "FAILURE", "NOT", "TRUE", "FALSE", "NAME",
    ]  # fmt: skip
    text = _expected_text(many)
    assert text.startswith("one of: 'failure', 'false', 'guard'")
    assert text.endswith(", ...") and text.count(", ") == 10
    # ignored and unknown terminals are dropped
    assert _expected_text({"NAME", "LINE_COMMENT", "NO_SUCH_TERMINAL"}) == "identifier"
