"""Pilot run files and the outcomes their failures inject (skinet/pilot/run.py; issue 24, the demo)."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import SourceError
from skinet.system.load import load_goals, load_system, load_typemap
from skinet.files.read import read_text
from skinet.pilot.run import Failure, Outcomes, check_pilot_run, is_pilot_run, parse_pilot_run

MISSIONS = Path(__file__).resolve().parents[1] / "skillsets" / "missions"
HEAD = '[pilot]\nname = "p"\nsystem = "../spot_arm.toml"\ngoals = "../goals/paper_mission.toml"\n'


@pytest.fixture(scope="module")
def system():
    return load_system(MISSIONS / "../spot_arm.toml")[0]


def test_the_demo_pilot_run_file(system) -> None:
    path = MISSIONS / "pilot.toml"
    text = read_text(path)
    assert is_pilot_run(text) and not is_pilot_run(read_text(MISSIONS / "assisted.toml"))
    run = parse_pilot_run(text, str(path))
    check_pilot_run(run, system, str(path))
    assert (run.name, run.mode, run.seed, run.failure_rate) == ("pilot", "drive", 0, 0.0)
    assert run.failures == (Failure("manipulator", "arm_ready", 1, "blocked"),
                            Failure("spot", "go_to_waypoint", 2, "not_arrived"))
    goals = load_goals(path.parent / run.goals, system, load_typemap(path.parent / run.system))
    assert len(goals) == 29


def test_declared_failures_end_those_runs_and_every_other_run_succeeds(system) -> None:
    outcomes = Outcomes(system, [Failure("manipulator", "arm_ready", 2, "blocked")])
    got = [outcomes.outcome("manipulator", "arm_ready") for _ in range(3)]
    assert got == [("success", "ready"), ("failure", "blocked"), ("success", "ready")]
    assert outcomes.outcome("spot", "teleop") == ("success", "done")  # the first success mode
    assert outcomes.runs == {("manipulator", "arm_ready"): 3, ("spot", "teleop"): 1}
    assert outcomes.failed == [("manipulator", "arm_ready", 2, "blocked")]


def test_a_failure_rate_draws_the_same_failures_from_the_same_seed(system) -> None:
    def draw(seed: int) -> list[tuple[str, str]]:
        outcomes = Outcomes(system, failure_rate=0.5, seed=seed)
        return [outcomes.outcome("spot", "go_to_waypoint") for _ in range(40)]

    first = draw(7)
    assert first == draw(7) and first != draw(8)
    assert {o for o in first} == {("success", "arrived"), ("failure", "not_arrived")}
    always = Outcomes(system, [Failure("spot", "teleop", 1, "link_lost")], failure_rate=1.0)
    assert always.outcome("spot", "teleop") == ("failure", "link_lost")  # the declared one
    assert always.outcome("spot", "stand_up") == ("failure", "fell")


@pytest.mark.parametrize("body,where,message", [
    ('mode = "fly"\n', "5:1", "mode must be 'guide' or 'drive', got 'fly'"),
    ('seed = 1.5\n', "5:1", "seed must be an integer"),
    ('failure_rate = 2\n', "5:1", "failure_rate must be a probability between 0 and 1, got 2"),
    ('speed = 2\n', "5:1", "unknown key 'speed' in [pilot]"),
    ('\n[[failures]]\nskill = "arm_ready"\nmode = "blocked"\n', "7:1",
     "failure 1: skill must be \"SKILLSET:SKILL\", got 'arm_ready'"),
    ('\n[[failures]]\nskill = "manipulator:arm_ready"\nrun = 0\nmode = "blocked"\n', "8:1",
     "failure 1: run must be a start number from 1, got 0"),
    ('\n[[failures]]\nskill = "manipulator:arm_ready"\n', "6:1", "failure 1: needs mode"),
    ('\n[[failures]]\nskill = "manipulator:arm_ready"\nmode = "blocked"\n'
     '[[failures]]\nskill = "manipulator:arm_ready"\nmode = "ready"\n', "9:1",
     "failure 2: run 1 of manipulator:arm_ready is already declared"),
    ('\n[failures]\nskill = "x"\n', "6:1", "'failures' must be [[failures]] tables"),
])
def test_bad_pilot_runs_say_where(body: str, where: str, message: str) -> None:
    with pytest.raises(SourceError) as info:
        parse_pilot_run(HEAD + body, "run.toml")
    assert str(info.value).startswith(f"run.toml:{where}: error: ") and message in str(info.value)


@pytest.mark.parametrize("failure,where,message", [
    ('skill = "arm:arm_ready"\nmode = "blocked"', "7:1", "unknown skillset 'arm' (skillsets of spot_arm: spot, "
                                                         "manipulator)"),
    ('skill = "manipulator:arm_steady"\nmode = "blocked"', "7:1", "unknown skill 'arm_steady' of skillset"),
    ('skill = "manipulator:arm_ready"\nmode = "ready"', "8:1",
     "'ready' is not a failure mode of manipulator:arm_ready (failure modes: blocked)"),
])
def test_failures_name_skills_and_failure_modes_of_the_system(system, failure: str, where: str, message: str) -> None:
    run = parse_pilot_run(HEAD + "\n[[failures]]\n" + failure + "\n", "run.toml")
    with pytest.raises(SourceError) as info:
        check_pilot_run(run, system, "run.toml")
    assert str(info.value).startswith(f"run.toml:{where}: error: failure 1: ") and message in str(info.value)


def test_a_pilot_run_without_its_head_is_refused() -> None:
    with pytest.raises(SourceError, match=r"run.toml:1:1: error: missing \[pilot\] table with 'name', 'system' "
                                          "and 'goals' strings"):
        parse_pilot_run('[pilot]\nname = "p"\n', "run.toml")
