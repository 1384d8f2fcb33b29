"""The paper's two runs replayed on the core (docs/mission.md acceptance, core part)."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import SourceError
from skinet.system.load import load_system
from skinet.mission.scenario import parse_scenario, replay, step_numbers

MISSIONS = Path(__file__).resolve().parents[1] / "skillsets" / "missions"


def run(name: str):
    scenario = parse_scenario((MISSIONS / f"{name}.toml").read_text(), name)
    system, _ = load_system(MISSIONS / scenario.system)
    return replay(system, scenario)


def test_unassisted_run_has_exactly_the_three_violations() -> None:
    records = run("unassisted")
    assert [(r.index, r.step.skillset, r.step.transition, r.violations) for r in records if r.violations] == [
        (26, "spot", "teleop.start", ["action_guard"]),
        (33, "spot", "go_to_waypoint.start", ["safety_guard"]),
        (38, "manipulator", "arm_ready.start", ["action_guard"]),
    ]
    assert all(r.divergence is None for r in records)


def test_assisted_run_warns_before_risky_commands_and_never_violates() -> None:
    records = run("assisted")
    assert not any(r.violations for r in records)
    assert all(all(r.holds.values()) for r in records)
    warned = [(r.index, [(w.skillset, w.transition, w.property, w.constraint, w.controllable) for w in r.warnings])
              for r in records if r.step.consider]
    assert warned == [
        (29, [("spot", "go_to_waypoint.start", "safety_guard", "explicit", True)]),
        (36, [("manipulator", "arm_ready.start", "action_guard", "explicit", True)]),  # entry 37, before step 36
    ]


def test_step_numbers_count_transitions() -> None:
    scenario = parse_scenario((MISSIONS / "assisted.toml").read_text(), "assisted")
    numbers = step_numbers(scenario)
    assert len(numbers) == 62 and numbers[-1] == 60
    assert [(n, numbers[n - 1]) for n in (28, 29, 30, 36, 37, 38)] == [(28, 28), (29, 29), (30, 29), (36, 35),
                                                                        (37, 36), (38, 36)]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[scenario]\nname = 'x'\n", "s.toml:1:1: error: missing [scenario] table with 'name' and 'system' strings"),
        ("[scenario]\nname='x'\nsystem='y'\n[[steps]]\nskillset='a'\n",
         "s.toml:4:1: error: step 1: give exactly one of 'transition' or 'consider'"),
        ("[scenario]\nname='x'\nsystem='y'\n[[steps]]\nt=2\nskillset='a'\ntransition='b'\n[[steps]]\nt=1\nskillset='a'\ntransition='b'\n",
         "s.toml:9:1: error: step 2: time 1.0 goes backwards (previous step at 2.0)"),
        ("[scenario]\nname='x'\nsystem='y'\n[[steps]]\nskillset='a'\ntransition='b'\n[[steps]]\nskillset='a'\n"
         "transition='b'\n  expect_divergence = 'yes'\n",
         "s.toml:10:3: error: step 2: 'expect_divergence' must be true or false, got 'yes'"),
        ("[scenario]\nname='x'\nsystem='y'\n[[steps]]\nskillset='a'\nconsider='b'\nexpect_divergence = true\n",
         "s.toml:7:1: error: step 1: 'expect_divergence' needs a 'transition' (a considered command is not played)"),
    ],
)
def test_scenario_errors(text: str, message: str) -> None:
    with pytest.raises(SourceError) as info:
        parse_scenario(text, "s.toml")
    assert str(info.value) == message


def test_a_step_may_expect_a_divergence() -> None:
    scenario = parse_scenario((MISSIONS / "mobile_divergence.toml").read_text(), "mobile_divergence")
    assert [(n, s.transition) for n, s in enumerate(scenario.steps, 1) if s.expect_divergence] == [
        (3, "pick.success.picked")]
    system, _ = load_system(MISSIONS / scenario.system)
    assert [(r.index, r.divergence) for r in replay(system, scenario) if r.divergence] == [
        (3, "'pick.success.picked' is not enabled in the live marking")]
