"""Algorithm 1 with implicit constraints (docs/semantics.md §5) on the paper's system and on
small synthetic systems."""

from __future__ import annotations

import itertools
from collections.abc import Mapping

import pytest

from skinet.lang.parser import parse_skillset
from skinet.net.semantics import enabled, stable_successors, steps
from skinet.props.evaluate import holds
from skinet.system.model import System, build_system, marking_from_json, marking_to_json
from skinet.verify.algorithm1 import Analysis, PredictionVerdict, Recovery, UnsafeTransition, analyse
from skinet.verify.predict import forecast

Marking = dict[str, int]


def fire_named(system: System, marking: Mapping[str, int], skillset: str, name: str) -> Marking:
    """One step of the full net: the logical transition ``name``, then its cascade."""
    net = system.component(skillset).net
    m = marking[skillset]
    (t,) = [t for t in enabled(net, m) if t.name == name]
    (after,) = stable_successors(net, m, t)
    return {**marking, skillset: after}


def run(system: System, *moves: tuple[str, str]) -> Marking:
    m: Marking = system.initial_marking()
    for skillset, name in moves:
        m = fire_named(system, m, skillset, name)
    return m


def summary(analysis: Analysis) -> list[tuple[str, str, str, str, bool]]:
    """(property, skillset, transition, constraint, controllable) of every unsafe transition."""
    return [(u.property, u.skillset, u.transition, u.constraint, u.controllable) for u in analysis.unsafe]


def recovery(analysis: Analysis) -> dict[str, list[tuple[str, str, bool]]]:
    return {p: [(r.skillset, r.transition, r.controllable) for r in rs] for p, rs in analysis.recovery.items()}


POWERED_STANDING = (
    ("spot", "init_power.start"),
    ("spot", "init_power.success.powered_on"),
    ("spot", "stand_up.start"),
    ("spot", "stand_up.success.standing"),
)


# ---------------------------------------------------------------------------
# The paper's two warnings (docs/mission.md, assisted run)


def test_warning_go_to_waypoint_with_arm_out_of_home(paper_system: System) -> None:
    m = run(paper_system, *POWERED_STANDING, ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"))
    assert marking_to_json(paper_system, m) == {
        "spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"}, "running": []},
        "manipulator": {"resources": {"mutex": "Free", "arm_status": "RD"}, "running": []},
    }
    a = analyse(paper_system, m)
    assert a.violated == []
    assert a.recovery == {}
    assert a.unsafe == [
        UnsafeTransition("spot", "go_to_waypoint.start", "start", True, "safety_guard", "explicit", 0, ()),
    ]
    assert a.operator_unsafe() == a.unsafe


def test_warning_go_to_waypoint_after_a_joystick_session(paper_system: System) -> None:
    # trap 2 of the unassisted run: the arm is left Away after arm_joystick
    m = run(
        paper_system, *POWERED_STANDING,
        ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"),
        ("manipulator", "arm_joystick.start"), ("manipulator", "arm_joystick.success.released"),
    )  # fmt: skip
    assert marking_to_json(paper_system, m)["manipulator"] == {
        "resources": {"mutex": "Free", "arm_status": "Away"}, "running": [],
    }  # fmt: skip
    assert summary(analyse(paper_system, m)) == [
        ("safety_guard", "spot", "go_to_waypoint.start", "explicit", True),
    ]


def test_warning_arm_ready_while_teleop_runs(paper_system: System) -> None:
    m = run(paper_system, *POWERED_STANDING, ("spot", "teleop.start"))
    assert m == marking_from_json(
        paper_system,
        {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"},
                  "running": ["teleop"]}},
    )  # fmt: skip
    a = analyse(paper_system, m)
    assert a.violated == []
    assert a.unsafe == [
        UnsafeTransition("manipulator", "arm_ready.start", "start", True, "action_guard", "explicit", 0, ()),
    ]


def test_teleop_running_and_arm_away_flags_both_arm_starts(paper_system: System) -> None:
    m = marking_from_json(
        paper_system,
        {
            "spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"},
                     "running": ["teleop"]},
            "manipulator": {"resources": {"arm_status": "Away"}},
        },
    )  # fmt: skip
    assert summary(analyse(paper_system, m)) == [
        ("action_guard", "manipulator", "arm_joystick.start", "explicit", True),
        ("action_guard", "manipulator", "arm_moving_to_RD.start", "explicit", True),
    ]


def test_arm_moving_while_spot_stands_idle(paper_system: System) -> None:
    m = run(paper_system, *POWERED_STANDING, ("manipulator", "arm_ready.start"))
    assert summary(analyse(paper_system, m)) == [
        ("action_guard", "spot", "sit_down.start", "explicit", True),
        ("action_guard", "spot", "go_to_waypoint.start", "explicit", True),
        ("safety_guard", "spot", "go_to_waypoint.start", "explicit", True),
        ("action_guard", "spot", "teleop.start", "explicit", True),
    ]


def test_initial_marking_is_safe_everywhere(paper_system: System) -> None:
    a = analyse(paper_system, paper_system.initial_marking())
    assert (a.violated, a.unsafe, a.recovery) == ([], [], {})


# ---------------------------------------------------------------------------
# Already violated: literal list and recovery transitions


def test_action_guard_violated_teleop_and_joystick(paper_system: System) -> None:
    # trap 2 of the unassisted run: teleop started while arm_joystick runs
    m = run(
        paper_system, *POWERED_STANDING,
        ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"),
        ("manipulator", "arm_joystick.start"), ("spot", "teleop.start"),
    )  # fmt: skip
    a = analyse(paper_system, m)
    assert a.violated == ["action_guard"]
    # every transition recovers: the arm's emergency stop ends the joystick
    # session through its in_motion invariant, which frees the mutex
    assert a.unsafe == []
    assert a.operator_unsafe() == []
    assert a.recovery == {
        "action_guard": [
            Recovery("spot", "power_switchoff", "event", False),
            Recovery("spot", "teleop.interrupt", "interrupt", True),
            Recovery("spot", "teleop.success.done", "success", False),
            Recovery("spot", "teleop.failure.link_lost", "failure", False),
            Recovery("manipulator", "arm_emergency_stop", "event", False),
            Recovery("manipulator", "arm_joystick.interrupt", "interrupt", True),
            Recovery("manipulator", "arm_joystick.success.released", "success", False),
            Recovery("manipulator", "arm_joystick.failure.lost", "failure", False),
        ]
    }


def test_safety_guard_violated_walking_with_arm_ready(paper_system: System) -> None:
    # next transfer of the unassisted run: go_to_waypoint with the arm in RD
    m = run(
        paper_system, *POWERED_STANDING,
        ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"),
        ("spot", "go_to_waypoint.start"),
    )  # fmt: skip
    a = analyse(paper_system, m)
    assert a.violated == ["safety_guard"]
    assert summary(a) == [
        ("action_guard", "manipulator", "arm_joystick.start", "explicit", True),
        ("safety_guard", "manipulator", "arm_joystick.start", "explicit", True),
        ("action_guard", "manipulator", "arm_RD_to_HP.start", "explicit", True),
        ("safety_guard", "manipulator", "arm_RD_to_HP.start", "explicit", True),
    ]
    # the operator view hides the already violated property
    assert summary_of(a.operator_unsafe()) == [
        ("action_guard", "manipulator", "arm_joystick.start", "explicit", True),
        ("action_guard", "manipulator", "arm_RD_to_HP.start", "explicit", True),
    ]
    # bringing the arm home takes two steps: no arm transition recovers at once
    assert recovery(a) == {
        "safety_guard": [
            ("spot", "power_switchoff", False),
            ("spot", "go_to_waypoint.interrupt", True),
            ("spot", "go_to_waypoint.success.arrived", False),
            ("spot", "go_to_waypoint.failure.not_arrived", False),
        ]
    }


def test_both_violated(paper_system: System) -> None:
    m = run(paper_system, *POWERED_STANDING, ("manipulator", "arm_ready.start"), ("spot", "go_to_waypoint.start"))
    a = analyse(paper_system, m)
    assert a.violated == ["action_guard", "safety_guard"]
    assert a.operator_unsafe() == []
    # every step recovers action_guard, none recovers safety_guard (the arm is
    # not back home)
    assert summary(a) == [
        ("safety_guard", "manipulator", "arm_emergency_stop", "explicit", False),
        ("safety_guard", "manipulator", "arm_ready.interrupt", "explicit", True),
        ("safety_guard", "manipulator", "arm_ready.success.ready", "explicit", False),
        ("safety_guard", "manipulator", "arm_ready.failure.blocked", "explicit", False),
    ]
    assert recovery(a) == {
        "action_guard": [
            ("spot", "power_switchoff", False),
            ("spot", "go_to_waypoint.interrupt", True),
            ("spot", "go_to_waypoint.success.arrived", False),
            ("spot", "go_to_waypoint.failure.not_arrived", False),
            ("manipulator", "arm_emergency_stop", False),
            ("manipulator", "arm_ready.interrupt", True),
            ("manipulator", "arm_ready.success.ready", False),
            ("manipulator", "arm_ready.failure.blocked", False),
        ],
        "safety_guard": [
            ("spot", "power_switchoff", False),
            ("spot", "go_to_waypoint.interrupt", True),
            ("spot", "go_to_waypoint.success.arrived", False),
            ("spot", "go_to_waypoint.failure.not_arrived", False),
        ],
    }


def summary_of(unsafe: list[UnsafeTransition]) -> list[tuple[str, str, str, str, bool]]:
    return [(u.property, u.skillset, u.transition, u.constraint, u.controllable) for u in unsafe]


# ---------------------------------------------------------------------------
# With the predictor's mu1


SCENARIOS = {
    "arm ready, spot standing": (*POWERED_STANDING, ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready")),
    "teleop running": (*POWERED_STANDING, ("spot", "teleop.start")),
    "teleop and joystick": (
        *POWERED_STANDING, ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"),
        ("manipulator", "arm_joystick.start"), ("spot", "teleop.start"),
    ),
    "walking with arm ready": (
        *POWERED_STANDING, ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"),
        ("spot", "go_to_waypoint.start"),
    ),
    "initial": (),
}  # fmt: skip


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_prediction_changes_nothing_at_the_mission_markings(paper_system: System, scenario: str) -> None:
    m = run(paper_system, *SCENARIOS[scenario])
    plain = analyse(paper_system, m)
    predicted = analyse(paper_system, m, prediction=forecast(paper_system, m))
    assert (predicted.violated, predicted.unsafe, predicted.recovery) == (plain.violated, plain.unsafe, plain.recovery)


def test_mu1_equals_violation_from_the_initial_marking(paper_system: System) -> None:
    f = forecast(paper_system)
    report = f.report()
    assert (report["complete"], report["markings"], report["deadlocks"]) == (True, 63, 0)
    assert report["properties"] == {
        "action_guard": {"violating": 24, "dangerous": 24, "undecided": 0, "safe": 39,
                         "implicit_fair": 0, "undecided_fair": 0},
        "safety_guard": {"violating": 6, "dangerous": 6, "undecided": 0, "safe": 57,
                         "implicit_fair": 0, "undecided_fair": 0},
    }
    for risk in f.risks.values():
        assert ((risk.mu1.lower & f.kripke.stored) == risk.violating).all()


def _reachable(net) -> list[int]:
    seen, todo = {net.initial}, [net.initial]
    while todo:
        for _, results in steps(net, todo.pop()):
            for r in results - seen:
                seen.add(r)
                todo.append(r)
    return sorted(seen)


def _replay_reaches_violation(system: System, start: Mapping[str, int], witness: tuple[str, ...], prop) -> bool:
    """Follow the witness labels (``skillset:transition``) in the eventless nets."""
    current = [dict(start)]
    for label in witness:
        ss, _, name = label.partition(":")
        net = system.component(ss).eventless
        current = [
            {**m, ss: r}
            for m in current
            for t in enabled(net, m[ss])
            if t.name == name
            for r in stable_successors(net, m[ss], t)
        ]
    nets = system.nets
    return any(not holds(prop.expr, m, nets) for m in current)


# The paper's pair has no implicit constraint at any combined marking the full
# nets reach (as in the paper, where |mu1| is the number of violating markings).
# An earlier manipulator model had some: an emergency stop during a movement left
# the mutex Busy forever; the in_motion invariants of the arm skills fixed that.


def test_no_implicit_constraint_in_the_paper_pair(paper_system: System) -> None:
    spot_net = paper_system.component("spot").net
    arm_net = paper_system.component("manipulator").net
    spot_all, arm_all = _reachable(spot_net), _reachable(arm_net)
    assert (len(spot_all), len(arm_all)) == (10, 7)
    for ms, ma in itertools.product(spot_all, arm_all):
        m = {"spot": ms, "manipulator": ma}
        plain = analyse(paper_system, m)
        predicted = analyse(paper_system, m, prediction=forecast(paper_system, m))
        assert predicted.violated == plain.violated
        assert predicted.unsafe == plain.unsafe
        assert predicted.recovery == plain.recovery


def test_emergency_stop_ends_the_arm_skill(paper_system: System) -> None:
    m = run(
        paper_system, *POWERED_STANDING,
        ("manipulator", "arm_ready.start"), ("manipulator", "arm_emergency_stop"),
    )  # fmt: skip
    assert marking_to_json(paper_system, m)["manipulator"] == {
        "resources": {"mutex": "Free", "arm_status": "Away"}, "running": [],
    }
    a = analyse(paper_system, m, prediction=forecast(paper_system, m))
    assert a.violated == []
    # the arm is out of HP: walking is the only unsafe command
    assert a.unsafe == [
        UnsafeTransition("spot", "go_to_waypoint.start", "start", True, "safety_guard", "explicit", 0, ()),
    ]


# ---------------------------------------------------------------------------
# A synthetic system with implicit constraints (and unknown ones when truncated)

STOVE = """
skillset stove {
    resource { flame { state { Off Warm Hot On } initial Off transition all } }
    event { spark { guard flame == Off effect flame -> Hot } }
    // heat's only outcome (no mode; its interrupt) leaves the flame Hot
    skill heat {
        precondition cold: flame == Off
        start flame -> Warm
        interrupt { effect flame -> Hot }
    }
    // the only thing that can happen when the flame is Hot
    skill blast {
        precondition hot: flame == Hot
        start flame -> On
    }
    // a safe loop from Off
    skill rest { precondition cold: flame == Off }
}
"""


@pytest.fixture(scope="module")
def kitchen() -> System:
    return build_system("kitchen", [(parse_skillset(STOVE, "stove.rl"), "/stove")], "no_fire = not stove:On\n", "k.props")


def test_synthetic_implicit_constraints(kitchen: System) -> None:
    m = kitchen.initial_marking()
    assert analyse(kitchen, m).unsafe == []  # nothing explicit: every step is safe now
    f = forecast(kitchen, m)
    assert f.report()["complete"] is True
    a = analyse(kitchen, m, prediction=f)
    assert a.violated == []
    # heat.start: heat.interrupt (Warm -> Hot), then blast.start (Hot -> On): two steps
    # spark: Hot at once, then blast.start: one step; rest.start is safe (rest loops)
    assert a.unsafe == [
        UnsafeTransition("stove", "spark", "event", False, "no_fire", "implicit", 1, ("stove:blast.start",)),
        UnsafeTransition(
            "stove", "heat.start", "start", True, "no_fire", "implicit", 2,
            ("stove:heat.interrupt", "stove:blast.start"),
        ),
    ]  # fmt: skip
    assert a.operator_unsafe() == a.unsafe


def test_synthetic_verdicts(kitchen: System) -> None:
    m = kitchen.initial_marking()
    f = forecast(kitchen, m)
    state = lambda flame, *running: marking_from_json(  # noqa: E731
        kitchen, {"stove": {"resources": {"flame": flame}, "running": list(running)}}
    )
    assert f.verdict("no_fire", m) == PredictionVerdict("safe")
    assert f.verdict("no_fire", state("Off", "rest")) == PredictionVerdict("safe")
    assert f.verdict("no_fire", state("Warm", "heat")) == PredictionVerdict(
        "dangerous", 2, ("stove:heat.interrupt", "stove:blast.start")
    )
    assert f.verdict("no_fire", state("Hot")) == PredictionVerdict("dangerous", 1, ("stove:blast.start",))
    assert f.verdict("no_fire", state("On", "blast")) == PredictionVerdict("dangerous", 0, ())
    # never explored from here (heat cannot run with the flame On): undecided by the
    # exploration, decided compositionally (docs/semantics.md §6.4)
    alone = forecast(kitchen, m, compositional=False)
    assert alone.verdict("no_fire", state("On", "heat")) == PredictionVerdict("undecided")
    assert f.verdict("no_fire", state("On", "heat")).status == "dangerous"


def test_synthetic_already_dangerous_marking(kitchen: System) -> None:
    # Hot with nothing running: phi holds now but the only step violates it
    m = marking_from_json(kitchen, {"stove": {"resources": {"flame": "Hot"}}})
    a = analyse(kitchen, m, prediction=forecast(kitchen, m))
    assert a.violated == []
    assert a.unsafe == [
        UnsafeTransition("stove", "blast.start", "start", True, "no_fire", "explicit", 0, ()),
    ]


def test_truncated_prediction_gives_unknown_never_safe(kitchen: System) -> None:
    m = kitchen.initial_marking()
    nothing = forecast(kitchen, m, max_depth=0, compositional=False)
    assert nothing.report()["complete"] is False
    assert summary(analyse(kitchen, m, prediction=nothing)) == [
        ("no_fire", "stove", "spark", "unknown", False),
        ("no_fire", "stove", "heat.start", "unknown", True),
        ("no_fire", "stove", "rest.start", "unknown", True),
    ]
    one = forecast(kitchen, m, max_depth=1, compositional=False)
    assert analyse(kitchen, m, prediction=one).unsafe == [
        UnsafeTransition("stove", "spark", "event", False, "no_fire", "implicit", 1, ("stove:blast.start",)),
        UnsafeTransition("stove", "heat.start", "start", True, "no_fire", "unknown", None, ()),
        UnsafeTransition("stove", "rest.start", "start", True, "no_fire", "unknown", None, ()),
    ]


def test_worst_constraint_over_cascade_results_and_variants() -> None:
    # Two invariants enabled at once: one order violates phi now, the other
    # does not; Algorithm 1 keeps the worst (explicit) for the transition.
    ss = parse_skillset(
        """
        skillset s {
            resource {
                power { state { Off On } initial On transition all }
                light { state { Dark Red Green } initial Dark transition all }
            }
            skill watcher { invariant p { guard power == On effect light -> Green } }
            skill red { invariant p { guard power == On effect light -> Red } }
            skill cutter { start power -> Off }
        }
        """
    )
    system = build_system("s", [(ss, "")], "no_red = not s:Red\n")
    m = marking_from_json(system, {"s": {"running": ["watcher", "red"]}})
    net = system.component("s").net
    (t,) = [t for t in enabled(net, m["s"]) if t.name == "cutter.start"]
    assert len(stable_successors(net, m["s"], t)) == 2
    a = analyse(system, m)
    assert a.unsafe == [UnsafeTransition("s", "cutter.start", "start", True, "no_red", "explicit", 0, ())]


def test_recovery_needs_every_cascade_result_to_recover() -> None:
    ss = parse_skillset(
        """
        skillset s {
            resource {
                power { state { Off On } initial On transition all }
                light { state { Dark Red Green } initial Red transition all }
            }
            skill watcher { invariant p { guard power == On effect light -> Green } }
            skill red { invariant p { guard power == On effect light -> Red } }
            skill cutter { start power -> Off }
            skill painter { success ok { effect light -> Dark } }
        }
        """
    )
    system = build_system("s", [(ss, "")], "no_red = not s:Red\n")
    m = marking_from_json(system, {"s": {"running": ["watcher", "red", "painter"]}})
    a = analyse(system, m)
    assert a.violated == ["no_red"]
    # cutter.start ends Red or Green depending on the order: not a recovery
    assert recovery(a) == {"no_red": [("s", "painter.success.ok", False)]}
    assert ("no_red", "s", "cutter.start", "explicit", True) in summary(a)
