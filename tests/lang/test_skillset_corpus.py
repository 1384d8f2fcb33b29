"""The real skillset files of the corpus parse and validate (docs/semantics.md §2)."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import Pos
from skinet.lang.expr import And, Or, StateAtom
from skinet.lang.model import Effect, Interrupt, Model, Skillset, Variable
from skinet.lang.parser import parse_model

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "corpus"

FILES = ["spot.rl", "manipulator.rl", "isae_robot/isae_robot.rl"]


def eff(effects: tuple[Effect, ...]) -> list[tuple[str, str]]:
    """Effects without positions (model objects compare their positions too)."""
    return [(e.resource, e.state) for e in effects]


def load(name: str) -> Model:
    return parse_model((CORPUS / name).read_text(encoding="utf-8"), name)


def skillset(name: str) -> Skillset:
    model = load(name)
    assert len(model.skillsets) == 1
    return model.skillsets[0]


@pytest.mark.parametrize(
    "name, resources, events, skills",
    [
        ("spot.rl", 6, 6, 11),
        ("manipulator.rl", 2, 6, 5),
        ("isae_robot/isae_robot.rl", 2, 3, 4),
    ],
)
def test_corpus_counts(name: str, resources: int, events: int, skills: int) -> None:
    ss = skillset(name)
    assert (len(ss.resources), len(ss.events), len(ss.skills)) == (resources, events, skills)
    assert ss.source == name


@pytest.mark.parametrize(
    "name, invariants, successes, failures",
    [
        ("spot.rl", 14, 11, 12),
        ("manipulator.rl", 5, 5, 9),
        ("isae_robot/isae_robot.rl", 4, 3, 4),
    ],
)
def test_corpus_counts_match_expected_md(
    name: str, invariants: int, successes: int, failures: int
) -> None:
    ss = skillset(name)
    assert sum(len(s.invariants) for s in ss.skills) == invariants
    assert sum(len(s.successes) for s in ss.skills) == successes
    assert sum(len(s.failures) for s in ss.skills) == failures


@pytest.mark.parametrize("name", FILES)
def test_corpus_has_no_warnings(name: str) -> None:
    # EXPECTED.md says spot.rl uses an undeclared `Pose`, but its type block does
    # declare `Pose` (and every other type used): no file of the corpus warns.
    assert load(name).warnings == ()


def test_spot_types_and_data() -> None:
    model = load("spot.rl")
    assert [t.name for t in model.types] == ["Pose2D", "Pose", "PoseArray", "Float", "GeoPoint"]
    ss = model.skillsets[0]
    assert ss.types == model.types
    assert ss.data == (
        Variable("battery", "Float", Pos(12, 9), Pos(12, 18)),
        Variable("position", "GeoPoint", Pos(13, 9), Pos(13, 19)),
        Variable("home", "GeoPoint", Pos(14, 9), Pos(14, 15)),
    )


def test_spot_resources() -> None:
    ss = skillset("spot.rl")
    power = ss.resource("power_status")
    assert power.states == ("PowerOff", "PowerOn")
    assert power.initial == "PowerOff"
    assert power.transitions is None
    assert power.pos == Pos(18, 9)
    assert power.state_pos == (Pos(19, 21), Pos(19, 30))
    assert power.initial_pos == Pos(20, 21)
    origin = ss.resource("origin_status")
    assert origin.transitions == (("OriginNotSet", "OriginSet"),)
    assert origin.transition_pos == (Pos(41, 25),)
    assert origin.transition_target_pos == (Pos(41, 41),)


def test_spot_events() -> None:
    ss = skillset("spot.rl")
    standing = ss.event("status_standing")
    assert standing.guard == And(
        StateAtom("spot_status", "Sitting"), StateAtom("power_status", "PowerOn")
    )
    assert eff(standing.effects) == [("spot_status", "Standing")]
    assert standing.pos == Pos(70, 9)
    atom = standing.guard.left  # type: ignore[union-attr]
    assert (atom.pos, atom.state_pos) == (Pos(71, 19), Pos(71, 34))
    off = ss.event("power_switchoff")
    assert off.guard == StateAtom("power_status", "PowerOn")
    assert [(e.resource, e.state) for e in off.effects] == [
        ("power_status", "PowerOff"),
        ("spot_status", "Sitting"),
    ]
    assert (off.effects[1].pos, off.effects[1].state_pos) == (Pos(63, 17), Pos(63, 32))


def test_spot_skills() -> None:
    ss = skillset("spot.rl")
    modes = {s.name: ([m.name for m in s.successes], [m.name for m in s.failures]) for s in ss.skills}
    assert modes["init_power"] == (["is_poweredon"], ["no_battery", "is_estopped"])
    assert modes["capture_origin"] == (["is_set"], ["is_not_set"])
    assert modes["teleop"] == (["teleop_done"], ["teleop_failed"])

    init = ss.skill("init_power")
    assert [p.name for p in init.preconditions] == ["is_sitting", "canmove", "is_powered"]
    assert init.preconditions[1].expr == And(
        StateAtom("lease_status", "AutoMode"), StateAtom("control_mode", "Idle")
    )
    assert eff(init.start) == [("control_mode", "Busy")]
    assert init.interrupt == Interrupt()
    assert not init.interrupt.declared
    assert init.progress is not None and init.progress.period_seconds == 1.0
    assert init.progress.fields == ()
    success = init.successes[0]
    assert success.kind == "success"
    assert eff(success.effects) == [("control_mode", "Idle")]
    assert success.postcondition == StateAtom("power_status", "PowerOn")
    assert init.failures[0].kind == "failure"

    odom = ss.skill("go_to_odom")
    assert odom.inputs == (Variable("target", "Pose", Pos(217, 15), Pos(217, 23)),)
    assert [(v.name, v.type) for v in odom.outputs] == [("pose", "Pose")]
    assert [i.name for i in odom.invariants] == ["is_auto", "is_powered"]
    assert odom.invariants[1].guard == StateAtom("spot_status", "Standing")
    assert eff(odom.invariants[1].effects) == [("control_mode", "Idle")]
    assert odom.interrupt.declared and odom.interrupt.interrupting
    assert eff(odom.interrupt.effects) == [("control_mode", "Idle")]
    assert odom.progress is not None
    assert [(v.name, v.type) for v in odom.progress.fields] == [("distance", "Float")]

    capture = ss.skill("capture_origin")
    assert capture.preconditions == () and capture.start == () and capture.progress is None
    assert capture.failures[0].effects == () and capture.failures[0].postcondition is None

    teleop = ss.skill("teleop")
    assert eff(teleop.start) == [("control_mode", "Busy"), ("lease_status", "ManualMode")]
    assert len(teleop.interrupt.effects) == 2

    standup = ss.skill("standup")
    assert standup.progress is None
    assert standup.interrupt == Interrupt()


def test_manipulator() -> None:
    ss = skillset("manipulator.rl")
    arm = ss.resource("arm_status")
    assert arm.transitions == (
        ("Hp", "Motion"),
        ("Motion", "Static"),
        ("Static", "Motion"),
        ("Motion", "Hp"),
    )
    assert len(ss.resource("control_mode").transitions or ()) == 6
    periods = {s.name: s.progress.period_seconds for s in ss.skills if s.progress}
    assert periods == {
        "arm_moving_manual": 0.1,
        "arm_moving_goaldriven": 0.001,
        "arm_moving_interaction": 0.1,
        "arm_moving_pickplace": 0.1,
        "arm_moving_to_HP": 0.1,
    }
    to_hp = ss.skill("arm_moving_to_HP")
    cm = "control_mode"
    assert to_hp.preconditions[1].expr == Or(
        Or(Or(StateAtom(cm, "ManualMode"), StateAtom(cm, "GoalDriven")), StateAtom(cm, "InteractionMode")),
        StateAtom(cm, "PickandPlace"),
    )
    manual = ss.skill("arm_moving_manual")
    assert [(v.name, v.type) for v in manual.inputs] == [("target", "Accel")]
    assert manual.progress is not None
    assert [(v.name, v.type) for v in manual.progress.fields] == [
        ("pos_err", "float"),
        ("att_err", "float"),
    ]
    assert eff(manual.invariants[0].effects) == [
        ("control_mode", "ManualMode"),
        ("arm_status", "Static"),
    ]
    assert [m.name for m in manual.modes] == ["is_ready", "singularity_encountered", "stop_arm"]


def test_isae_robot() -> None:
    ss = skillset("isae_robot/isae_robot.rl")
    assert ss.data == (Variable("pose", "Pose", Pos(11, 10), Pos(11, 16)),)
    assert ss.resource("battery_status").transitions == (
        ("BatteryOk", "BatteryLow"),
        ("BatteryLow", "BatteryOk"),
    )
    estop = ss.event("estop")
    assert estop.guard is None
    assert eff(estop.effects) == [("motion_status", "Idle")]

    detect = ss.skill("detect_target")
    assert detect.interrupt.declared and not detect.interrupt.interrupting
    assert detect.interrupt.effects == ()
    assert [(v.name, v.type) for v in detect.inputs] == [("timeout", "Float")]
    assert [(v.name, v.type) for v in detect.outputs] == [("target", "Color")]

    move = ss.skill("move_to")
    assert eff(move.start) == [("motion_status", "Busy")]
    assert move.invariants[0].effects == ()
    assert move.progress is not None
    assert move.progress.period_seconds == 1.0
    assert [(v.name, v.type) for v in move.progress.fields] == [("distance", "Float")]
    assert move.outputs == ()

    picture = ss.skill("take_picture")
    assert not picture.interrupt.declared

    track = ss.skill("track_target")
    assert track.successes == ()
    assert [m.name for m in track.failures] == ["error_tracking"]
    assert track.preconditions[1].expr == StateAtom("battery_status", "BatteryOk")
