"""Safety properties: parsing, name resolution, errors, evaluation (docs/semantics.md §4), and
the JSON form of combined markings used to state them."""

from __future__ import annotations

import pytest

from skinet.errors import Pos, SourceError
from skinet.lang.expr import And, Const, Implies, Not, Or
from skinet.lang.parser import parse_skillset
from skinet.props.evaluate import holds
from skinet.props.formula import PlaceAtom, Temporal, Until
from skinet.props.parser import parse_formula, parse_properties
from skinet.system.model import System, build_system, marking_from_json, marking_to_json

ARM = """
skillset arm {
    resource {
        joint { state { Home Ready Moving } initial Home transition all }
        gripper { state { Open Closed Ready } initial Open transition all }
    }
    skill grasp { success ok {} }
    skill reach {}
}
"""

BASE = """
skillset base {
    resource { drive { state { Stopped Driving } initial Stopped transition all } }
    skill move {}
}
"""


@pytest.fixture(scope="module")
def skillsets():
    return {"arm": parse_skillset(ARM, "arm.rl"), "base": parse_skillset(BASE, "base.rl")}


@pytest.fixture(scope="module")
def system(skillsets) -> System:
    props = "\n".join(
        [
            "# evaluation tests",
            "home = arm:Home",
            "guarded = arm:joint.Moving => base:Driving",
            "exclusive = not (arm:i_grasp and base:i_move)",
            "always = arm:e_reach or arm:i_reach",
            "never = false",
            "tautology = true",
            "mixed = arm:gripper.Ready or not (base:e_move and arm:Closed)",
        ]
    )
    return build_system("robot", [(skillsets["arm"], "/arm"), (skillsets["base"], "/base")], props, "robot.props")


def error(text: str, skillsets, source: str = "f.props") -> str:
    with pytest.raises(SourceError) as info:
        parse_properties(text, skillsets, source)
    assert len(info.value.diagnostics) == 1
    return str(info.value)


# ---------------------------------------------------------------------------
# parsing and resolution


def test_atoms_resolve_to_places(skillsets) -> None:
    text = (
        "# a comment line\n"
        "\n"
        "a = arm:Home   # trailing comment\n"
        "b = arm:joint.Ready and arm:gripper.Ready\n"
        "c = base:i_move or arm:e_grasp\n"
        "d = arm:Closed => not base:Driving\n"
    )
    props = parse_properties(text, skillsets, "p.props")
    assert [p.name for p in props] == ["a", "b", "c", "d"]
    assert [p.text for p in props] == [
        "arm:Home",
        "arm:joint.Ready and arm:gripper.Ready",
        "base:i_move or arm:e_grasp",
        "arm:Closed => not base:Driving",
    ]
    assert [p.pos for p in props] == [Pos(3, 1), Pos(4, 1), Pos(5, 1), Pos(6, 1)]
    a, b, c, d = (p.expr for p in props)
    assert a == PlaceAtom("arm", "joint.Home")
    assert b == And(PlaceAtom("arm", "joint.Ready"), PlaceAtom("arm", "gripper.Ready"))
    assert c == Or(PlaceAtom("base", "i_move"), PlaceAtom("arm", "e_grasp"))
    assert d == Implies(PlaceAtom("arm", "gripper.Closed"), Not(PlaceAtom("base", "drive.Driving")))
    assert a.text == "arm:Home" and a.pos == Pos(3, 5)
    assert str(b.right) == "arm:gripper.Ready"


def test_precedence_and_constants(skillsets) -> None:
    (p,) = parse_properties("p = not arm:Home or arm:Moving and base:Stopped => false", skillsets)
    assert p.expr == Implies(
        Or(Not(PlaceAtom("arm", "joint.Home")), And(PlaceAtom("arm", "joint.Moving"), PlaceAtom("base", "drive.Stopped"))),
        Const(False),
    )
    (q,) = parse_properties("q = true", skillsets)
    assert q.expr == Const(True)


def test_paper_properties_resolve(paper_system) -> None:
    assert [(p.name, p.text) for p in paper_system.properties] == [
        ("action_guard", "not (spot:Busy and manipulator:Busy)"),
        ("safety_guard", "not (spot:i_go_to_waypoint and not manipulator:HP)"),
    ]
    action, safety = (p.expr for p in paper_system.properties)
    assert action == Not(And(PlaceAtom("spot", "control_mode.Busy"), PlaceAtom("manipulator", "mutex.Busy")))
    assert safety == Not(And(PlaceAtom("spot", "i_go_to_waypoint"), Not(PlaceAtom("manipulator", "arm_status.HP"))))


def test_empty_properties_text(skillsets) -> None:
    assert parse_properties("", skillsets) == []
    assert parse_properties("# nothing\n\n", skillsets) == []


def test_formula_with_temporal_operators(skillsets) -> None:
    f = parse_formula("AG (arm:Home => EF base:Driving)", skillsets)
    assert f == Temporal("AG", Implies(PlaceAtom("arm", "joint.Home"), Temporal("EF", PlaceAtom("base", "drive.Driving"))))
    assert parse_formula("E[arm:Home U base:i_move]", skillsets) == Until(
        "E", PlaceAtom("arm", "joint.Home"), PlaceAtom("base", "i_move")
    )


# ---------------------------------------------------------------------------
# errors, with exact messages


def test_unknown_skillset(skillsets) -> None:
    assert error("p = legs:Busy", skillsets) == (
        "f.props:1:5: error: unknown skillset 'legs' in 'legs:Busy' (skillsets: arm, base)"
    )


def test_unknown_name_lists_close_candidates(skillsets) -> None:
    assert error("ok = arm:Home\np = base:Stoped", skillsets) == (
        "f.props:2:5: error: unknown name 'base:Stoped' (candidates: base:Stopped, base:drive.Stopped)"
    )
    assert error("p = arm:i_grap", skillsets) == (
        "f.props:1:5: error: unknown name 'arm:i_grap' (candidates: arm:i_grasp, arm:e_grasp, arm:i_reach)"
    )
    assert error("p = arm:joint.Nope", skillsets) == (
        "f.props:1:5: error: unknown name 'arm:joint.Nope'"
        " (candidates: arm:joint.Home, arm:joint.Ready, arm:joint.Moving)"
    )


def test_unknown_name_without_close_match_lists_every_short_name(skillsets) -> None:
    assert error("p = arm:xyz", skillsets) == (
        "f.props:1:5: error: unknown name 'arm:xyz' (candidates: arm:Closed, arm:Home, arm:Moving,"
        " arm:Open, arm:Ready, arm:e_grasp, arm:e_reach, arm:i_grasp, arm:i_reach)"
    )


def test_ambiguous_short_state_name(skillsets) -> None:
    # Ready is a state of both joint and gripper
    assert error("ok = arm:Home\np = arm:Home and arm:Ready", skillsets) == (
        "f.props:2:18: error: ambiguous name 'arm:Ready': could be arm:joint.Ready, arm:gripper.Ready"
    )
    # the qualified forms are fine
    parse_properties("p = arm:joint.Ready and arm:gripper.Ready", skillsets)


def test_duplicate_property(skillsets) -> None:
    assert error("p = arm:Home\nq = base:Stopped\n  p = arm:Open", skillsets) == (
        "f.props:3:3: error: duplicate property 'p' (first defined at 1:1)"
    )


def test_temporal_operator_in_property_is_rejected(skillsets) -> None:
    assert error("p = AF arm:Home", skillsets) == (
        "f.props:1:1: error: property 'p' uses a temporal operator; properties are state formulas"
    )


def test_syntax_errors_point_at_file_line_column(skillsets) -> None:
    assert error("p arm:Home", skillsets) == "f.props:1:3: error: unexpected 'arm', expected '='"
    msg = error("a = arm:Home\n\nb = (arm:Home and base:Stopped", skillsets, "dir/sys.props")
    assert msg.startswith("dir/sys.props:3:")
    assert "unexpected end of input" in msg and "')'" in msg
    msg = error("p = arm:Home and\nq = arm:Home", skillsets)
    assert msg.startswith("f.props:1:17: error: unexpected end of line, expected one of: ")
    msg = error("p = arm:Home )", skillsets)
    assert msg.startswith("f.props:1:14: error: unexpected ')'")


def test_error_is_a_source_error_with_a_diagnostic(skillsets) -> None:
    with pytest.raises(SourceError) as info:
        parse_properties("p = legs:Busy", skillsets, "x.props")
    (d,) = info.value.diagnostics
    assert (d.file, d.pos, d.level) == ("x.props", Pos(1, 5), "error")


# ---------------------------------------------------------------------------
# evaluation: safe(phi, m) on hand-built combined markings


def combined(system: System, arm: set[str], base: set[str]) -> dict[str, int]:
    nets = system.nets
    return {"arm": nets["arm"].marking_of(arm), "base": nets["base"].marking_of(base)}


def values(system: System, marking: dict[str, int]) -> dict[str, bool]:
    return {p.name: holds(p.expr, marking, system.nets) for p in system.properties}


def test_holds_at_initial_marking(system: System) -> None:
    assert values(system, system.initial_marking()) == {
        "home": True, "guarded": True, "exclusive": True, "always": True,
        "never": False, "tautology": True, "mixed": True,
    }  # fmt: skip


def test_holds_on_hand_built_markings(system: System) -> None:
    m = combined(
        system,
        {"joint.Moving", "gripper.Closed", "i_grasp", "e_reach"},
        {"drive.Stopped", "i_move"},
    )
    assert values(system, m) == {
        "home": False, "guarded": False, "exclusive": False, "always": True,
        "never": False, "tautology": True, "mixed": True,
    }  # fmt: skip
    m = combined(
        system,
        {"joint.Moving", "gripper.Closed", "e_grasp", "i_reach"},
        {"drive.Driving", "e_move"},
    )
    assert values(system, m) == {
        "home": False, "guarded": True, "exclusive": True, "always": True,
        "never": False, "tautology": True, "mixed": False,
    }  # fmt: skip
    m = combined(system, {"joint.Ready", "gripper.Ready", "e_grasp", "e_reach"}, {"drive.Stopped", "e_move"})
    assert values(system, m)["mixed"] is True
    assert values(system, m)["home"] is False


def test_holds_on_the_paper_system(paper_system: System) -> None:
    nets = paper_system.nets
    action, safety = paper_system.properties
    spot, arm = nets["spot"], nets["manipulator"]
    both_busy = {
        "spot": spot.marking_of({"power_status.PowerOn", "posture.Standing", "control_mode.Busy", "e_init_power",
                                 "e_safe_poweroff", "e_stand_up", "e_sit_down", "e_go_to_waypoint", "i_teleop"}),
        "manipulator": arm.marking_of({"mutex.Busy", "arm_status.Moving", "e_arm_ready", "i_arm_joystick",
                                       "e_arm_moving_to_RD", "e_arm_RD_to_HP"}),
    }  # fmt: skip
    assert holds(action.expr, both_busy, nets) is False
    assert holds(safety.expr, both_busy, nets) is True
    assert holds(action.expr, paper_system.initial_marking(), nets) is True


# ---------------------------------------------------------------------------
# JSON form of a combined marking


def test_marking_json_round_trip(system: System) -> None:
    assert marking_to_json(system, system.initial_marking()) == {
        "arm": {"resources": {"joint": "Home", "gripper": "Open"}, "running": []},
        "base": {"resources": {"drive": "Stopped"}, "running": []},
    }
    data = {
        "arm": {"resources": {"gripper": "Ready"}, "running": ["reach", "grasp"]},
        "base": {"running": ["move"]},
    }
    m = marking_from_json(system, data)
    assert m == combined(
        system, {"joint.Home", "gripper.Ready", "i_grasp", "i_reach"}, {"drive.Stopped", "i_move"}
    )
    assert marking_to_json(system, m) == {
        "arm": {"resources": {"joint": "Home", "gripper": "Ready"}, "running": ["grasp", "reach"]},
        "base": {"resources": {"drive": "Stopped"}, "running": ["move"]},
    }
    assert marking_from_json(system, {}) == system.initial_marking()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ([], "<state>: error: state must be an object mapping skillset names to states"),
        ({"legs": {}}, "<state>: error: unknown skillset 'legs' (skillsets: arm, base)"),
        ({"arm": []}, "<state>: error: state of 'arm' must be an object"),
        (
            {"arm": {"skills": []}},
            "<state>: error: unknown key 'skills' in state of 'arm' (keys: resources, running)",
        ),
        (
            {"arm": {"running": "grasp"}},
            "<state>: error: state of 'arm': 'resources' must be an object and 'running' a list",
        ),
        (
            {"arm": {"resources": {"elbow": "Up"}}},
            "<state>: error: unknown resource 'elbow' of 'arm' (resources: joint, gripper)",
        ),
        (
            {"arm": {"resources": {"joint": "Up"}}},
            "<state>: error: unknown state 'Up' of resource 'arm:joint' (states: Home, Ready, Moving)",
        ),
        (
            {"base": {"running": ["dance"]}},
            "<state>: error: unknown skill 'dance' of 'base' (skills: move)",
        ),
        (
            {"arm": {"running": ["grasp", "throw"]}},
            "<state>: error: unknown skill 'throw' of 'arm' (skills: grasp, reach)",
        ),
    ],
)
def test_marking_from_json_errors(system: System, data: object, message: str) -> None:
    with pytest.raises(SourceError) as info:
        marking_from_json(system, data)
    assert str(info.value) == message


def test_marking_from_json_error_names_the_source(system: System) -> None:
    with pytest.raises(SourceError) as info:
        marking_from_json(system, {"legs": {}}, "live.json")
    assert str(info.value) == "live.json: error: unknown skillset 'legs' (skillsets: arm, base)"
