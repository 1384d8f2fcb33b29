"""Deep or huge property and CTL texts give one clear error, never a crash (docs/semantics.md §4, §6)."""

from __future__ import annotations

import pytest

from skinet.errors import SourceError
from skinet.props.parser import parse_formula, parse_properties
from tests.conftest import load_paper_skillset

SKILLSETS = {ss.name: ss for ss in (load_paper_skillset("spot.rl"), load_paper_skillset("manipulator.rl"))}
NESTED = "expression nested too deeply (more than 100 levels of operators); split it into several named parts"


def formula_error(text: str) -> str:
    with pytest.raises(SourceError) as info:
        parse_formula(text, SKILLSETS)
    return str(info.value)


def test_nesting_limit_in_a_property() -> None:
    ok = "p = " + "not " * 100 + "spot:Busy\n"
    assert len(parse_properties(ok, SKILLSETS, "p.props")) == 1
    with pytest.raises(SourceError) as info:
        parse_properties("p = " + "not " * 101 + "spot:Busy\n", SKILLSETS, "p.props")
    assert str(info.value) == f"p.props:1:405: error: {NESTED}"


@pytest.mark.parametrize("op", ["not ", "AG ", "EX not ", "spot:Busy and ", "spot:Busy or ", "spot:Busy => "])
def test_two_kilobytes_of_operators_in_ctl(op: str) -> None:
    assert formula_error(op * (2048 // len(op)) + "spot:Busy").endswith(NESTED)


def test_nested_until() -> None:
    text = "E[spot:Busy U " * 101 + "spot:Busy" + "]" * 101
    assert formula_error(text) == f"<formula>:1:1401: error: {NESTED}"


def test_formula_size_limit() -> None:
    assert formula_error("(" * 70_000) == "<formula>: error: input too large: 70000 characters (the limit is 65536)"


def test_deep_parentheses() -> None:
    assert str(parse_formula("(" * 3000 + "spot:Busy" + ")" * 3000, SKILLSETS)) == "spot:Busy"
