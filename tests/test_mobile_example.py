"""The mobile manipulator example (issue 9): forced warnings ahead of explicit ones.

``skillsets/mobile_manip.toml`` is a wheeled base carrying an arm whose skills
change the arm's pose only when they end.  Driving off while ``unfold`` runs
violates nothing yet, but unfold's outcome alone will (docs/semantics.md §6.3): SkiNet flags
it *forced*, one command before any explicit constraint appears.  Every step of
both runs is checked: the operator view's unsafe transitions with their kinds,
steps and witnesses.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.system.load import load_system
from skinet.files.read import read_text
from skinet.system.live import LiveSystem
from skinet.mission.scenario import parse_scenario, replay
from skinet.verify.algorithm1 import analyse
from skinet.verify.predict import forecast

SKILLSETS = Path(__file__).resolve().parents[1] / "skillsets"
MISSIONS = SKILLSETS / "missions"
FORCED_UNFOLD = ("arm:unfold.success.unfolded",)

# What the operator view lists, by situation.
DRIVING_IS_FORCED = [  # unfold runs, the arm still counts as Folded
    ("base:navigate.start", "stowed_drive", "forced", 1, FORCED_UNFOLD),
    ("base:dock_station.start", "stowed_drive", "forced", 1, FORCED_UNFOLD),
]
ARM_OUT = [  # the arm is Unfolded or Holding: driving violates at once
    ("base:navigate.start", "stowed_drive", "explicit", 0, ()),
    ("base:dock_station.start", "stowed_drive", "explicit", 0, ()),
]
ARM_OUT_AND_BUSY = [  # ... and pick or place runs: driving violates both properties
    ("base:navigate.start", "stowed_drive", "explicit", 0, ()),
    ("base:navigate.start", "still_grasp", "explicit", 0, ()),
    ("base:dock_station.start", "stowed_drive", "explicit", 0, ()),
    ("base:dock_station.start", "still_grasp", "explicit", 0, ()),
]
UNFOLDING_IS_FORCED = [("arm:unfold.start", "stowed_drive", "forced", 1, FORCED_UNFOLD)]  # the base drives

MOBILE_UNASSISTED = {
    0: [],  # initial marking
    1: [],  # base:undock.start
    2: [],  # base:undock.success.undocked
    3: DRIVING_IS_FORCED,  # arm:unfold.start
    4: [  # base:navigate.start (flagged forced, issued anyway): unfold's outcomes now violate at once
        ("arm:unfold.success.unfolded", "stowed_drive", "explicit", 0, ()),
        ("arm:unfold.failure.jammed", "stowed_drive", "explicit", 0, ()),
    ],
    5: [("arm:pick.start", "still_grasp", "explicit", 0, ())],  # arm:unfold.success.unfolded (violated)
    6: ARM_OUT,  # base:navigate.success.arrived
    7: ARM_OUT_AND_BUSY,  # arm:pick.start
    8: ARM_OUT,  # arm:pick.success.picked
    9: ARM_OUT_AND_BUSY,  # arm:place.start
    10: ARM_OUT,  # arm:place.success.placed
    11: ARM_OUT,  # arm:fold.start
    12: [],  # arm:fold.success.folded
    13: UNFOLDING_IS_FORCED,  # base:dock_station.start
    14: [],  # base:dock_station.success.docked
}

MOBILE_ASSISTED = {
    0: [],  # initial marking
    1: [],  # base:undock.start
    2: [],  # base:undock.success.undocked
    3: DRIVING_IS_FORCED,  # arm:unfold.start
    4: DRIVING_IS_FORCED,  # considers base:navigate.start
    5: ARM_OUT,  # arm:unfold.success.unfolded
    6: ARM_OUT_AND_BUSY,  # arm:pick.start
    7: ARM_OUT,  # arm:pick.success.picked
    8: ARM_OUT,  # considers base:navigate.start
    9: ARM_OUT_AND_BUSY,  # arm:place.start
    10: ARM_OUT,  # arm:place.success.placed
    11: ARM_OUT,  # arm:fold.start
    12: [],  # arm:fold.success.folded
    13: UNFOLDING_IS_FORCED,  # base:navigate.start
    14: [],  # base:navigate.success.arrived
    15: UNFOLDING_IS_FORCED,  # base:dock_station.start
    16: [],  # base:dock_station.success.docked
}

RUNS = {"mobile_unassisted": MOBILE_UNASSISTED, "mobile_assisted": MOBILE_ASSISTED}


def operator_view_per_step(name: str) -> dict[int, list[tuple]]:
    scenario = parse_scenario(read_text(MISSIONS / f"{name}.toml"), name)
    system, _ = load_system(MISSIONS / scenario.system)
    live = LiveSystem(system)
    out = {}
    for i in range(len(scenario.steps) + 1):
        if i > 0 and scenario.steps[i - 1].transition:
            step = scenario.steps[i - 1]
            assert live.apply(step.skillset, step.transition).divergence is None
        analysis = analyse(system, live.marking, forecast(system, live.marking))
        out[i] = [(f"{u.skillset}:{u.transition}", u.property, u.constraint, u.steps, u.witness)
                  for u in analysis.operator_unsafe()]
    return out


@pytest.mark.parametrize("name", list(RUNS))
def test_warnings_at_every_step(name: str) -> None:
    assert operator_view_per_step(name) == RUNS[name]


@pytest.mark.parametrize("name", list(RUNS))
def test_forced_comes_before_any_explicit_constraint(name: str) -> None:
    kinds = {i: {row[2] for row in rows} for i, rows in RUNS[name].items()}
    first_forced = min(i for i, k in kinds.items() if "forced" in k)
    first_explicit = min(i for i, k in kinds.items() if "explicit" in k)
    assert first_explicit - first_forced >= 1


def test_unassisted_run_violates_after_the_forced_warning() -> None:
    scenario = parse_scenario(read_text(MISSIONS / "mobile_unassisted.toml"), "mobile_unassisted")
    system, _ = load_system(MISSIONS / scenario.system)
    records = replay(system, scenario)
    assert [(r.index, r.violations) for r in records if r.violations] == [(5, ["stowed_drive"])]
    issued = records[3]  # step 4: base:navigate.start, issued although flagged
    assert [(u.transition, u.property, u.constraint, u.steps, u.witness) for u in issued.flagged] == [
        ("navigate.start", "stowed_drive", "forced", 1, FORCED_UNFOLD)
    ]
    assert issued.flagged[0].reason == (
        "unfold may succeed (1 step) and leave arm pose at Unfolded while base navigate runs")


def test_assisted_run_heeds_forced_then_explicit() -> None:
    scenario = parse_scenario(read_text(MISSIONS / "mobile_assisted.toml"), "mobile_assisted")
    system, _ = load_system(MISSIONS / scenario.system)
    records = replay(system, scenario)
    assert not any(r.violations for r in records)
    assert [(r.index, [(w.transition, w.constraint, w.steps) for w in r.warnings]) for r in records
            if r.step.consider] == [(4, [("navigate.start", "forced", 1)]), (7, [("navigate.start", "explicit", 0)])]
    assert records[7].warnings[0].reason == "violates it at once: base navigate runs while arm pose at Holding"


def test_demo_tells_forced_warnings_apart(capsys: pytest.CaptureFixture[str]) -> None:
    from skinet_cli.main import main

    paths = [str(MISSIONS / "mobile_unassisted.toml"), str(MISSIONS / "mobile_assisted.toml")]
    assert main(["demo", "--core", *paths]) == 0
    out = capsys.readouterr().out
    assert ("     stowed_drive at step 5: SkiNet flagged base:navigate.start when it was issued at step 4 "
            "(forced, 1 step ahead); the operator went ahead") in out
    assert ("SkiNet: base:navigate.start: forced for stowed_drive — unfold may succeed (1 step) and leave "
            "arm pose at Unfolded while base navigate runs; operator refrains") in out
    assert ("   warnings heeded (commands considered, flagged, not issued): 2; base:navigate.start forced for "
            "stowed_drive at step 4; base:navigate.start explicit for stowed_drive at step 7") in out


def test_the_issue_arm_forced_for_safety_guard_while_walking() -> None:
    """Issue 9's case: an arm_ready that takes the mutex at start and moves to RD only on success.

    While arm_ready runs with the arm still at HP, go_to_waypoint.start is explicit for
    action_guard only; its forced constraint for safety_guard is the paper's 15:42 violation.
    """
    from skinet.lang.parser import parse_skillset
    from skinet.system.model import build_system

    arm_text = (SKILLSETS / "manipulator.rl").read_text()
    start = arm_text.index("    skill arm_ready {")
    end = arm_text.index("    skill arm_joystick {")
    arm_ready = """    skill arm_ready {
        precondition {
            at_home: arm_status == HP
            free: mutex == Free
        }
        start mutex -> Busy
        interrupt {
            effect mutex -> Free
        }
        success ready {
            effect {
                mutex -> Free
                arm_status -> RD
            }
        }
    }

"""
    arm_text = arm_text[:start] + arm_ready + arm_text[end:]
    arm = parse_skillset(arm_text.replace("HP -> Moving", "HP -> Moving\n                HP -> RD"), "manipulator.rl")
    spot = parse_skillset((SKILLSETS / "spot.rl").read_text(), "spot.rl")
    system = build_system("spot_arm", [(spot, ""), (arm, "")], (SKILLSETS / "spot_arm.props").read_text())
    live = LiveSystem(system)
    for skillset, transition in (("spot", "init_power.start"), ("spot", "init_power.success.powered_on"),
                                 ("spot", "stand_up.start"), ("spot", "stand_up.success.standing"),
                                 ("manipulator", "arm_ready.start")):
        assert live.apply(skillset, transition).divergence is None
    flags = [(u.property, u.constraint, u.steps, u.witness) for u in analyse(system, live.marking).operator_unsafe()
             if u.transition == "go_to_waypoint.start"]
    assert flags == [("action_guard", "explicit", 0, ()),
                     ("safety_guard", "forced", 1, ("manipulator:arm_ready.success.ready",))]
