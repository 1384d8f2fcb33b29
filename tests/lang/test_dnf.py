"""Disjunctive normal form of skillset guards and its effect on nets (docs/semantics.md §3, *Guards*)."""

from __future__ import annotations

import pytest

from skinet.lang.dnf import dnf
from skinet.lang.expr import And, Const, Expr, Implies, Not, Or, StateAtom
from skinet.lang.parser import parse_skillset
from skinet.net.build import build_net

RESOURCES = """
    resource {
        a { state { x y } initial x transition all }
        b { state { x y } initial x transition all }
        c { state { x y z } initial x transition all }
    }
"""
STATES = {"a": ("x", "y"), "b": ("x", "y"), "c": ("x", "y", "z")}


def guard(text: str) -> Expr:
    """The expression of a precondition, parsed by the real parser."""
    ss = parse_skillset(f"skillset s {{ {RESOURCES} skill k {{ precondition p: {text} }} }}")
    return ss.skill("k").preconditions[0].expr


def clauses(text: str) -> list[dict[str, str]]:
    return dnf(guard(text), STATES)


def start_variants(precondition_block: str, start: str = "") -> dict[str, tuple[list[str], list[str]]]:
    ss = parse_skillset(f"skillset s {{ {RESOURCES} skill k {{ {precondition_block} {start} }} }}")
    net = build_net(ss)
    return {
        t.id: (sorted(net.places[i] for i in t.pre), sorted(net.places[i] for i in t.post))
        for t in net.transitions
        if t.name == "k.start"
    }


# ---------------------------------------------------------------------------
# dnf itself


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        # != expands to the other states, in declaration order
        ("c != x", [{"c": "y"}, {"c": "z"}]),
        ("c != y", [{"c": "x"}, {"c": "z"}]),
        ("not c == z", [{"c": "x"}, {"c": "y"}]),
        ("a != x", [{"a": "y"}]),
        ("c != x and c != y", [{"c": "z"}]),
        ("c != x or c != y", [{"c": "y"}, {"c": "z"}, {"c": "x"}]),
        # a => b is not a or b
        ("a == x => b == y", [{"a": "y"}, {"b": "y"}]),
        ("c == x => c == y", [{"c": "y"}, {"c": "z"}]),
        ("a == x => false", [{"a": "y"}]),
        ("false => a == x", [{}, {"a": "x"}]),
        # => is the weakest operator and associates to the left (grammar)
        ("a == x => b == x => c == z", [{"a": "x", "b": "y"}, {"c": "z"}]),
        ("a == x or b == x => c == z", [{"a": "y", "b": "y"}, {"c": "z"}]),
        # precedence: and binds tighter than or, not tighter than and
        ("a == x or b == x and c == z", [{"a": "x"}, {"b": "x", "c": "z"}]),
        ("not a == x and b == x", [{"a": "y", "b": "x"}]),
        # nested not / and / or (De Morgan, double negation)
        ("not (a == x and (b == y or c != z))", [{"a": "y"}, {"b": "x", "c": "z"}]),
        ("not (a == x or b == x)", [{"a": "y", "b": "y"}]),
        ("not not a == x", [{"a": "x"}]),
        ("not (not (a == x) or not (c == y))", [{"a": "x", "c": "y"}]),
        ("(a == x or a == y) and (c == x or c == z)",
         [{"a": "x", "c": "x"}, {"a": "x", "c": "z"}, {"a": "y", "c": "x"}, {"a": "y", "c": "z"}]),
        # contradictory clauses are dropped
        ("a == x and a == y", []),
        ("(a == x or b == x) and a == y", [{"a": "y", "b": "x"}]),
        ("c == x and c != x", []),
        ("(a == x and b == x) or (a == y and a == x) or b == y", [{"a": "x", "b": "x"}, {"b": "y"}]),
        # constants
        ("false", []),
        ("not true", []),
        ("a == x and false", []),
        ("a == x or false", [{"a": "x"}]),
        ("true", [{}]),
        ("not false", [{}]),
        ("true and a == x", [{"a": "x"}]),
        # no subsumption: `true` does not absorb the other clause
        ("a == x or true", [{"a": "x"}, {}]),
        # duplicates are removed, first occurrence kept
        ("a == x or a == x", [{"a": "x"}]),
        ("a == x and a == x", [{"a": "x"}]),
        ("(a == x and b == y) or (b == y and a == x)", [{"a": "x", "b": "y"}]),
        ("b == y or a == x or b == y", [{"b": "y"}, {"a": "x"}]),
    ],
)
def test_dnf(text: str, expected: list[dict[str, str]]) -> None:
    assert clauses(text) == expected


def test_dnf_none_is_true() -> None:
    assert dnf(None, STATES) == [{}]


def test_dnf_on_hand_built_expressions() -> None:
    ax, by = StateAtom("a", "x"), StateAtom("b", "y")
    assert dnf(Implies(ax, by), STATES) == [{"a": "y"}, {"b": "y"}]
    assert dnf(Not(Or(ax, Not(by))), STATES) == [{"a": "y", "b": "y"}]
    assert dnf(And(ax, Const(False)), STATES) == []
    assert dnf(Or(ax, ax), STATES) == [{"a": "x"}]
    assert dnf(Const(True), STATES) == [{}]


def test_dnf_rejects_foreign_atoms() -> None:
    with pytest.raises(TypeError, match="not a skillset expression"):
        dnf(And(StateAtom("a", "x"), "oops"), STATES)


def test_parsed_ne_is_not_of_atom() -> None:
    assert guard("c != x") == Not(StateAtom("c", "x"))


# ---------------------------------------------------------------------------
# How clauses become variants of one logical transition


def test_ne_over_three_states_gives_two_start_variants() -> None:
    assert start_variants("precondition p: c != x") == {
        "k.start": (["c.y", "e_k"], ["c.y", "i_k"]),
        "k.start#2": (["c.z", "e_k"], ["c.z", "i_k"]),
    }


def test_or_gives_one_variant_per_clause() -> None:
    assert start_variants("precondition p: a == x or b == y") == {
        "k.start": (["a.x", "e_k"], ["a.x", "i_k"]),
        "k.start#2": (["b.y", "e_k"], ["b.y", "i_k"]),
    }


def test_implies_variants() -> None:
    assert start_variants("precondition p: a == x => c == z") == {
        "k.start": (["a.y", "e_k"], ["a.y", "i_k"]),
        "k.start#2": (["c.z", "e_k"], ["c.z", "i_k"]),
    }


def test_preconditions_are_conjoined_before_dnf() -> None:
    block = "precondition { p: a == x or a == y q: c != z }"
    assert start_variants(block) == {
        "k.start": (["a.x", "c.x", "e_k"], ["a.x", "c.x", "i_k"]),
        "k.start#2": (["a.x", "c.y", "e_k"], ["a.x", "c.y", "i_k"]),
        "k.start#3": (["a.y", "c.x", "e_k"], ["a.y", "c.x", "i_k"]),
        "k.start#4": (["a.y", "c.y", "e_k"], ["a.y", "c.y", "i_k"]),
    }


def test_clause_and_effect_sources_multiply() -> None:
    # clause {a: y} or {b: y}; effect c -> z takes every source state of c
    assert start_variants("precondition p: a != x or b == y", "start c -> z") == {
        "k.start": (["a.y", "c.x", "e_k"], ["a.y", "c.z", "i_k"]),
        "k.start#2": (["a.y", "c.y", "e_k"], ["a.y", "c.z", "i_k"]),
        "k.start#3": (["a.y", "c.z", "e_k"], ["a.y", "c.z", "i_k"]),
        "k.start#4": (["b.y", "c.x", "e_k"], ["b.y", "c.z", "i_k"]),
        "k.start#5": (["b.y", "c.y", "e_k"], ["b.y", "c.z", "i_k"]),
        "k.start#6": (["b.y", "c.z", "e_k"], ["b.y", "c.z", "i_k"]),
    }


def test_clause_fixing_an_effect_resource_fixes_its_source() -> None:
    assert start_variants("precondition p: c == y", "start c -> z") == {
        "k.start": (["c.y", "e_k"], ["c.z", "i_k"]),
    }


def test_false_precondition_gives_no_start() -> None:
    assert start_variants("precondition p: false") == {}
    assert start_variants("precondition { p: a == x q: a == y }") == {}
    assert start_variants("precondition p: c == x and c != x") == {}


def test_true_precondition_gives_one_start() -> None:
    assert start_variants("precondition p: true") == {"k.start": (["e_k"], ["i_k"])}
    assert start_variants("") == {"k.start": (["e_k"], ["i_k"])}


def test_duplicate_clauses_give_one_variant() -> None:
    assert start_variants("precondition p: (a == x and b == y) or (b == y and a == x)") == {
        "k.start": (["a.x", "b.y", "e_k"], ["a.x", "b.y", "i_k"]),
    }


def test_true_disjunct_is_not_absorbed() -> None:
    # No subsumption: both variants exist and both are enabled when a == x.
    assert start_variants("precondition p: a == x or true") == {
        "k.start": (["a.x", "e_k"], ["a.x", "i_k"]),
        "k.start#2": (["e_k"], ["i_k"]),
    }


def _net(body: str):
    return build_net(parse_skillset(f"skillset s {{ {RESOURCES} {body} }}"))


def test_invariant_guard_is_negated() -> None:
    net = _net("skill k { invariant j { guard c == x } }")
    assert [(t.id, sorted(net.places[i] for i in t.pre)) for t in net.transitions if t.is_invariant] == [
        ("k.inv.j", ["c.y", "i_k"]),
        ("k.inv.j#2", ["c.z", "i_k"]),
    ]


def test_invariant_true_never_fails_invariant_false_always_fails() -> None:
    net = _net("skill k { invariant { ok { guard true } ko { guard false } } }")
    invariants = [t for t in net.transitions if t.is_invariant]
    assert [t.id for t in invariants] == ["k.inv.ko"]
    assert (invariants[0].pre, invariants[0].post) == (
        frozenset({net.place_index("i_k")}),
        frozenset({net.place_index("e_k")}),
    )


def test_event_guard_false_gives_no_transition() -> None:
    net = _net("event { never { guard false effect a -> y } always { guard true } }")
    assert [t.id for t in net.transitions] == ["always"]
    assert (net.transitions[0].pre, net.transitions[0].post) == (frozenset(), frozenset())


def test_event_ne_guard_with_effect_on_the_same_resource() -> None:
    net = _net("event e { guard c != y effect c -> y }")
    assert [(t.id, net.marked(t.pre_mask), net.marked(t.post_mask)) for t in net.transitions] == [
        ("e", ["c.x"], ["c.y"]),
        ("e#2", ["c.z"], ["c.y"]),
    ]
