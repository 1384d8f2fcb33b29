"""Every construct of ONERA's public grammars parses (docs/semantics.md §2).

The reference grammars are DavidD12/robot_language (2022, ``grammar.lalrpop``) and
DavidD12/rl_model-rs (2023-2024, every version).  The two files below are written
here, one per dialect, and use each construct those grammars accept.
"""

from __future__ import annotations

import pytest

from skinet.errors import SourceError
from skinet.lang.expr import And, Not, StateAtom
from skinet.lang.parser import parse_model, parse_skillset
from skinet.net.build import build_net

# robot_language (2022): type lines, skillset and skill `parameter` sections, data
# with a publication period, `interrupting`, effects then postcondition.
ROBOT_LANGUAGE = """\
type Pose
type Float
skillset uav {
    parameter { home: Pose }
    data { position: Pose period 1 sec  altitude: Float period 100 ms }
    data battery: Float
    resource {
        motors { state { Off On } initial Off transition all }
        flight { state { Landed Flying } initial Landed transition { Landed -> Flying Flying -> Landed } }
    }
    event { motors_off { guard flight == Landed effect motors -> Off } }
    skill takeoff {
        parameter altitude_target: Float
        input height: Float
        precondition { ready: motors == On and flight == Landed }
        start flight -> Flying
        invariant { powered { guard motors == On effect flight -> Landed } }
        progress { period 1 sec message current: Float }
        interrupt { interrupting true effect flight -> Landed postcondition flight == Landed }
        success ok { effect { flight -> Flying } postcondition flight == Flying }
        failure { ko { } blocked { postcondition motors == Off } }
    }
}
"""

# rl_model-rs (2024): type parameters, named postconditions (single or block, several
# allowed) written before the effects, interrupt without `interrupting`.
RL_MODEL = """\
skillset arm<Pose, Float> {
    data { pose: Pose period 1.0 }
    resource arm { state { HP RD Moving } initial HP transition all }
    resource grip { state { Open Closed } initial Open transition all }
    skill go_home {
        input target: Pose
        precondition { free: arm != Moving }
        start arm -> Moving
        interrupt {
            postcondition stopped: arm != Moving
            effect arm -> RD
        }
        success at_home {
            postcondition at_home: arm == HP
            postcondition { released: grip == Open still: arm != Moving }
            effect { arm -> HP }
        }
        failure blocked { postcondition arm_rd: arm == RD }
    }
}
"""


def test_robot_language_dialect() -> None:
    model = parse_model(ROBOT_LANGUAGE, "uav.rl")
    assert model.warnings == ()
    ss = model.skillsets[0]
    assert [(p.name, p.type) for p in ss.parameters] == [("home", "Pose")]
    assert [(d.name, d.period_seconds) for d in ss.data] == [("position", 1.0), ("altitude", 0.1), ("battery", None)]
    takeoff = ss.skill("takeoff")
    assert [p.name for p in takeoff.parameters] == ["altitude_target"]
    assert takeoff.interrupt.interrupting and takeoff.interrupt.postcondition == StateAtom("flight", "Landed")
    assert [m.name for m in takeoff.failures] == ["ko", "blocked"]
    net = build_net(ss)
    assert (len(net.places), len(net.transitions)) == (6, 12)


def test_rl_model_dialect() -> None:
    model = parse_model(RL_MODEL, "arm.rl")
    assert model.warnings == ()
    ss = model.skillsets[0]
    assert ss.type_params == ("Pose", "Float")
    assert ss.data[0].period_seconds == 1.0
    home = ss.skill("go_home")
    assert not home.interrupt.interrupting
    assert home.interrupt.postcondition == Not(StateAtom("arm", "Moving"))
    at_home = home.successes[0]
    # Several named postconditions are one conjunction, in source order.
    assert at_home.postcondition == And(
        And(StateAtom("arm", "HP"), StateAtom("grip", "Open")), Not(StateAtom("arm", "Moving"))
    )
    assert [(e.resource, e.state) for e in at_home.effects] == [("arm", "HP")]
    assert home.failures[0].postcondition == StateAtom("arm", "RD")
    net = build_net(ss)
    names = sorted({t.name for t in net.transitions})
    assert names == ["go_home.failure.blocked", "go_home.interrupt", "go_home.start", "go_home.success.at_home"]


@pytest.mark.parametrize(
    "field, seconds",
    [("position: GeoPoint period 1 sec", 1.0), ("position: GeoPoint period 100 ms", 0.1),
     ("position: GeoPoint period 1.0", 1.0), ("position: GeoPoint period 2 s", 2.0), ("position: GeoPoint", None)],
)
def test_data_period_forms(field: str, seconds: float | None) -> None:
    ss = parse_skillset(f"type GeoPoint skillset s {{ data {field} }}")
    assert ss.data[0].period_seconds == seconds


def test_named_postcondition_of_the_issue() -> None:
    ss = parse_skillset(
        "skillset s { resource arm { state { HP RD } initial RD transition all }\n"
        "  skill k { success done { postcondition at_home: arm == HP } } }"
    )
    assert ss.skills[0].successes[0].postcondition == StateAtom("arm", "HP")


def test_postcondition_before_effects_moves_both() -> None:
    ss = parse_skillset(
        "skillset s { resource arm { state { HP RD } initial RD transition all }\n"
        "  resource g { state { A B } initial A transition all }\n"
        "  skill k { failure f { postcondition p: arm == HP effect g -> B } } }"
    )
    net = build_net(ss)
    (fail,) = [t for t in net.transitions if t.name == "k.failure.f"][:1]
    post = {net.places[i] for i in fail.post}
    assert {"arm.HP", "g.B", "e_k"} <= post


def errors(text: str) -> list[str]:
    with pytest.raises(SourceError) as info:
        parse_model(text, "f.rl")
    return [str(d) for d in info.value.diagnostics]


HEAD = "type T\nskillset s {\n  resource r { state { A B } initial A transition all }\n"


def test_duplicate_postcondition_names() -> None:
    assert errors(HEAD + "  skill k { success m { postcondition { p: r == A p: r == B } } }\n}") == [
        "f.rl:4:51: error: duplicate postcondition 'p' in mode 'm'"
    ]
    assert errors(HEAD + "  skill k { interrupt { postcondition r == A postcondition r == B } }\n}") == [
        "f.rl:4:46: error: duplicate postcondition in interrupt"
    ]


def test_duplicate_parameters() -> None:
    assert errors(HEAD + "  parameter { p: T p: T }\n  skill k { parameter { q: T q: T } }\n}") == [
        "f.rl:4:20: error: duplicate parameter 'p' (first declared at 4:15)",
        "f.rl:5:30: error: duplicate parameter 'q' in skill 'k' (first declared at 5:25)",
    ]


def test_parameter_of_unknown_type_is_a_warning() -> None:
    model = parse_model(HEAD + "  parameter p: Nope\n}", "f.rl")
    assert [str(w) for w in model.warnings] == ["f.rl:4:16: warning: unknown type 'Nope' of parameter 'p'"]


# ---- docs/semantics.md §3: an unsatisfiable postcondition warns, and the skill still stops -----------


def test_unsatisfiable_postconditions_warn() -> None:
    model = parse_model(
        HEAD + "  skill k {\n"
        "    interrupt { postcondition r == A and r == B }\n"
        "    success ok { postcondition a: r == A postcondition b: r != A }\n"
        "    failure ko { postcondition false effect r -> B }\n"
        "    failure fine { postcondition r == A or false }\n  }\n}",
        "f.rl",
    )
    assert [str(w) for w in model.warnings] == [
        "f.rl:5:31: warning: postcondition of interrupt of skill 'k' is unsatisfiable: it moves no resource when the skill stops",
        "f.rl:6:35: warning: postcondition of success 'ok' of skill 'k' is unsatisfiable: it moves no resource when the skill stops",
        "f.rl:7:32: warning: postcondition of failure 'ko' of skill 'k' is unsatisfiable: it moves no resource when the skill stops",
    ]
    net = build_net(model.skillsets[0])
    ko = [t for t in net.transitions if t.name == "k.failure.ko"]
    # The mode still stops the skill and applies its effects (one variant per source state).
    assert sorted(sorted(net.places[i] for i in t.post) for t in ko) == [["e_k", "r.B"], ["e_k", "r.B"]]


# ---- bounds on expressions -----------------------------------------------------------------


def test_nesting_limit_in_guards() -> None:
    ok = HEAD + "  event e { guard " + "not " * 100 + "r == A }\n}"
    assert len(parse_model(ok).skillsets[0].events) == 1
    assert errors(HEAD + "  event e { guard " + "not " * 101 + "r == A }\n}") == [
        "f.rl:4:419: error: expression nested too deeply (more than 100 levels of operators);"
        " split it into several named parts"
    ]
    chain = " and ".join(["r == A"] * 102)
    assert errors(HEAD + f"  skill k {{ precondition p: {chain} }}\n}}")[0].startswith(
        "f.rl:4:29: error: expression nested too deeply"
    )


@pytest.mark.parametrize("op", ["not ", "r == A and ", "r == A or ", "r == A => "])
def test_two_kilobytes_of_operators_never_crash(op: str) -> None:
    body = op * (2048 // len(op)) + "r == A"
    message = errors(HEAD + f"  event e {{ guard {body} }}\n}}")[0]
    assert "expression nested too deeply" in message


def test_deep_parentheses_parse() -> None:
    # Parentheses add no operator: 4 KB of them is one atom.
    guard = "(" * 2048 + "r == A" + ")" * 2048
    assert parse_model(HEAD + f"  event e {{ guard {guard} }}\n}}").skillsets[0].events[0].guard == StateAtom("r", "A")


def wide(resources: int, states: str, event: str) -> str:
    """A skillset of ``resources`` resources x0, x1... and one event ``e`` with body ``event``."""
    lines = "".join(f"  resource x{i} {{ state {{ {states} }} initial A transition all }}\n" for i in range(resources))
    return f"skillset s {{\n{lines}  event e {{ {event} }}\n}}"


def guard(n: int) -> str:
    return "guard " + " and ".join(f"(x{i} == A or x{i} == B)" for i in range(n))


def effects(n: int) -> str:
    return "effect { " + " ".join(f"x{i} -> B" for i in range(n)) + " }"


EIGHT = "A B C D E F G H"


@pytest.mark.parametrize(
    "refused, accepted, message",
    [
        # 2^11 clauses; 2^10 is accepted.
        (wide(11, "A B", guard(11)), wide(11, "A B", guard(10)),
         "f.rl:13:20: error: guard of event 'e' is too complex: more than 1024 clauses in"
         " disjunctive normal form (each clause becomes a transition)"),
        # 2 KB that would give 8^5 = 32768 transitions; 8^4 is accepted.
        (wide(5, EIGHT, effects(5)), wide(5, EIGHT, effects(4)),
         "f.rl:7:9: error: event 'e' is too large: more than 4096 transition variants"
         " (one per guard clause and combination of source states of the resources it moves)"),
    ],
)
def test_bounds_of_one_element(refused: str, accepted: str, message: str) -> None:
    assert errors(refused) == [message]
    assert parse_model(accepted).skillsets


def test_largest_element_accepted() -> None:
    ss = parse_model(wide(5, EIGHT, effects(4))).skillsets[0]
    assert len(build_net(ss).transitions) == 8**4


# ---- big inputs ------------------------------------------------------------------------


def test_input_size_limit() -> None:
    assert errors("skillset s { /*" + "x" * 300_000) == [
        "f.rl: error: input too large: 300015 characters (the limit is 262144)"
    ]


def test_unterminated_comment_costs_linear_memory() -> None:
    import tracemalloc

    text = "skillset s { /*" + "x" * 250_000
    tracemalloc.start()
    try:
        assert errors(text) == ["f.rl:1:14: error: unterminated comment '/*'"]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * len(text)


def test_bad_effect_and_bad_postcondition_are_both_reported() -> None:
    assert errors(HEAD + "  skill k { success ok { effect q -> A postcondition z == A } }\n}") == [
        "f.rl:4:33: error: effect on undeclared resource 'q' in success 'ok' of skill 'k'",
        "f.rl:4:54: error: unknown resource 'z' in postcondition of success 'ok' of skill 'k'",
    ]
