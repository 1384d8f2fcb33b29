"""``skinet plan`` (issue 23): the human output, the JSON, missions, and both engines alike."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from skinet.verify.symbolic import available
from skinet_cli.main import main

ROOT = Path(__file__).resolve().parents[2]
SYSTEM = str(ROOT / "skillsets" / "spot_arm.toml")
WALK = str(ROOT / "skillsets" / "goals" / "walk.toml")
TARGET = "go_to_waypoint.target = {x = 12.0, y = 3.5, z = 0.0}"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    code = main(["plan", *argv])
    out, err = capsys.readouterr()
    assert (code, err) == (0, "")
    return out


def test_a_strong_plan_reads_as_steps(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    state = tmp_path / "teleop.json"
    state.write_text('{"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", '
                     '"control_mode": "Busy"}, "running": ["teleop"]}}')
    out = run(capsys, SYSTEM, "reach spot:Idle", "--state", str(state))
    lines = out.splitlines()
    assert lines[:5] == ["goal: reach spot:Idle", "strong: at most 1 move, whatever the outcomes", "steps:",
                         "  1. wait for spot:teleop.success.done",
                         "     if spot:teleop.failure.link_lost: the goal is reached"]
    assert lines[5].startswith("explicit engine: 63 markings (complete), ") and len(lines) == 6


def test_a_mission_with_retries_and_another_route(capsys: pytest.CaptureFixture[str]) -> None:
    out = run(capsys, SYSTEM, "--goals", WALK)
    assert "goal 2: run spot:go_to_waypoint (from where goal 1 ends)" in out
    assert ("  5. manipulator:arm_RD_to_HP.start\n"
            "  6. wait for manipulator:arm_RD_to_HP.success.at_home\n"
            "     if manipulator:arm_RD_to_HP.failure.blocked:\n"
            "       6.1. manipulator:arm_moving_to_RD.start\n"
            "       6.2. wait for manipulator:arm_moving_to_RD.success.at_ready\n"
            "            if manipulator:arm_moving_to_RD.failure.blocked: retry from step 6.1\n"
            "       then continue at step 5\n"
            "  7. spot:go_to_waypoint.start with {target = {x = 12.0, y = 3.5, z = 0.0}}\n") in out


def test_a_goal_after_one_without_a_plan_is_not_planned(capsys: pytest.CaptureFixture[str]) -> None:
    out = run(capsys, SYSTEM, "reach spot:i_go_to_waypoint and manipulator:RD", "reach spot:Standing")
    assert out.splitlines()[-2:] == ["goal 2: reach spot:Standing", "not planned: goal 1 has no plan"]
    data = json.loads(run(capsys, SYSTEM, "reach spot:i_go_to_waypoint and manipulator:RD", "reach spot:Standing",
                          "--json"))
    assert [(d["goal"], d["answer"]) for d in data] == [
        ("reach spot:i_go_to_waypoint and manipulator:RD", "none"), ("reach spot:Standing", "unknown")]
    assert data[1]["reason"] == "not planned: goal 1 has no plan, so where this one starts is unknown"


def test_json_has_the_answer_steps_policy_and_stats(capsys: pytest.CaptureFixture[str]) -> None:
    (data,) = json.loads(run(capsys, SYSTEM, "run spot:go_to_waypoint", "--inputs", TARGET, "--json"))
    assert (data["answer"], data["moves"], data["reason"]) == ("cyclic", 6, None)
    assert data["retries"] == ["spot:init_power.failure.no_battery", "spot:stand_up.failure.fell",
                               "spot:go_to_waypoint.failure.not_arrived"]
    assert [(s["skillset"], s["action"], s["expect"]) for s in data["steps"]] == [
        ("spot", "init_power.start", None), ("spot", "wait", "init_power.success.powered_on"),
        ("spot", "stand_up.start", None), ("spot", "wait", "stand_up.success.standing"),
        ("spot", "go_to_waypoint.start", None), ("spot", "wait", "go_to_waypoint.success.arrived")]
    assert data["steps"][4]["inputs"] == {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}
    assert data["steps"][1]["branches"] == [{"skillset": "spot", "transition": "init_power.failure.no_battery",
                                             "then": "retry", "step": "1", "steps": []}]
    policy = data["policy"]
    assert data["policy_complete"] and len(policy) == 6  # the markings the plan can reach
    assert policy[0] == {"state": {"spot": {"resources": {"power_status": "PowerOff", "posture": "Sitting",
                                                          "control_mode": "Idle"}, "running": []},
                                   "manipulator": {"resources": {"mutex": "Free", "arm_status": "HP"}, "running": []}},
                         "action": {"skillset": "spot", "action": "init_power.start", "inputs": None}, "rank": 6}
    assert sorted(p["rank"] for p in policy) == [1, 2, 3, 4, 5, 6]
    assert {p["action"]["action"] for p in policy if p["action"]["skillset"] is None} == {"wait"}
    assert data["end"]["spot"]["running"] == [] and data["start"] == policy[0]["state"]
    assert set(data["stats"]) == {"markings", "time", "engine", "complete", "truncated_by"}
    assert (data["stats"]["markings"], data["stats"]["engine"], data["stats"]["complete"]) == (63, "explicit", True)


@pytest.mark.skipif(not available(), reason="dd.cudd (CUDD) is not installed")
def test_both_engines_print_the_same_plans(capsys: pytest.CaptureFixture[str]) -> None:
    def plans(engine: str) -> list[dict]:
        data = json.loads(run(capsys, SYSTEM, "reach spot:i_go_to_waypoint", "--goals", WALK, "--engine", engine,
                              "--json"))
        for d in data:
            d.pop("stats")
        return data

    explicit, symbolic = plans("explicit"), plans("symbolic")
    assert explicit == symbolic
    assert [d["answer"] for d in explicit] == ["cyclic", "cyclic", "none"]
    assert explicit[2]["reason"] == ("a skill the plan needs has inputs the goal does not give: "
                                     "spot:go_to_waypoint (input target)")


def test_the_help_explains_goals(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["plan", "--help"])
    out = capsys.readouterr().out
    for text in ("reach FORMULA", "run SKILLSET:SKILL.success.MODE", "--goals FILE", "--inputs TOML",
                 "--engine {auto,explicit,symbolic}", "strong", "cyclic", "unknown"):
        assert text in out


def test_the_examples_of_plan_help_work(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Every example of ``skinet plan --help`` runs as written (lines joined at their backslash)."""
    import shlex

    from skinet_cli.plan import EPILOG

    monkeypatch.chdir(ROOT)
    examples = EPILOG.split("examples:")[1].replace("\\\n", " ").strip().splitlines()
    assert len(examples) == 3
    for line in examples:
        argv = shlex.split(line)
        assert argv[:2] == ["skinet", "plan"]
        out = run(capsys, *argv[2:])
        assert "cyclic" in out, line


def test_the_papers_mission_as_goals_is_planned_whole(capsys: pytest.CaptureFixture[str]) -> None:
    """skillsets/goals/paper_mission.toml: docs/mission.md's protocol (stand up, four traps), every goal planned,
    each from where the previous one ends, with the commands of the protocol when outcomes are favourable."""
    data = json.loads(run(capsys, SYSTEM, "--goals", str(ROOT / "skillsets" / "goals" / "paper_mission.toml"),
                          "--json"))
    trap = ["run spot:go_to_waypoint", "run spot:teleop", "run manipulator:arm_ready", "run manipulator:arm_joystick",
            "run manipulator:arm_moving_to_RD", "run manipulator:arm_RD_to_HP", "run spot:teleop"]
    assert [d["goal"] for d in data] == ["reach spot:Standing", *trap * 4]
    assert {d["answer"] for d in data} == {"cyclic"}
    commands = [s["action"] for d in data for s in d["steps"] if s["action"] != "wait"]
    assert commands == ["init_power.start", "stand_up.start", *[
        "go_to_waypoint.start", "teleop.start", "arm_ready.start", "arm_joystick.start", "arm_moving_to_RD.start",
        "arm_RD_to_HP.start", "teleop.start"] * 4]
    walks = [s["inputs"]["target"] for d in data for s in d["steps"] if s["action"] == "go_to_waypoint.start"]
    assert walks == [{"x": 8.0, "y": 2.0, "z": 0.0}, {"x": 15.5, "y": -3.0, "z": 0.0},
                     {"x": 22.0, "y": 4.5, "z": 0.0}, {"x": 30.0, "y": 0.0, "z": 0.0}]
    # A blocked arm on its way to ready is brought to RD, home, and started again.
    arm_ready = data[3]["steps"][1]["branches"]
    assert [(b["transition"], b["then"]) for b in arm_ready] == [("arm_ready.failure.blocked", "route")]
    assert [s["action"] for s in arm_ready[0]["steps"]] == [
        "arm_moving_to_RD.start", "wait", "arm_RD_to_HP.start", "wait"]


def test_a_bound_skills_input_is_checked_against_its_goal_message(capsys: pytest.CaptureFixture[str]) -> None:
    """The model does not type nav2's DockId; the binding maps it to dock_id, a string: a plan (and skinet goal)
    refuses an input the goal message cannot hold, as the pilot would."""
    nav2 = str(ROOT / "examples" / "nav2" / "nav2.toml")
    assert main(["plan", nav2, "run nav2:dock_robot", "--inputs", "dock_robot.dock = 3"]) == 1
    assert capsys.readouterr().err == ("skinet: error: goal 'run nav2:dock_robot': nav2:dock_robot: the goal of "
                                       "/dock_robot cannot be sent: expected string at dock_id, got an integer\n")
    assert main(["plan", nav2, "run nav2:dock_robot", "--inputs", 'dock_robot.dock = "home_dock"']) == 0
    assert capsys.readouterr().out.startswith("goal: run nav2:dock_robot\ncyclic: 4 moves")


def test_from_a_violation_every_property_and_the_way_back_are_named(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 30: from the paper's violation (teleop while the arm joystick runs), ``reach true`` answered
    none with no way out; the recovery commands are in the reason and in the JSON's ``recovery``."""
    state = str(ROOT / "skillsets" / "states" / "teleop_during_joystick.json")
    reason = ("the robot is in a marking forced for action_guard (violated there: spot control_mode at Busy while "
              "manipulator mutex at Busy): no plan can promise safety from here; recover first with one of "
              "spot:teleop.interrupt, manipulator:arm_joystick.interrupt (each leads back into Safe whatever its "
              "outcome), then plan again")
    lines = run(capsys, SYSTEM, "reach true", "--state", state).splitlines()
    assert lines[:2] == ["goal: reach true", f"none: {reason}"] and len(lines) == 3
    [plan] = json.loads(run(capsys, SYSTEM, "reach true", "--state", state, "--json"))
    assert (plan["answer"], plan["reason"], plan["recovery"]) == ("none", reason, [
        {"skillset": "spot", "action": "teleop.interrupt"}, {"skillset": "manipulator", "action": "arm_joystick.interrupt"}])
