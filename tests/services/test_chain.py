"""MISSION.md acceptance: both paper runs through the whole chain.

Simulated managers (real CDR on bridge keys) -> bridge_ros2 -> monitor ->
predictor, on one embedded Zenoh session; the records must equal the core
replay step for step and show exactly the paper's violations and warnings.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from services.chain import run_chain
from skinet.files import load_system, load_typemap, read_text
from skinet.mission import StepRecord, parse_scenario, replay

MISSIONS = Path(__file__).resolve().parents[2] / "skillsets" / "missions"


def both(name: str) -> tuple[list[StepRecord], list[StepRecord]]:
    scenario = parse_scenario(read_text(MISSIONS / f"{name}.toml"), name)
    system, _ = load_system(MISSIONS / scenario.system)
    return run_chain(system, load_typemap(MISSIONS / scenario.system), scenario), replay(system, scenario)


def comparable(records: list[StepRecord]) -> list[tuple]:
    def flags(us: list) -> list[tuple]:
        return [(u.skillset, u.transition, u.property, u.constraint, u.steps, u.witness, u.reason) for u in us]

    return [(r.index, r.holds, r.violations, flags(r.warnings), flags(r.flagged), r.recovery, r.unsafe_count,
             r.divergence) for r in records]


def test_unassisted_run_through_the_chain() -> None:
    chain, core = both("unassisted")
    assert [(r.index, r.step.transition, r.violations) for r in chain if r.violations] == [
        (26, "teleop.start", ["action_guard"]),
        (33, "go_to_waypoint.start", ["safety_guard"]),
        (38, "arm_ready.start", ["action_guard"]),
    ]
    assert comparable(chain) == comparable(core)


def test_assisted_run_through_the_chain() -> None:
    chain, core = both("assisted")
    assert not any(r.violations for r in chain)
    assert [(r.index, [(w.transition, w.property, w.constraint, w.controllable) for w in r.warnings])
            for r in chain if r.step.consider] == [
        (29, [("go_to_waypoint.start", "safety_guard", "explicit", True)]),
        (37, [("arm_ready.start", "action_guard", "explicit", True)]),
    ]
    assert comparable(chain) == comparable(core)


def test_demo_command_runs_the_chain(capsys: pytest.CaptureFixture[str]) -> None:
    from skinet.cli.main import main

    assert main(["demo", "--all-steps"]) == 0
    out = capsys.readouterr().out
    assert out.count("chain: simulated managers -> CDR -> bridge -> monitor -> predictor") == 4
    assert "   violations: 3; action_guard at step 26; safety_guard at step 33; action_guard at step 38" in out
    assert "model divergence" not in out


def test_mobile_runs_through_the_chain() -> None:
    """The forced warning comes from the monitor itself, through the whole chain, as in the core replay."""
    chain, core = both("mobile_unassisted")
    assert [(r.index, r.violations) for r in chain if r.violations] == [(5, ["stowed_drive"])]
    assert [(u.transition, u.constraint, u.steps, u.witness) for u in chain[3].flagged] == [
        ("navigate.start", "forced", 1, ("arm:unfold.success.unfolded",))]
    assert comparable(chain) == comparable(core)
    chain, core = both("mobile_assisted")
    assert not any(r.violations for r in chain)
    assert comparable(chain) == comparable(core)
