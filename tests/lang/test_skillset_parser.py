"""Every dialect form of the skillset language parses (docs/semantics.md §2)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skinet.errors import Pos, SourceError
from skinet.lang.expr import And, Const, Expr, Implies, Not, Or, StateAtom, to_text
from skinet.lang.model import Effect, Model, Skill, Skillset
from skinet.lang.parser import _parser, parse_model, parse_skillset

# Two resources with states every test below may use.
RESOURCES = """
    resource {
        a { state { x y } initial x transition all }
        b { state { x y } initial x transition all }
        c { state { x y z } initial x transition all }
        d { state { w v } initial w transition all }
    }
"""


def ss(body: str, header: str = "") -> Skillset:
    """Parse one skillset whose body is ``RESOURCES`` plus ``body``."""
    return parse_skillset(f"{header}\nskillset s {{\n{RESOURCES}\n{body}\n}}\n")


def skill(body: str) -> Skill:
    return ss(f"skill k {{\n{body}\n}}").skill("k")


def eff(effects: tuple[Effect, ...]) -> list[tuple[str, str]]:
    return [(e.resource, e.state) for e in effects]


def expr(text: str) -> Expr:
    return skill(f"precondition p: {text}").preconditions[0].expr


# ---- file level -------------------------------------------------------------


def test_grammar_loaded_once() -> None:
    assert _parser() is _parser()


def test_type_lines_and_blocks() -> None:
    model = parse_model("type A\ntype B\ntype { C D }\ntype {}\nskillset s {}\ntype E\n")
    assert [t.name for t in model.types] == ["A", "B", "C", "D", "E"]
    assert model.types[0].pos == Pos(1, 6)
    assert model.skillsets[0].types == model.types


def test_no_types_and_empty_skillset() -> None:
    model = parse_model("skillset empty {}")
    assert model.types == ()
    assert model.source == "<string>"
    empty = model.skillsets[0]
    assert (empty.name, empty.pos, empty.source) == ("empty", Pos(1, 10), "<string>")
    assert (empty.resources, empty.events, empty.skills, empty.data) == ((), (), (), ())


def test_several_skillsets_and_type_params() -> None:
    model = parse_model("skillset one<T, U> { data x: T }\nskillset two {}", "f.rl")
    assert [s.name for s in model.skillsets] == ["one", "two"]
    assert model.skillsets[0].type_params == ("T", "U")
    assert model.skillsets[1].type_params == ()
    assert model.warnings == ()
    assert all(s.source == "f.rl" for s in model.skillsets)


def test_parse_skillset_wants_exactly_one() -> None:
    with pytest.raises(SourceError) as info:
        parse_skillset("skillset one {}\nskillset two {}", "f.rl")
    assert str(info.value) == (
        "f.rl:2:10: error: expected exactly one skillset, found 2 ('two' is the second)"
    )


def test_comments() -> None:
    text = """// header
    /* block
       comment */ type T // trailing
    skillset s { /* inline */ data x: T // end
    }"""
    model = parse_model(text)
    assert [t.name for t in model.types] == ["T"]
    assert [d.name for d in model.skillsets[0].data] == ["x"]


# ---- data, resources, events ----------------------------------------------------


def test_data_single_repeated_and_block() -> None:
    s = parse_skillset("type {T U}\nskillset s { data x: T data y: U data { z: T w: U } }")
    assert [(d.name, d.type) for d in s.data] == [("x", "T"), ("y", "U"), ("z", "T"), ("w", "U")]
    assert (s.data[0].pos, s.data[0].type_pos) == (Pos(2, 19), Pos(2, 22))


def test_resource_forms() -> None:
    s = parse_skillset(
        """skillset s {
        resource r1 { state { A B C D } initial A transition { A -> B C -> D } }
        resource {
            r2 { transition all initial B state { A B } }
            r3 {
                state { A B }
                initial A
                transition {
                    A -> B
                    B -> A
                }
            }
            r4 { state { A B } initial A transition A -> B }
            r5 { state { A } initial A }
        }
    }"""
    )
    r1, r2, r3, r4, r5 = s.resources
    assert r1.transitions == (("A", "B"), ("C", "D"))
    assert r1.transition_pos == (Pos(2, 64), Pos(2, 71))
    assert r1.transition_target_pos == (Pos(2, 69), Pos(2, 76))
    assert r1.state_pos == (Pos(2, 31), Pos(2, 33), Pos(2, 35), Pos(2, 37))
    assert r1.initial_pos == Pos(2, 49)
    assert (r2.transitions, r2.initial, r2.states) == (None, "B", ("A", "B"))
    assert r3.transitions == (("A", "B"), ("B", "A"))
    assert r4.transitions == (("A", "B"),)
    assert r5.transitions == ()  # no `transition` clause: only identity moves
    assert r2.allows("A", "B") and not r4.allows("B", "A") and r5.allows("A", "A")


def test_event_forms() -> None:
    s = ss(
        """
        event only_guard { guard a == x }
        event only_effect { effect a -> y }
        event {
            both { guard a == y effect { a -> x b -> y } }
            nothing {}
            repeated { effect a -> x effect b -> y }
        }
        """
    )
    assert [e.name for e in s.events] == ["only_guard", "only_effect", "both", "nothing", "repeated"]
    g, e, both, nothing, repeated = s.events
    assert g.guard == StateAtom("a", "x") and g.effects == ()
    assert e.guard is None and eff(e.effects) == [("a", "y")]
    assert both.guard == StateAtom("a", "y")
    assert eff(both.effects) == [("a", "x"), ("b", "y")]
    assert (nothing.guard, nothing.effects) == (None, ())
    assert eff(repeated.effects) == [("a", "x"), ("b", "y")]


# ---- skills ---------------------------------------------------------------------


def test_skill_single_and_block_sections() -> None:
    s = ss("skill one {}\nskill { two {} three {} }")
    assert [k.name for k in s.skills] == ["one", "two", "three"]
    one = s.skills[0]
    assert one == Skill("one", pos=one.pos)
    assert not one.interrupt.declared


def test_inputs_and_outputs() -> None:
    k = skill("input i: T input { j: U l: V } output o: T output { p: U }")
    assert [(v.name, v.type) for v in k.inputs] == [("i", "T"), ("j", "U"), ("l", "V")]
    assert [(v.name, v.type) for v in k.outputs] == [("o", "T"), ("p", "U")]


def test_preconditions_single_and_block() -> None:
    k = skill("precondition p1: a == x\nprecondition { p2: b != y p3 : true }")
    assert [p.name for p in k.preconditions] == ["p1", "p2", "p3"]
    assert k.preconditions[1].expr == Not(StateAtom("b", "y"))
    assert k.preconditions[2].expr == Const(True)


def test_start_forms() -> None:
    assert eff(skill("start a -> y").start) == [("a", "y")]
    assert eff(skill("start { a -> y b -> y }").start) == [("a", "y"), ("b", "y")]
    assert eff(skill("start {}").start) == []


def test_invariant_forms() -> None:
    k = skill(
        """invariant single { guard a == x }
        invariant {
            i1 { guard b == x effect a -> y }
            i2 { effect { a -> y b -> y } guard true }
        }"""
    )
    assert [i.name for i in k.invariants] == ["single", "i1", "i2"]
    assert k.invariants[0].effects == ()
    assert k.invariants[1].guard == StateAtom("b", "x")
    assert eff(k.invariants[1].effects) == [("a", "y")]
    assert k.invariants[2].guard == Const(True)
    assert eff(k.invariants[2].effects) == [("a", "y"), ("b", "y")]


@pytest.mark.parametrize(
    "period, seconds",
    [("1 sec", 1.0), ("100 ms", 0.1), ("1 ms", 0.001), ("1.0", 1.0), ("2", 2.0), ("0.5 s", 0.5)],
)
def test_progress_periods(period: str, seconds: float) -> None:
    progress = skill(f"progress {{ period {period} }}").progress
    assert progress is not None
    assert progress.period_seconds == seconds
    assert progress.fields == ()


@pytest.mark.parametrize(
    "fields",
    [
        "message m: T message n: U",
        "message { m: T n: U }",
        "output m: T output n: U",
        "output { m: T } message n: U",
    ],
)
def test_progress_fields(fields: str) -> None:
    k = skill(f"progress {{ period 1 sec {fields} }}")
    assert k.progress is not None
    assert [(v.name, v.type) for v in k.progress.fields] == [("m", "T"), ("n", "U")]
    assert k.outputs == ()


def test_progress_period_after_fields_and_position() -> None:
    s = parse_skillset("skillset s { skill k { progress { message m: T period 10 ms } } }")
    progress = s.skills[0].progress
    assert progress is not None
    assert (progress.period_seconds, progress.pos) == (0.01, Pos(1, 24))


def test_interrupt_forms() -> None:
    k = skill("interrupt { interrupting true effect { a -> y } postcondition a == y }")
    i = k.interrupt
    assert (i.declared, i.interrupting) == (True, True)
    assert eff(i.effects) == [("a", "y")]
    assert i.postcondition == StateAtom("a", "y")
    assert i.pos is not None
    off = skill("interrupt { interrupting false }").interrupt
    assert (off.declared, off.interrupting, off.effects, off.postcondition) == (True, False, (), None)
    bare = skill("interrupt { effect a -> x }").interrupt
    assert (bare.declared, bare.interrupting) == (True, False)


def test_named_modes() -> None:
    k = skill(
        """success ok { effect a -> y postcondition a == y }
        success also_ok {}
        failure { f1 { effect a -> x } f2 { postcondition true } f3 {} }
        failure f4 { postcondition b == x effect b -> x }"""
    )
    assert [(m.name, m.kind) for m in k.modes] == [
        ("ok", "success"),
        ("also_ok", "success"),
        ("f1", "failure"),
        ("f2", "failure"),
        ("f3", "failure"),
        ("f4", "failure"),
    ]
    ok = k.successes[0]
    assert eff(ok.effects) == [("a", "y")] and ok.postcondition == StateAtom("a", "y")
    assert k.successes[1].effects == () and k.successes[1].postcondition is None
    assert k.failures[1].postcondition == Const(True)
    assert eff(k.failures[3].effects) == [("b", "x")]


def test_empty_mode_blocks_mean_no_modes() -> None:
    k = skill("success {} failure {}")
    assert (k.successes, k.failures) == ((), ())


def test_unnamed_modes() -> None:
    s = parse_skillset(
        "skillset s { resource r { state { A B } initial A transition all }\n"
        "skill k { success { effect r -> B } failure f {} }\n"
        "skill l { failure { postcondition r == A effect r -> A } }}"
    )
    k, l = s.skills
    assert [(m.name, m.kind) for m in k.modes] == [("", "success"), ("f", "failure")]
    assert eff(k.successes[0].effects) == [("r", "B")]
    assert k.successes[0].pos == Pos(2, 11)  # the `success` keyword
    assert [(m.name, m.kind) for m in l.modes] == [("", "failure")]
    assert l.failures[0].postcondition == StateAtom("r", "A")
    assert eff(l.failures[0].effects) == [("r", "A")]
    assert l.failures[0].pos == Pos(3, 11)


def test_skill_sections_in_any_order() -> None:
    k = skill(
        """failure f {}
        success s1 {}
        interrupt { interrupting true }
        progress { period 1 sec }
        invariant i { guard true }
        start a -> y
        precondition p: a == x
        output o: T
        input i: T
        precondition q: b == x"""
    )
    assert [p.name for p in k.preconditions] == ["p", "q"]
    assert [m.name for m in k.modes] == ["s1", "f"]
    assert k.interrupt.interrupting and k.progress is not None
    assert eff(k.start) == [("a", "y")]
    assert [v.name for v in k.inputs] == ["i"] and [v.name for v in k.outputs] == ["o"]


def test_keywords_as_identifiers() -> None:
    s = parse_skillset(
        """skillset skill {
        data state: initial
        resource { state { state { state initial } initial initial transition all } }
        event event { guard state == state effect state -> initial }
        skill skill { precondition precondition: state == initial }
    }""",
    )
    assert s.name == "skill"
    r = s.resource("state")
    assert (r.states, r.initial) == (("state", "initial"), "initial")
    assert s.event("event").guard == StateAtom("state", "state")
    assert s.skill("skill").preconditions[0].name == "precondition"


def test_positions_of_effects_and_variables() -> None:
    text = (
        "type T\n"
        "skillset s {\n"
        "  resource r { state { A B } initial A transition all }\n"
        "  skill k {\n"
        "    input i: T\n"
        "    start r -> B\n"
        "    invariant inv { guard r != A }\n"
        "    success done { postcondition not (r == B) }\n"
        "  }\n"
        "}\n"
    )
    k = parse_skillset(text).skills[0]
    assert (k.pos, k.inputs[0].pos, k.inputs[0].type_pos) == (Pos(4, 9), Pos(5, 11), Pos(5, 14))
    start = k.start[0]
    assert (start.pos, start.state_pos) == (Pos(6, 11), Pos(6, 16))
    inv = k.invariants[0]
    assert inv.pos == Pos(7, 15)
    assert isinstance(inv.guard, Not) and isinstance(inv.guard.arg, StateAtom)
    assert (inv.guard.pos, inv.guard.arg.pos, inv.guard.arg.state_pos) == (
        Pos(7, 27),
        Pos(7, 27),
        Pos(7, 32),
    )
    mode = k.successes[0]
    assert mode.pos == Pos(8, 13)
    post = mode.postcondition
    assert isinstance(post, Not) and post.pos == Pos(8, 34)
    assert isinstance(post.arg, StateAtom) and post.arg.pos == Pos(8, 39)


# ---- expressions --------------------------------------------------------------


def A(r: str, s: str) -> StateAtom:  # noqa: N802 - reads like the syntax
    return StateAtom(r, s)


def test_precedence() -> None:
    assert expr("a == x or b == y and not c == z => d == w") == Implies(
        Or(A("a", "x"), And(A("b", "y"), Not(A("c", "z")))), A("d", "w")
    )


@pytest.mark.parametrize(
    "text, tree",
    [
        ("a == x and b == y and c == z", And(And(A("a", "x"), A("b", "y")), A("c", "z"))),
        ("a == x or b == y or c == z", Or(Or(A("a", "x"), A("b", "y")), A("c", "z"))),
        ("a == x => b == y => c == z", Implies(Implies(A("a", "x"), A("b", "y")), A("c", "z"))),
        ("a == x => (b == y => c == z)", Implies(A("a", "x"), Implies(A("b", "y"), A("c", "z")))),
        ("(a == x or b == y) and c == z", And(Or(A("a", "x"), A("b", "y")), A("c", "z"))),
        ("not not a != x", Not(Not(Not(A("a", "x"))))),
        ("not (a == x and b == y)", Not(And(A("a", "x"), A("b", "y")))),
        ("not a == x and b == y", And(Not(A("a", "x")), A("b", "y"))),
        ("true or false", Or(Const(True), Const(False))),
        ("((a == x))", A("a", "x")),
    ],
)
def test_expression_shapes(text: str, tree: Expr) -> None:
    assert expr(text) == tree


_ATOMS = st.sampled_from(
    [A("a", "x"), A("a", "y"), A("b", "x"), A("c", "z"), A("d", "v"), Const(True), Const(False)]
)
_EXPRS = st.recursive(
    _ATOMS,
    lambda sub: st.one_of(
        st.builds(Not, sub),
        st.builds(And, sub, sub),
        st.builds(Or, sub, sub),
        st.builds(Implies, sub, sub),
    ),
    max_leaves=12,
)


@settings(max_examples=60, deadline=None)
@given(_EXPRS)
def test_expression_round_trip(tree: Expr) -> None:
    assert expr(to_text(tree)) == tree


def test_model_type() -> None:
    assert isinstance(parse_model("skillset s {}"), Model)
