"""Validation errors and warnings of skillset models (docs/semantics.md §2), exact messages."""

from __future__ import annotations

import pytest

from skinet.errors import Diagnostic, Pos, SourceError
from skinet.lang.expr import StateAtom
from skinet.lang.model import Event, Model, Resource, Skillset
from skinet.lang.parser import parse_model
from skinet.lang.validate import validate

# Lines 1-4; the text under test starts on line 5, usually indented by 2.
HEAD = """type Float
skillset s {
  resource power { state { Off On } initial Off transition all }
  resource mode { state { Idle Busy } initial Idle transition { Idle -> Busy } }
"""


def errors(body: str) -> list[str]:
    """The error lines ``parse_model`` raises for ``HEAD + body + '}'``."""
    with pytest.raises(SourceError) as info:
        parse_model(HEAD + body + "\n}\n", "f.rl")
    assert all(d.level == "error" for d in info.value.diagnostics)
    return [str(d) for d in info.value.diagnostics]


def warnings(body: str) -> list[str]:
    return [str(w) for w in parse_model(HEAD + body + "\n}\n", "f.rl").warnings]


def test_valid_head() -> None:
    assert warnings("") == []


# ---- unknown resources and states in expressions ------------------------------------


def test_unknown_resource_in_event_guard() -> None:
    assert errors("  event e { guard foo == On }") == [
        "f.rl:5:19: error: unknown resource 'foo' in guard of event 'e'"
    ]


def test_unknown_state_in_event_guard() -> None:
    assert errors("  event e { guard power == Bar }") == [
        "f.rl:5:28: error: unknown state 'Bar' of resource 'power' (states: Off, On)"
        " in guard of event 'e'"
    ]


def test_unknown_state_behind_not_equal() -> None:
    assert errors("  event e { guard not (power != Bar) }") == [
        "f.rl:5:33: error: unknown state 'Bar' of resource 'power' (states: Off, On)"
        " in guard of event 'e'"
    ]


def test_unknown_resource_in_precondition() -> None:
    assert errors("  skill k { precondition p: power == On and foo == X }") == [
        "f.rl:5:45: error: unknown resource 'foo' in precondition 'p' of skill 'k'"
    ]


def test_unknown_state_in_invariant_guard() -> None:
    assert errors("  skill k { invariant i { guard mode == Running } }") == [
        "f.rl:5:41: error: unknown state 'Running' of resource 'mode' (states: Idle, Busy)"
        " in guard of invariant 'i' of skill 'k'"
    ]


def test_unknown_resource_in_mode_postcondition() -> None:
    assert errors("  skill k { success done { postcondition foo == On } }") == [
        "f.rl:5:42: error: unknown resource 'foo' in postcondition of success 'done' of skill 'k'"
    ]


def test_unknown_state_in_unnamed_mode_postcondition() -> None:
    assert errors("  skill k { failure { postcondition power == Dead } }") == [
        "f.rl:5:46: error: unknown state 'Dead' of resource 'power' (states: Off, On)"
        " in postcondition of unnamed failure of skill 'k'"
    ]


def test_unknown_resource_in_interrupt_postcondition() -> None:
    assert errors("  skill k { interrupt { interrupting true postcondition foo == On } }") == [
        "f.rl:5:57: error: unknown resource 'foo' in postcondition of interrupt of skill 'k'"
    ]


# ---- effects ------------------------------------------------------------------------


def test_effect_on_undeclared_resource_in_event() -> None:
    assert errors("  event e { effect foo -> On }") == [
        "f.rl:5:20: error: effect on undeclared resource 'foo' in event 'e'"
    ]


def test_effect_on_undeclared_resource_in_skill_parts() -> None:
    body = (
        "  skill k {\n"
        "    start x -> On\n"
        "    invariant i { guard true effect y -> On }\n"
        "    interrupt { effect z -> On }\n"
        "    success ok { effect w -> On }\n"
        "  }"
    )
    assert errors(body) == [
        "f.rl:6:11: error: effect on undeclared resource 'x' in start of skill 'k'",
        "f.rl:7:37: error: effect on undeclared resource 'y' in invariant 'i' of skill 'k'",
        "f.rl:8:24: error: effect on undeclared resource 'z' in interrupt of skill 'k'",
        "f.rl:9:25: error: effect on undeclared resource 'w' in success 'ok' of skill 'k'",
    ]


def test_unknown_state_in_effect() -> None:
    assert errors("  event e { effect { power -> On mode -> Sleeping } }") == [
        "f.rl:5:42: error: unknown state 'Sleeping' of resource 'mode' (states: Idle, Busy)"
        " in effect of event 'e'"
    ]


def test_unknown_state_in_start_effect() -> None:
    assert errors("  skill k { start power -> Up }") == [
        "f.rl:5:28: error: unknown state 'Up' of resource 'power' (states: Off, On)"
        " in start of skill 'k'"
    ]


# ---- resources ------------------------------------------------------------------------


def test_initial_state_not_declared() -> None:
    assert errors("  resource r { state { A B } initial X transition all }") == [
        "f.rl:5:38: error: initial state 'X' of resource 'r' is not declared"
    ]


def test_transition_to_undeclared_state() -> None:
    assert errors("  resource r { state { A B } initial A transition { A -> B B -> X } }") == [
        "f.rl:5:65: error: transition to undeclared state 'X' of resource 'r'"
    ]


def test_transition_from_undeclared_state() -> None:
    assert errors("  resource r { state { A B } initial A transition Y -> B }") == [
        "f.rl:5:51: error: transition from undeclared state 'Y' of resource 'r'"
    ]


def test_duplicate_transition_is_a_warning() -> None:
    assert warnings("  resource r { state { A B } initial A transition { A -> B A -> B } }") == [
        "f.rl:5:60: warning: duplicate transition 'A -> B' in resource 'r'"
        " (first declared at 5:53)"
    ]


# ---- duplicates ---------------------------------------------------------------------------


def test_duplicate_skillset() -> None:
    with pytest.raises(SourceError) as info:
        parse_model("skillset s {}\nskillset s {}", "f.rl")
    assert str(info.value) == "f.rl:2:10: error: duplicate skillset 's' (first declared at 1:10)"


def test_duplicate_resource() -> None:
    assert errors("  resource power { state { A } initial A }") == [
        "f.rl:5:12: error: duplicate resource 'power' (first declared at 3:12)"
    ]


def test_duplicate_state() -> None:
    assert errors("  resource r { state { A B A } initial A transition all }") == [
        "f.rl:5:28: error: duplicate state 'A' in resource 'r' (first declared at 5:24)"
    ]


def test_duplicate_event() -> None:
    assert errors("  event e {}\n  event { e {} }") == [
        "f.rl:6:11: error: duplicate event 'e' (first declared at 5:9)"
    ]


def test_duplicate_skill() -> None:
    assert errors("  skill teleop {}\n  skill teleop {}") == [
        "f.rl:6:9: error: duplicate skill 'teleop' (first declared at 5:9)"
    ]


def test_duplicate_data() -> None:
    assert errors("  data x: Float\n  data { x: Float }") == [
        "f.rl:6:10: error: duplicate data 'x' (first declared at 5:8)"
    ]


def test_duplicate_precondition() -> None:
    assert errors("  skill k { precondition { p: true p: false } }") == [
        "f.rl:5:36: error: duplicate precondition 'p' in skill 'k' (first declared at 5:28)"
    ]


def test_duplicate_invariant() -> None:
    assert errors("  skill k { invariant i { guard true } invariant i { guard true } }") == [
        "f.rl:5:50: error: duplicate invariant 'i' in skill 'k' (first declared at 5:23)"
    ]


def test_precondition_and_invariant_may_share_a_name() -> None:
    # spot.rl and manipulator.rl do this (`is_powered`, `is_angular`).
    assert warnings("  skill k { precondition i: true invariant i { guard true } }") == []


def test_duplicate_mode_across_success_and_failure() -> None:
    assert errors("  skill k { success done {} failure { other {} done {} } }") == [
        "f.rl:5:48: error: duplicate mode 'done' in skill 'k' (first declared at 5:21)"
    ]


def test_unnamed_success_and_failure_coexist() -> None:
    model = parse_model(HEAD + "  skill k { success { effect power -> On } failure { effect power -> Off } }}", "f.rl")
    assert [m.kind for m in model.skillsets[0].skill("k").modes] == ["success", "failure"]


def test_duplicate_unnamed_mode() -> None:
    assert errors("  skill k { success { effect power -> On } success { effect power -> Off } }") == [
        "f.rl:5:44: error: duplicate unnamed success in skill 'k' (first declared at 5:13)"
    ]


def test_duplicate_input_and_output() -> None:
    assert errors("  skill k { input { a: Float a: Float } output b: Float output b: Float }") == [
        "f.rl:5:30: error: duplicate input 'a' in skill 'k' (first declared at 5:21)",
        "f.rl:5:64: error: duplicate output 'b' in skill 'k' (first declared at 5:48)",
    ]


def test_input_and_output_may_share_a_name() -> None:
    assert warnings("  skill k { input a: Float output a: Float }") == []


def test_duplicate_progress_field() -> None:
    assert errors("  skill k { progress { period 1 sec message { d: Float d: Float } } }") == [
        "f.rl:5:56: error: duplicate progress field 'd' in skill 'k' (first declared at 5:47)"
    ]


# ---- structural errors found while building the model ----------------------------------


@pytest.mark.parametrize(
    "body, message",
    [
        ("  event e { guard true guard false }", "5:24: error: duplicate guard in event 'e'"),
        ("  skill k { invariant i { effect power -> On } }", "5:23: error: invariant 'i' has no guard"),
        ("  skill k { progress { message m: Float } }", "5:13: error: progress has no period"),
        (
            "  skill k { progress { period 1 period 2 } }",
            "5:33: error: duplicate period in progress",
        ),
        (
            "  skill k { progress { period 1 } progress { period 2 } }",
            "5:35: error: duplicate progress in skill 'k'",
        ),
        (
            "  skill k { interrupt {} interrupt {} }",
            "5:26: error: duplicate interrupt in skill 'k'",
        ),
        (
            "  skill k { interrupt { interrupting true interrupting false } }",
            "5:43: error: duplicate interrupting in interrupt",
        ),
        (
            "  skill k { success m { postcondition true postcondition false } }",
            "5:44: error: duplicate postcondition in mode 'm'",
        ),
        ("  resource r { state { A } }", "5:12: error: resource 'r' has no initial state"),
        (
            "  resource r { state { A } state { B } initial A }",
            "5:28: error: duplicate state in resource 'r'",
        ),
        (
            "  resource r { state { A } initial A transition all transition all }",
            "5:53: error: duplicate transition in resource 'r'",
        ),
    ],
)
def test_structural_errors(body: str, message: str) -> None:
    assert errors(body) == [f"f.rl:{message}"]


def test_resource_without_states() -> None:
    assert errors("  resource r { initial A }") == [
        "f.rl:5:12: error: resource 'r' has no state declaration",
        "f.rl:5:24: error: initial state 'A' of resource 'r' is not declared",
    ]


# ---- type warnings ---------------------------------------------------------------------------


def test_unknown_type_warnings() -> None:
    body = (
        "  data d: Pose\n"
        "  skill go_to_odom {\n"
        "    input target: Pose\n"
        "    output reached: Float\n"
        "    output where: Place\n"
        "    progress { period 1 sec message left: Meters }\n"
        "  }"
    )
    assert warnings(body) == [
        "f.rl:5:11: warning: unknown type 'Pose' of data 'd'",
        "f.rl:7:19: warning: unknown type 'Pose' of input 'target' of skill 'go_to_odom'",
        "f.rl:9:19: warning: unknown type 'Place' of output 'where' of skill 'go_to_odom'",
        "f.rl:10:43: warning: unknown type 'Meters' of progress field 'left' of skill 'go_to_odom'",
    ]


def test_type_params_are_known_types() -> None:
    model = parse_model("skillset s<T, U> { data x: T skill k { input y: U output z: V } }", "f.rl")
    assert [str(w) for w in model.warnings] == [
        "f.rl:1:61: warning: unknown type 'V' of output 'z' of skill 'k'"
    ]


def test_types_declared_after_the_skillset_count() -> None:
    assert parse_model("skillset s { data x: T }\ntype T").warnings == ()


def test_duplicate_type_is_a_warning() -> None:
    model = parse_model("type { A B A }\nskillset s {}", "f.rl")
    assert [str(w) for w in model.warnings] == [
        "f.rl:1:12: warning: duplicate type 'A' (first declared at 1:8)"
    ]


# ---- several diagnostics ---------------------------------------------------------------------


def test_all_errors_sorted_by_position() -> None:
    body = (
        "  skill k { precondition p: foo == A }\n"
        "  event e { guard power == X effect bar -> On }\n"
        "  data d: Nowhere\n"
        "  resource r { state { A } initial B }"
    )
    assert errors(body) == [
        "f.rl:5:29: error: unknown resource 'foo' in precondition 'p' of skill 'k'",
        "f.rl:6:28: error: unknown state 'X' of resource 'power' (states: Off, On)"
        " in guard of event 'e'",
        "f.rl:6:37: error: effect on undeclared resource 'bar' in event 'e'",
        "f.rl:8:36: error: initial state 'B' of resource 'r' is not declared",
    ]


def test_validate_on_a_hand_built_model() -> None:
    power = Resource("power", ("Off", "On"), "Off", None)
    event = Event("e", StateAtom("power", "Up"), ())
    model = Model("m.rl", (), (Skillset("s", resources=(power,), events=(event,)),))
    assert validate(model) == [
        Diagnostic(
            "m.rl",
            None,
            "error",
            "unknown state 'Up' of resource 'power' (states: Off, On) in guard of event 'e'",
        )
    ]


def test_validate_returns_warnings_too() -> None:
    model = parse_model("skillset s { data x: T }", "f.rl")
    found = validate(model)
    assert found == list(model.warnings)
    assert found[0].level == "warning" and found[0].pos == Pos(1, 22)


def test_resource_without_transition_clause_warns() -> None:
    assert warnings("  resource frozen { state { A B } initial A }") == [
        "f.rl:5:12: warning: resource 'frozen' has no transition clause: no effect can change its state"
        " (write 'transition all' or 'transition { A -> B }')"
    ]
    # a one-state resource cannot change anyway
    assert warnings("  resource single { state { A } initial A }") == []
